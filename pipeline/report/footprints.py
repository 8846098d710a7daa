"""Where a video flight's camera looked, for the report's map: the image's footprint on the ground at a few
observation frames and the frame-centre track (the image centre's ground point at every observation), beside the
payload's own frame centre where its KLV gives one (`GroupResult.tracking["payload_frame_centre_deg"]`).

Each frame's rays come from its projection matrix (`Observations.P`: the pose and the intrinsics the solvers
used, a zoom's included; lens distortion is left out, it moves a corner by pixels) through the image's corners,
edge midpoints and centre. They meet the ground on the flight's DEM where its config gives one
(`terrain.dem`, `pipeline.terrain.raycast`), else on the level plane at the ground's height: the median height of
the laser's points (each range along the image centre's ray: the rangefinder is boresighted), else the answer's
(the best estimate's, else the truth's). A ray that misses the ground (above the horizon, or past the DEM) is cut
at `FAR_FACTOR` times the distance to that ground, so an oblique view still draws.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from pipeline.geometry.frames import R_ecef_from_enu, lla_from_enu
from pipeline.geometry.rays import camera_rays_m
from pipeline.report.geometry import best_reference_m, geodetic_from_enu
from pipeline.results import GroupResult

FAR_FACTOR = 3.0  # a ray that meets no ground is drawn to this many times the reference point's distance
N_FOOTPRINTS = 4  # footprints drawn per flight (first, last and evenly between)


@dataclass
class Footprints:
    """frames (k,) observation rows with a footprint; frame_index (k,) their frame numbers (None if unknown);
    outline_lla (k, 8, 3) corner, edge-midpoint, corner ... of each footprint; centre_lla (n, 3) the image
    centre's ground point at every observation (NaN where it misses); payload_deg (m, 2) the payload's frame
    centres (lat, lon) at the observations that have one (None without); ground: what the rays met."""

    frames: np.ndarray
    frame_index: list
    outline_lla: np.ndarray
    centre_lla: np.ndarray
    payload_deg: np.ndarray | None
    ground: str


def _image_size(r: GroupResult) -> tuple[int, int] | None:
    cam = (r.settings or {}).get("camera_resolved") or {}
    w, h = cam.get("width_px"), cam.get("height_px")
    return (int(w), int(h)) if w and h else None


def _outline_px(w: int, h: int) -> np.ndarray:
    """(8, 2) corners and edge midpoints of a w x h image, clockwise from the top left (pixel edges)."""
    x0, y0, x1, y1 = -0.5, -0.5, w - 0.5, h - 0.5
    xm, ym = (x0 + x1) / 2, (y0 + y1) / 2
    return np.array([[x0, y0], [xm, y0], [x1, y0], [x1, ym], [x1, y1], [xm, y1], [x0, y1], [x0, ym]])


def _dem(r: GroupResult):
    terrain = (r.settings or {}).get("terrain")
    if not isinstance(terrain, dict) or not terrain.get("dem") or not Path(terrain["dem"]).is_file():
        return None
    from pipeline.errors import RidgelocError
    from pipeline.terrain.dem import Dem

    try:
        return Dem.open(terrain["dem"], vertical_datum=terrain.get("vertical_datum"))
    except RidgelocError:
        return None


def _ground_points(r: GroupResult, C: np.ndarray, d: np.ndarray, ref: np.ndarray, dem) -> np.ndarray:
    """(k, 3) ENU m where the rays (centres C, unit directions d, both (k, 3) ENU m) meet the ground (see the
    module docstring)."""
    far = FAR_FACTOR * np.linalg.norm(ref - C, axis=1)
    out = C + far[:, None] * d
    if dem is not None:
        from pipeline.terrain.raycast import intersect_rays

        origins = lla_from_enu(C, r.origin_lla)
        R0 = R_ecef_from_enu(*r.origin_lla[:2])
        d_local = np.einsum("kji,kj->ki", R_ecef_from_enu(origins[:, 0], origins[:, 1]), d @ R0.T)
        hit, _ = intersect_rays(dem, origins, d_local)
        ok = np.isfinite(hit).all(axis=1)
        if ok.any():
            from pipeline.geometry.frames import enu_from_lla

            out[ok] = enu_from_lla(hit[ok, 0], hit[ok, 1], hit[ok, 2], r.origin_lla)
        return out
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (ref[2] - C[:, 2]) / d[:, 2]
    ok = np.isfinite(t) & (t > 0) & (t < far)
    out[ok] = C[ok] + t[ok, None] * d[ok]
    return out


def flight_footprints(r: GroupResult, n_footprints: int = N_FOOTPRINTS) -> Footprints | None:
    """The footprints and frame-centre tracks of a video flight's result, or None where there is nothing to draw
    (no image size, no observation, no reference height)."""
    size = _image_size(r)
    obs = r.observations
    tracking = r.tracking or {}
    if size is None or obs is None or obs.n == 0 or "frame_index" not in tracking:
        return None
    n = obs.n
    outline = _outline_px(*size)
    centre_px = np.array([(size[0] - 1) / 2.0, (size[1] - 1) / 2.0])
    rows = np.unique(np.linspace(0, n - 1, min(n_footprints, n)).round().astype(int))
    # one batch of rays: 8 outline points of the chosen frames, then the centre of every frame
    P = np.concatenate([np.repeat(obs.P[rows], len(outline), axis=0), obs.P])
    px = np.concatenate([np.tile(outline, (len(rows), 1)), np.repeat(centre_px[None], n, axis=0)])
    C, d = camera_rays_m(P, px)
    laser = C[-n:] + obs.range_m[:, None] * d[-n:]
    laser = laser[np.isfinite(laser).all(axis=1)]
    ref = best_reference_m(r)
    if ref is None or not np.isfinite(ref).all():
        ref = r.truth_m
    if len(laser):  # the ground where the laser hit it; horizontally, the middle of those points
        ref = np.median(laser, axis=0)
    if ref is None or not np.isfinite(ref).all():
        return None
    ref = np.asarray(ref, dtype=np.float64)
    dem = _dem(r)
    ground = _ground_points(r, C, d, ref, dem)
    used = [i for i, u in zip(tracking["frame_index"], tracking.get("used") or [True] * len(tracking["frame_index"]),
                              strict=True) if u]
    payload = tracking.get("payload_frame_centre_deg")
    payload_deg = None
    if payload:
        pts = [p for p in payload if p is not None]
        payload_deg = np.array(pts, dtype=np.float64).reshape(-1, 2) if pts else None
    what = f"the DEM {Path(dem.path).name}" if dem is not None else \
        f"the level plane at {geodetic_from_enu(ref, r.origin_lla)[2]:.1f} m (ellipsoid), the " + \
        ("laser points' median height" if len(laser) else "answer's height")
    return Footprints(frames=rows, frame_index=[used[k] if k < len(used) else None for k in rows],
                      outline_lla=geodetic_from_enu(ground[:len(rows) * len(outline)].reshape(len(rows), -1, 3),
                                                    r.origin_lla),
                      centre_lla=geodetic_from_enu(ground[len(rows) * len(outline):], r.origin_lla),
                      payload_deg=payload_deg, ground=what)
