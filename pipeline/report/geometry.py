"""Geometry the outputs draw: lines of sight, error ellipses, CEP, per-frame residuals, ENU -> WGS84.

All positions are ENU metres in the group's local frame unless a name says otherwise (`_deg` for geodetic).
"""

from __future__ import annotations

import numpy as np

from pipeline.geometry.camera import project
from pipeline.geometry.frames import lla_from_enu
from pipeline.geometry.rays import camera_rays_m
from pipeline.results import GroupResult
from pipeline.solve.estimate import Estimate
from pipeline.solve.observations import Observations
from pipeline.solve.uncertainty import horizontal

ALT_DATUM = "WGS84 ellipsoidal height (EPSG:4979)"


def geodetic_from_enu(enu_m: np.ndarray, origin_lla: tuple[float, float, float]) -> np.ndarray:
    """(..., 3) ENU metres -> (..., 3) (lat_deg, lon_deg, alt_m) on WGS84, alt above the ellipsoid, the longitude
    in [-180, 180) as RFC 7946 and KML want (`geometry.frames.lla_from_enu`, wrapped)."""
    lla = lla_from_enu(enu_m, origin_lla)
    lla[..., 1] = (lla[..., 1] + 180.0) % 360.0 - 180.0
    return lla


def camera_rays(obs: Observations) -> tuple[np.ndarray, np.ndarray]:
    """Camera centres (n, 3) m and unit viewing directions (n, 3) through each frame's target pixel (rows of NaN
    where the target was not seen). The direction's sign puts the target in front of the camera."""
    return camera_rays_m(obs.P, obs.pixel)


def lines_of_sight_m(obs: Observations, reference_m: np.ndarray | None = None,
                     max_lines: int | None = 200) -> tuple[np.ndarray, np.ndarray]:
    """Line-of-sight segments (k, 2, 3) m and the frame index of each (k,).

    A frame with a target pixel gives its camera ray from the camera centre, as long as the laser range when
    there is one, else to the point of the ray closest to `reference_m`. A frame with only a range gives the
    segment from the platform towards `reference_m`, as long as the range. Frames with neither (or no
    reference where one is needed) give no segment. At most `max_lines` evenly spaced frames are kept.
    """
    centre, d = camera_rays(obs)
    has_px = obs.has_pixel
    rng = obs.range_m
    ref = None if reference_m is None or not np.isfinite(reference_m).all() else np.asarray(reference_m, float)
    start = np.where(has_px[:, None], centre, obs.platform_m)
    direction = d.copy()
    length = np.where(np.isfinite(rng), rng, np.nan)
    if ref is not None:
        to_ref = ref - obs.platform_m
        dist = np.linalg.norm(to_ref, axis=1)
        towards = to_ref / np.where(dist > 0, dist, 1.0)[:, None]
        direction[~has_px] = towards[~has_px]
        along = np.einsum("ij,ij->i", ref - centre, np.nan_to_num(d))
        length = np.where(np.isfinite(length), length, np.where(has_px, along, np.nan))
    ok = np.isfinite(length) & (length > 0) & np.isfinite(direction).all(axis=1)
    idx = np.flatnonzero(ok)
    if max_lines is not None and idx.size > max_lines:
        idx = idx[np.unique(np.linspace(0, idx.size - 1, max_lines).round().astype(int))]
    seg = np.stack([start[idx], start[idx] + length[idx, None] * direction[idx]], axis=1)
    return seg, idx


def uncertainty(e: Estimate) -> dict:
    """CEP50, CEP90, vertical sigma and the 95 % horizontal ellipse of an estimate, where defined (with a
    covariance; `pipeline.solve.uncertainty.horizontal`); an estimator's own CEP values in `extras` (`cep50_m`,
    `cep90_m`) take precedence."""
    out = {"cep50_m": None, "cep90_m": None, "sigma_up_m": None, "ellipse95_semi_major_m": None,
           "ellipse95_semi_minor_m": None, "ellipse95_azimuth_deg": None}
    cov = e.covariance_m2
    if cov is not None and np.isfinite(cov).all():
        out.update(horizontal(np.asarray(cov)))
    for key in ("cep50_m", "cep90_m", "sigma_up_m"):
        v = e.extras.get(key)
        if isinstance(v, (int, float)) and not isinstance(v, bool) and np.isfinite(v):
            out[key] = float(v)
    return out


def frame_residuals(obs: Observations, position_m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per-frame residuals of a target position: pixel reprojection error magnitude (n,) px and range
    residual |X - s_i| - d_i (n,) m; NaN where the frame has no pixel / no range or X is not finite."""
    X = np.asarray(position_m, dtype=np.float64)
    if not np.isfinite(X).all():
        nan = np.full(obs.n, np.nan)
        return nan, nan.copy()
    px = np.linalg.norm(project(obs.P, np.broadcast_to(X, (obs.n, 3))) - obs.pixel, axis=1)
    rng = np.linalg.norm(X - obs.platform_m, axis=1) - obs.range_m
    return px, rng


def best_reference_m(r: GroupResult, order=("mle", "ridge", "fusion", "vision", "range")) -> np.ndarray | None:
    """The position lines of sight are drawn towards and close-ups centre on: the answer where the target is
    located, else the first finite estimate in `order`, else any (an undetermined method's point, kilometres off
    on nearly parallel lines of sight, is no centre while there is an answer)."""
    a = r.answer
    if a is not None and a.located and a.position_m is not None and np.isfinite(a.position_m).all():
        return np.asarray(a.position_m, dtype=np.float64)
    for m in (*order, *r.estimates):
        e = r.estimates.get(m)
        if e is not None and np.isfinite(e.position_m).all():
            return np.asarray(e.position_m, dtype=np.float64)
    return None
