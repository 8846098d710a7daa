"""The `dem` method: the ray through each view's target pixel, intersected with the terrain.

One view gives one point; several give the component-wise median of their points (as `los` does with the
laser), in the observations' world frame (ENU at `origin_lla`). Views whose ray misses are left out and listed
in the estimate's extras; when none hits, a GeometryError (an InputError) of one line names the view, its
pixel, why, and the DEM: `pipeline.solve.methods.unsolved_status` maps it to "degenerate".
"""

from __future__ import annotations

import numpy as np

from pipeline.errors import GeometryError, ObservationError
from pipeline.geometry.frames import R_ecef_from_enu, enu_from_lla, lla_from_enu
from pipeline.geometry.rays import camera_rays_m
from pipeline.solve.estimate import Estimate, Status
from pipeline.solve.observations import Observations
from pipeline.terrain.dem import Dem


def dem_points(obs: Observations, dem: Dem, origin_lla, labels: list[str] | None = None, pixels_shown=None):
    """Per view: the ground point (n, 3) in the world frame (ENU at origin_lla, metres) where the ray through its
    pixel meets the DEM, NaN where the view has no pixel or the ray misses; and the misses as one-line messages
    (view label, pixel, reason, DEM) keyed by view index. `pixels_shown` (n, 2): the pixels to name in those
    messages, as the user gave them (before undistortion); default the observations' own."""
    origin = tuple(float(v) for v in origin_lla)
    if labels is not None and len(labels) != obs.n:
        raise ObservationError(f"{len(labels)} labels for {obs.n} views")
    idx = np.flatnonzero(obs.has_pixel)
    points = np.full((obs.n, 3), np.nan)
    misses: dict[int, str] = {}
    if idx.size == 0:
        return points, misses
    try:
        C, a = camera_rays_m(obs.P[idx], obs.pixel[idx])
    except np.linalg.LinAlgError:
        raise ObservationError("a view's camera matrix P has a singular left 3x3 block") from None
    C_lla = lla_from_enu(C, origin)
    # the direction from the world ENU frame into the ENU frame at each camera, through ECEF
    R = np.swapaxes(R_ecef_from_enu(C_lla[:, 0], C_lla[:, 1]), -1, -2) @ R_ecef_from_enu(origin[0], origin[1])
    hits, reasons = dem.intersect_many(C_lla, np.einsum("kij,kj->ki", R, a))  # a Dem, or a FlatGround
    for j, i in enumerate(idx):
        if reasons[j] is None:
            points[i] = enu_from_lla(*hits[j], origin)
        else:
            name = labels[i] if labels is not None else f"view {i} (t_ns {int(obs.t_ns[i])})"
            u, v = obs.pixel[i] if pixels_shown is None else np.asarray(pixels_shown, dtype=np.float64)[i]
            where = getattr(dem, "label", None) or f"DEM {dem.path}"
            misses[int(i)] = f"{name} pixel ({u:.1f}, {v:.1f}): {reasons[j]} ({where})"
    return points, misses


def locate_dem(obs: Observations, dem: Dem, origin_lla, labels: list[str] | None = None,
               pixels_shown=None) -> Estimate:
    """The `dem` estimate: the median of the views' terrain points (world frame, metres), status CLOSED_FORM;
    extras: points_m (per view, None where no point), n_points, missed (the one-line messages of the views whose
    ray missed; `labels` and `pixels_shown` as in dem_points). Raises ObservationError when no view has a pixel,
    GeometryError when every ray misses (the first miss's message)."""
    points, misses = dem_points(obs, dem, origin_lla, labels, pixels_shown)
    ok = np.isfinite(points).all(axis=1)
    if not obs.has_pixel.any():
        raise ObservationError("dem: no view has a target pixel")
    if not ok.any():
        first = misses[min(misses)]
        more = f" (and {len(misses) - 1} more view(s) missed)" if len(misses) > 1 else ""
        raise GeometryError(f"dem: {first}{more}")
    X = np.median(points[ok], axis=0)
    extras = {"points_m": [p.tolist() if np.isfinite(p).all() else None for p in points],
              "n_points": int(ok.sum()), "missed": [misses[i] for i in sorted(misses)]}
    return Estimate(method="dem", position_m=X, iterations=0, status=Status.CLOSED_FORM, extras=extras)
