"""A level ground at one height, for a photo with neither laser nor DEM (`ridgeloc locate --ground`): the weaker
answer, where the target is assumed to stand on ground at a stated height or at the take-off point's.

`FlatGround` offers what the `dem` method asks of a Dem (`intersect_many`, `path` for messages), so
`pipeline.terrain.locate_dem` casts the rays onto it; `ground_covariance_m2` says how far the answer may be off,
from the assumed height's own error and the photo's pose errors (docs/locate.md, "Answers with less").
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pymap3d

from pipeline.geometry.frames import R_ecef_from_enu, ecef_from_lla

MAX_RANGE_M = 50_000.0  # a ray meeting the level ground further than this is refused (it is nearly level)


@dataclass(frozen=True)
class FlatGround:
    """Level ground at ellipsoidal height h_m (the surface h = h_m, following the ellipsoid's curve). `path` is the
    label messages name it by (as a Dem's file), e.g. "level ground at 130.1 m (the take-off point's)"."""

    h_m: float
    path: str

    @property
    def label(self) -> str:
        return self.path

    def intersect_many(self, origins_lla, directions_enu) -> tuple[np.ndarray, list[str | None]]:
        """lla (k, 3) where k rays (origins_lla (k, 3), directions_enu (k, 3) in the ENU frame at each origin) meet
        the ground (NaN rows for misses) and k reasons (None for a hit)."""
        o = np.asarray(origins_lla, dtype=np.float64).reshape(-1, 3)
        d = np.asarray(directions_enu, dtype=np.float64).reshape(-1, 3)
        out = np.full(o.shape, np.nan)
        reasons: list[str | None] = []
        for k in range(len(o)):
            reasons.append(self._one(o[k], d[k], out, k))
        return out, reasons

    def _one(self, origin, direction, out, k) -> str | None:
        n = np.linalg.norm(direction)
        if not (np.isfinite(origin).all() and np.isfinite(direction).all() and n > 0):
            return "the ray has no finite origin or direction"
        dz = direction[2] / n
        above = origin[2] - self.h_m
        if above <= 0:
            return f"the ray starts below the ground ({origin[2]:.1f} m, {-above:.1f} m under it)"
        if dz >= -1e-9:
            return "the ray never meets the ground: it points above the horizon"
        O = ecef_from_lla(origin[0], origin[1], origin[2])
        D = R_ecef_from_enu(origin[0], origin[1]) @ (direction / n)
        t = above / -dz  # the level plane's answer, then Newton steps on the curved surface
        for _ in range(20):
            if not (0 < t <= MAX_RANGE_M):
                return f"the ray meets the ground further than {MAX_RANGE_M / 1000:g} km away (it is nearly level)"
            p = O + t * D
            lat, lon, h = pymap3d.ecef2geodetic(*p)
            up = R_ecef_from_enu(float(lat), float(lon))[:, 2]
            rate = float(D @ up)
            if rate >= 0:
                return "the ray never meets the ground: it points above the horizon"
            step = (float(h) - self.h_m) / -rate
            t += step
            if abs(step) < 1e-6:
                break
        p = O + t * D
        out[k] = np.array(pymap3d.ecef2geodetic(*p), dtype=np.float64)
        return None


def ground_covariance_m2(camera_m, R_enu0_from_optical, pinhole_px, K, point_m, sigma_relative_m: float,
                         sigma_absolute_m: float, sigma_h_m: float, sigma_yaw_deg: float, sigma_tilt_deg: float,
                         sigma_px: float) -> np.ndarray:
    """(3, 3) ENU covariance (m^2) of one photo's level-ground answer `point_m` (3,), first order in the errors:
    the ground's height against the camera (sigma_relative_m), the camera's heading (sigma_yaw_deg, about up), its
    tilt and roll (sigma_tilt_deg, about the camera's x and z axes), the pixel (sigma_px, per axis), and the camera's
    horizontal position (sigma_h_m per axis, moving the answer by as much); the answer's height is the ground's, whose
    own error is sigma_absolute_m. camera_m (3,), R_enu0_from_optical (3, 3), pinhole_px (2,) undistorted, K (3, 3).
    The ground is taken as the level plane through the answer (exact to first order over a few kilometres)."""
    c = np.asarray(camera_m, dtype=np.float64)
    R = np.asarray(R_enu0_from_optical, dtype=np.float64)
    z_g = float(point_m[2])
    Kinv = np.linalg.inv(K)

    def hit(d_up=0.0, yaw=0.0, tilt=0.0, roll=0.0, du=0.0, dv=0.0):
        from scipy.spatial.transform import Rotation

        ray_cam = Kinv @ np.array([pinhole_px[0] + du, pinhole_px[1] + dv, 1.0])
        Rc = (Rotation.from_rotvec([0.0, 0.0, yaw]).as_matrix() @ R
              @ Rotation.from_rotvec([tilt, 0.0, roll]).as_matrix())
        d = Rc @ ray_cam
        t = (z_g + d_up - c[2]) / d[2]
        return c + t * d

    base = hit()
    eps = {"d_up": 0.01, "yaw": 1e-5, "tilt": 1e-5, "roll": 1e-5, "du": 0.01, "dv": 0.01}
    sig = {"d_up": sigma_relative_m, "yaw": np.radians(sigma_yaw_deg), "tilt": np.radians(sigma_tilt_deg),
           "roll": np.radians(sigma_tilt_deg), "du": sigma_px, "dv": sigma_px}
    J = np.column_stack([(hit(**{k: e}) - base) / e for k, e in eps.items()])
    S = np.diag([sig[k] ** 2 for k in eps])
    cov = J @ S @ J.T
    cov[:2, :2] += np.eye(2) * sigma_h_m ** 2
    cov[2, :] = 0.0
    cov[:, 2] = 0.0
    cov[2, 2] = sigma_absolute_m ** 2
    return cov
