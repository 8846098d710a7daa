"""Locate a target from drone photos (`ridgeloc locate`, docs/locate.md): the photos' poses and one pixel per
photo become `Observations` (P = K [R | -R c] in ENU at the first photo, the pinhole pixel, the camera centre as
platform, the laser range where the photo's LRF status is Normal and the pixel is the laser's, the image centre);
every estimator of `pipeline.solve` runs on them, plus `dem` (a GeoTIFF DEM, pipeline.terrain) and `dji` (the
photos' own LRFTarget*, the maker's one-shot answer, for comparison).

Error model for consumer drones (docs/locate.md): compass/gimbal yaw errors of 1-5 deg that stay constant over a
flight are the MLE's boresight bias. PHOTO_SIGMA states the attitude sigma as the largest such bias (5 deg): the MLE
then learns the bias's size from the flight (its bias mixture, docs/solvers.md) and carries the GNSS error as an
offset shared by the photos; a fixed bias prior (bias_prior_deg) may be stated instead. An altitude datum offset
shared by all photos moves every estimate by the same vector (no geometry sees it) except `dem`, which it moves
horizontally by offset / tan(depression).
"""

from __future__ import annotations

import csv
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from pipeline.errors import InputError, RidgelocError
from pipeline.geometry.frames import enu_from_lla
from pipeline.ingest.photo import Photo
from pipeline.ingest.photo_views import PhotoViews, photo_heights_ellipsoid_m, photo_views
from pipeline.solve import METHODS, Estimate, Status, solve, unsolved_status
from pipeline.solve.observations import Observations, Sigma

#: consumer drone defaults: marking 2 px, DJI LRF ~1 m, GNSS 3 m, and the largest constant compass / gimbal-yaw
#: bias over a flight, 5 deg (the MLE learns the bias's size up to it)
PHOTO_SIGMA = Sigma(pixel_px=2.0, range_m=1.0, position_m=3.0, attitude_deg=5.0)
#: a pixel within this fraction of the image width from the centre is taken to be where the laser points
LASER_PIXEL_TOLERANCE = 0.01


@dataclass
class PhotoLocation:
    """Every method's answer: estimates {method: Estimate} in ENU at views.origin_lla; unsolved {method: (status,
    reason)}; the observations built."""

    views: PhotoViews
    obs: Observations
    estimates: dict[str, Estimate] = field(default_factory=dict)
    unsolved: dict[str, tuple[str, str]] = field(default_factory=dict)


def photo_observations(views: PhotoViews, pixel_px=None, sigma: Sigma = PHOTO_SIGMA) -> Observations:
    """Observations of photos' views: pixel_px (n, 2) in the files' frame (NaN row: not seen; None: every image
    centre); ranges where the LRF is valid and the pixel is the image centre."""
    photos = views.photos
    n = len(photos)
    centre = np.array([[(p.width_px - 1) / 2.0, (p.height_px - 1) / 2.0] for p in photos])
    px = centre.copy() if pixel_px is None else np.asarray(pixel_px, dtype=np.float64).reshape(n, 2)
    width = np.array([p.width_px for p in photos], dtype=np.float64)
    at_centre = np.linalg.norm(px - centre, axis=1) <= LASER_PIXEL_TOLERANCE * width
    rng = np.array([p.lrf_range_m if (p.lrf_valid and c) else np.nan for p, c in zip(photos, at_centre, strict=True)])
    t = np.array([p.t_ns if p.t_ns is not None else i for i, p in enumerate(photos)], dtype=np.int64)
    return Observations(P=views.P, pixel=views.pinhole_pixels(px), platform_m=views.camera_m, range_m=rng,
                        t_ns=t, sigma=sigma)


def _file_pixels(photos: list[Photo], pixel_px) -> np.ndarray:
    """(n, 2) the pixels as the user gave them (the image centres when none), to name in messages."""
    if pixel_px is None:
        return np.array([[(p.width_px - 1) / 2.0, (p.height_px - 1) / 2.0] for p in photos])
    return np.asarray(pixel_px, dtype=np.float64).reshape(len(photos), 2)


def mle_options(bias_prior_deg: float | None = None, terrain=None) -> dict:
    """Options for solve("mle"): a fixed bias prior when given (else the MLE learns the bias's size up to the
    attitude sigma), and the terrain prior `terrain=(fn, sigma_m)` when a DEM is given."""
    o = {} if bias_prior_deg is None else {"bias_prior_deg": float(bias_prior_deg)}
    if terrain is not None:
        o["terrain"] = terrain
    return o


