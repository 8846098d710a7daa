"""What the MLE is told about a photo flight's errors when the user states nothing: defaults per source type (laser or
not; RTK fixed, RTK float or a plain GNSS fix) from what the sources are known to do (docs/locate.md, "Error model";
the figures and where they come from are there).

Two parts:
- per photo, from photo to photo (`Sigma`): the marked pixel, the laser's range, the position's and the recorded
  attitude's photo-to-photo noise;
- shared by every photo of the flight: the compass / gimbal-yaw bias (the MLE's boresight bias, `bias_prior_deg`),
  the GNSS offset (horizontal per axis, vertical) and the altitude datum offset. An offset shared by every camera
  moves the estimate by the same vector and shows in no residual, so `pipeline.locate` adds its covariance to the
  MLE's; against a DEM the vertical part is an error of the terrain prior, whose sigma grows by it.

Checked against real lines of sight of a Skydio X2 (scripts/real_rays.py; docs/locate.md, "Real lines of sight"):
left as they are; the per-photo part is small for photos spread over a long session, whose time span the split
between the shared and the per-photo GNSS error does not yet take from the photos' times.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from pipeline.solve.observations import Sigma

#: DJI drone-dji:RtkFlag (DJI Mavic 3E/3T user manual, "Photo File"): 0 no fix, 16 single point (metre level),
#: 32-49 float (decimetre to metre), 50 fixed (centimetre)
RTK_FIXED = 50
RTK_FLOAT = range(32, 50)

#: a target marked by hand in a photo (px, 1 sigma)
MARK_SIGMA_PX = 2.0
#: DJI laser rangefinders (Zenmuse H20/H20T/H30T, M30T, M3TD/M4T): accuracy +-(0.2 m + 0.15 % of the range); DJI
#: states no confidence level, so the bound is read as 1 sigma (the safe side)
LRF_ACCURACY_M = 0.2
LRF_ACCURACY_PER_M = 0.0015
#: the recorded gimbal attitude's photo-to-photo noise (deg): the constant part of the error is the bias
ATTITUDE_NOISE_DEG = 0.3
#: the compass / gimbal-yaw bias of a consumer drone, constant over a flight: 1-5 deg (magnetic disturbance,
#: calibration); a zero-mean Gaussian prior of 3 deg puts 9 in 10 biases inside 5 deg. RTK does not help: a
#: single RTK antenna measures position, not heading
COMPASS_BIAS_DEG = 3.0
#: (shared horizontal per axis, shared vertical, photo-to-photo) position sigmas (m) by fix type:
#: plain GNSS: DJI's stated horizontal GNSS hover accuracy +-1.5 m; over a few minutes a single-frequency receiver's
#: error is mostly an offset; the vertical is the altitude datum offset below (AbsoluteAltitude without RTK is
#: barometric height above take-off plus the take-off's GNSS altitude: errors of 10-30 m are common)
GNSS_PLAIN_M = (1.5, 15.0, 0.5)
#: RTK float without RtkStd tags: decimetre to metre
GNSS_FLOAT_M = (0.5, 1.0, 0.3)
#: RTK fixed without RtkStd tags: DJI states 1 cm + 1 ppm horizontal, 1.5 cm + 1 ppm vertical; the camera's offset
#: from the antenna and the exposure's timing add a few centimetres; the datum of AbsoluteAltitude (stated by the user,
#: --alt-datum) leaves a geoid-model difference of decimetres
GNSS_FIXED_M = (0.05, 0.3, 0.05)


@dataclass(frozen=True)
class PhotoErrorModel:
    """The per-photo sigmas, the compass bias prior (deg, 1 sigma) and the shared offset's sigmas (m): horizontal
    per axis, vertical (GNSS and altitude datum together); `source` says what they were derived from."""

    sigma: Sigma
    bias_prior_deg: float
    shared_h_m: float
    shared_v_m: float
    source: str

    def shared_covariance_m2(self) -> np.ndarray:
        """(3, 3) ENU covariance of the offset shared by every photo."""
        return np.diag([self.shared_h_m ** 2, self.shared_h_m ** 2, self.shared_v_m ** 2])

    def to_dict(self) -> dict:
        return {"source": self.source, "sigma": self.sigma.to_dict(), "bias_prior_deg": self.bias_prior_deg,
                "shared_offset_horizontal_m": self.shared_h_m, "shared_offset_vertical_m": self.shared_v_m}


def _position_of(photo) -> tuple[tuple[float, float, float], str]:
    """(shared h, shared v, per-photo) sigmas of one photo's position and the fix type's name: RtkStdLon/Lat/Hgt
    when the photo's RtkFlag says RTK (float or fixed) and the tags are there, else the fix type's default."""
    flag = photo.rtk_flag
    std = photo.rtk_std_m
    rtk = flag is not None and (flag == RTK_FIXED or flag in RTK_FLOAT)
    name = "RTK fixed" if flag == RTK_FIXED else "RTK float" if rtk else "GNSS without RTK"
    default = GNSS_FIXED_M if flag == RTK_FIXED else GNSS_FLOAT_M if rtk else GNSS_PLAIN_M
    if rtk and std is not None and all(math.isfinite(v) and v > 0 for v in std):
        h = max(std[0], std[1])
        return (h, max(std[2], default[1]), h), f"{name} (RtkStdLon/Lat/Hgt)"
    return default, name


def photo_error_model(photos, ranges_m=None) -> PhotoErrorModel:
    """The default error model of photos (`pipeline.ingest.photo.Photo`): the worst position class among them (a
    flight mixing RTK fixed and plain photos is as good as its plain ones), the laser's sigma at the longest range
    used (ranges_m: the ranges the MLE gets, NaN where none; default every valid LRF range)."""
    pos = [_position_of(p) for p in photos]
    h, v, per = (max(s[k] for s, _ in pos) for k in range(3))
    kinds = sorted({name for _, name in pos})
    if ranges_m is None:
        ranges_m = [p.lrf_range_m for p in photos if p.lrf_valid]
    r = np.asarray(ranges_m, dtype=np.float64)
    r = r[np.isfinite(r)]
    laser = r.size > 0
    s_range = LRF_ACCURACY_M + LRF_ACCURACY_PER_M * float(r.max()) if laser else None
    sigma = Sigma(pixel_px=MARK_SIGMA_PX, range_m=s_range if laser else 1.0, position_m=per,
                  attitude_deg=ATTITUDE_NOISE_DEG)
    source = f"{' + '.join(kinds)}, {'laser' if laser else 'no laser'}"
    return PhotoErrorModel(sigma=sigma, bias_prior_deg=COMPASS_BIAS_DEG, shared_h_m=h, shared_v_m=v, source=source)