def dji_estimate(views: PhotoViews) -> Estimate | None:
    """The mean of the photos' own laser targets (LRFTargetLat/Lon/AbsAlt, on the photos' altitude datum) in ENU;
    extras: per-photo points. None when no photo has one."""
    pts = []
    for p in views.photos:
        if p.dji_target_lla is None:
            continue
        lat, lon, alt = p.dji_target_lla
        h = photo_heights_ellipsoid_m([_with_alt(p, lat, lon, alt)])[0]
        pts.append(enu_from_lla(lat, lon, h, views.origin_lla))
    if not pts:
        return None
    pts = np.array(pts)
    return Estimate(method="dji", position_m=pts.mean(axis=0), iterations=0, status=Status.CLOSED_FORM,
                    extras={"points_m": pts.tolist(), "n_points": len(pts)})


def _with_alt(p: Photo, lat, lon, alt) -> Photo:
    import dataclasses

    return dataclasses.replace(p, lat_deg=lat, lon_deg=lon, alt_m=alt)


def locate_photos(photos: list[Photo], pixel_px=None, dem=None, rotation_deg: int = 0, sigma: Sigma = PHOTO_SIGMA,
                  bias_prior_deg: float | None = None, dem_sigma_m: float = 5.0,
                  methods=None) -> PhotoLocation:
    """Run every method (or `methods`) on the photos and one pixel per photo (see photo_observations)."""
    views = photo_views(photos, rotation_deg=rotation_deg)
    obs = photo_observations(views, pixel_px, sigma)
    out = PhotoLocation(views, obs)
    wanted = list(methods) if methods is not None else [*METHODS, "dem", "dji"]
    terrain = None
    if dem is not None:
        terrain = (dem.local(*views.origin_lla), float(dem_sigma_m))
    for m in wanted:
        try:
            if m == "dji":
                e = dji_estimate(views)
                if e is None:
                    out.unsolved[m] = ("insufficient_data", "no photo has drone-dji:LRFTargetLat/Lon/AbsAlt")
                    continue
            elif m == "dem":
                if dem is None:
                    out.unsolved[m] = ("insufficient_data", "no DEM given (--dem)")
                    continue
                from pipeline.terrain import locate_dem
                e = locate_dem(obs, dem, views.origin_lla, labels=[p.name for p in photos],
                               pixels_shown=_file_pixels(photos, pixel_px))
            elif m == "mle":
                e = solve("mle", obs, **mle_options(bias_prior_deg, terrain))
            else:
                e = solve(m, obs)
        except RidgelocError as exc:
            out.unsolved[m] = (unsolved_status(exc), str(exc))
            continue
        except (ValueError, np.linalg.LinAlgError) as exc:
            out.unsolved[m] = ("diverged", str(exc))
            continue
        if not np.isfinite(e.position_m).all():
            out.unsolved[m] = ("diverged", "no finite estimate")
            continue
        out.estimates[m] = e
    return out


def estimate_row(e: Estimate, views: PhotoViews) -> dict:
    """lat_deg, lon_deg, h_m (WGS84 ellipsoidal), alt_msl_m (EGM2008), cep50_m (None where undefined), the 95 %
    horizontal ellipse where there is a covariance, status, and the method's own extras that are small."""
    from pipeline.geometry.geoid import geoid_undulation_m
    from pipeline.report.geometry import uncertainty

    lat, lon, h = views.lla(e.position_m)
    n_m = float(geoid_undulation_m(lat, lon))
    u = uncertainty(e)
    row = {"lat_deg": float(lat), "lon_deg": float(lon), "h_m": float(h), "alt_msl_m": float(h - n_m),
           "cep50_m": u["cep50_m"], "status": e.status.name.lower(), "e_m": float(e.position_m[0]),
           "n_m": float(e.position_m[1]), "u_m": float(e.position_m[2])}
    if u["ellipse95_semi_major_m"] is not None:
        row.update({k: u[k] for k in ("cep90_m", "sigma_up_m", "ellipse95_semi_major_m", "ellipse95_semi_minor_m",
                                      "ellipse95_azimuth_deg")})
    for key in ("n_points", "missed"):
        if key in e.extras:
            row[key] = e.extras[key]
    bias = e.extras.get("boresight_bias")
    if isinstance(bias, dict):  # the MLE's constant pointing bias: camera-frame u (pan) and v (tilt) angles
        row["boresight_bias_deg"] = {k: float(bias[k]) for k in ("u_deg", "v_deg", "u_sigma_deg", "v_sigma_deg")
                                     if isinstance(bias.get(k), (int, float))}
    return row


def check_pixels(photos: list[Photo], pixel_px) -> None:
    """InputError naming the photo when a pixel lies outside its image."""
    for p, (u, v) in zip(photos, np.asarray(pixel_px, dtype=np.float64).reshape(-1, 2), strict=True):
        if np.isfinite(u) and not (-0.5 <= u <= p.width_px - 0.5 and -0.5 <= v <= p.height_px - 0.5):
            raise InputError(f"pixel ({u:g}, {v:g}) is outside the {p.width_px}x{p.height_px} image", path=p.path)


def process_photo_group(config):
    """`ridgeloc run` of a flight config with `files: {photos: ..., marks: ...}` (issue 22): the photos located as
    `ridgeloc locate` does (marks from files.marks, else every image centre), as a GroupResult for the report.
    Unreadable photos are left out with a note each; none readable is an InputError naming the config."""
    import time

    from pipeline.geometry.rays import intersection_angle_deg
    from pipeline.ingest.photo import read_photos
    from pipeline.results import GroupResult

    t0 = time.perf_counter()
    photos, bad = read_photos(list(config.files.photos))
    notes = [f"photo left out: {err}" for _, err in bad]
    if not photos:
        raise InputError("no readable photo in files.photos", config.path)
    pixels = read_marks(config.files.marks, photos) if config.files.marks else None
    if pixels is not None:
        check_pixels(photos, pixels)
    dem = None
    dem_sigma = 5.0
    terrain_cfg = getattr(config, "terrain", None)
    if terrain_cfg is not None:
        from pipeline.terrain import Dem
        dem = Dem.open(terrain_cfg.dem, vertical_datum=terrain_cfg.vertical_datum)
        dem_sigma = terrain_cfg.vertical_sigma_m or dem_sigma
    loc = locate_photos(photos, pixels, dem=dem, dem_sigma_m=dem_sigma)
    if not loc.estimates:
        reasons = "; ".join(f"{m}: {r}" for m, (_, r) in loc.unsolved.items())
        raise InputError(f"no method could locate the target from the photos: {reasons}", config.path)
    truth = config.truth_lla()
    truth_m = None if truth is None else enu_from_lla(*truth, origin_lla=loc.views.origin_lla)
    ref = truth_m if truth_m is not None else next(iter(loc.estimates.values())).position_m
    gamma = intersection_angle_deg(loc.obs.platform_m, ref) if loc.obs.n >= 2 else float("nan")
    for p in photos:
        notes.extend(f"{p.name}: {w}" for w in p.warnings)
    settings = config.to_dict()
    settings["notes"] = notes
    settings["solve_failures"] = {m: {"status": s, "reason": r} for m, (s, r) in loc.unsolved.items()}
    settings["photos"] = [p.path for p in photos]
    return GroupResult(name=config.name, origin_lla=loc.views.origin_lla, observations=loc.obs,
                       estimates=loc.estimates, truth_m=truth_m, intersection_angle_deg=gamma,
                       timings_s={"locate": time.perf_counter() - t0}, settings=settings)


def read_marks(path: str, photos) -> list:
    """(n, 2) pixels (NaN where a photo is not listed) from a marks CSV `photo,x_px,y_px`."""
    try:
        with open(path, newline="") as f:
            rows = list(csv.DictReader(f))
    except (OSError, UnicodeDecodeError, csv.Error) as exc:
        raise InputError(f"cannot read marks: {exc}", path=path) from None
    by_name = {}
    for i, r in enumerate(rows, start=2):
        try:
            by_name[Path(r["photo"]).name] = (float(r["x_px"]), float(r["y_px"]))
        except (KeyError, TypeError, ValueError):
            raise InputError(f"line {i}: want photo,x_px,y_px with numbers", path=path) from None
    unknown = sorted(set(by_name) - {p.name for p in photos})
    if unknown:
        raise InputError(f"marks for photos not given: {', '.join(unknown[:5])}", path=path)
    return np.array([by_name.get(p.name, (np.nan, np.nan)) for p in photos])
