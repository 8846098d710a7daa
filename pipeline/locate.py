"""Locate a target from drone photos (`ridgeloc locate`, docs/locate.md): the photos' poses and one pixel per
photo become `Observations` (P = K [R | -R c] in ENU at the first photo, the pinhole pixel, the camera centre as
platform, the laser range where the photo's LRF status is Normal and the pixel is the laser's, the image centre);
every estimator of `pipeline.solve` runs on them, plus `dem` (a GeoTIFF DEM, pipeline.terrain) and `dji` (the
photos' own LRFTarget*, the maker's one-shot answer, for comparison).

Error model (docs/locate.md, "Error model"; pipeline.photo_errors): the sigmas per photo and the constant parts
by source type, unless stated: the compass / gimbal-yaw bias constant over a flight is the MLE's boresight bias with
a fixed prior (`bias_prior_deg`); the GNSS and altitude datum offsets shared by every photo move the estimate by
the same vector and show in no residual, so their covariance is added to the MLE's; with a DEM the vertical part
is also an error of the terrain prior, whose sigma grows by it. `dem` is moved horizontally by a datum offset
/ tan(depression).
"""

from __future__ import annotations

import csv
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from pipeline.answer import Answer, choose_answer
from pipeline.errors import InputError, RidgelocError
from pipeline.geometry.frames import enu_from_lla
from pipeline.ingest.photo import Photo
from pipeline.ingest.photo_views import PhotoViews, photo_heights_ellipsoid_m, photo_views
from pipeline.photo_errors import PhotoErrorModel, photo_error_model
from pipeline.solve import METHODS, Estimate, Status, solve, unsolved_status
from pipeline.solve.observations import Observations, Sigma
from pipeline.solve.propagate import ErrorSources
from pipeline.targets import in_image

#: a pixel within this fraction of the image width from the centre is taken to be where the laser points
LASER_PIXEL_TOLERANCE = 0.01


@dataclass
class PhotoLocation:
    """Every method's answer: estimates {method: Estimate} in ENU at views.origin_lla; unsolved {method: (status,
    reason)}; the observations built."""

    views: PhotoViews
    obs: Observations
    errors: PhotoErrorModel
    estimates: dict[str, Estimate] = field(default_factory=dict)
    unsolved: dict[str, tuple[str, str]] = field(default_factory=dict)


def photo_observations(views: PhotoViews, pixel_px=None, sigma: Sigma | None = None) -> Observations:
    """Observations of photos' views: pixel_px (n, 2) in the files' frame (NaN row: not seen; None: every image
    centre); ranges where the LRF is valid and the pixel is the image centre."""
    photos = views.photos
    px = _file_pixels(photos, pixel_px)
    at_centre = at_laser_pixel(photos, pixel_px)
    rng = np.array([p.lrf_range_m if (p.lrf_valid and c) else np.nan for p, c in zip(photos, at_centre, strict=True)])
    t = np.array([p.t_ns if p.t_ns is not None else i for i, p in enumerate(photos)], dtype=np.int64)
    if sigma is None:
        sigma = photo_error_model(photos, rng).sigma
    return Observations(P=views.P, pixel=views.pinhole_pixels(px), platform_m=views.camera_m, range_m=rng,
                        t_ns=t, sigma=sigma)


def at_laser_pixel(photos: list[Photo], pixel_px) -> np.ndarray:
    """(n,) bool: the photo's pixel is where its laser points (within LASER_PIXEL_TOLERANCE of the image width from
    the image centre; every photo when pixel_px is None)."""
    centre = _file_pixels(photos, None)
    width = np.array([p.width_px for p in photos], dtype=np.float64)
    return np.linalg.norm(_file_pixels(photos, pixel_px) - centre, axis=1) <= LASER_PIXEL_TOLERANCE * width


def _file_pixels(photos: list[Photo], pixel_px) -> np.ndarray:
    """(n, 2) the pixels as the user gave them (the image centres when none), to name in messages."""
    if pixel_px is None:
        return np.array([[(p.width_px - 1) / 2.0, (p.height_px - 1) / 2.0] for p in photos])
    return np.asarray(pixel_px, dtype=np.float64).reshape(len(photos), 2)


def mle_options(errors: PhotoErrorModel, terrain=None) -> dict:
    """Options for solve("mle"): the compass bias's fixed prior, and the terrain prior `terrain=(fn, sigma_m)` when
    a DEM is given, its sigma grown by the shared vertical offset (the DEM is in the true datum, the photos' heights
    are not)."""
    o = {"bias_prior_deg": float(errors.bias_prior_deg)}
    if terrain is not None:
        fn, sigma_m = terrain
        o["terrain"] = (fn, float(np.hypot(sigma_m, errors.shared_v_m)))
    return o


def with_shared_offset(e: Estimate, errors: PhotoErrorModel) -> Estimate:
    """The MLE's estimate with the shared offset's covariance added (and its CEP and ellipsoid extras redone): every
    camera off by the same vector puts the target off by it too, which no residual shows."""
    import dataclasses

    from pipeline.solve.uncertainty import ellipsoid_json, summaries

    if e.covariance_m2 is None or not np.isfinite(e.covariance_m2).all():
        return e
    cov = np.asarray(e.covariance_m2) + errors.shared_covariance_m2()
    acc = summaries(cov[None])
    extras = dict(e.extras, cep50_m=float(acc["cep50_m"][0]), cep90_m=float(acc["cep90_m"][0]),
                  error_model=errors.to_dict(),
                  ellipsoid=ellipsoid_json(acc["ellipsoid_semi_axes_1sigma_m"][0], acc["ellipsoid_axes"][0]))
    return dataclasses.replace(e, covariance_m2=cov, extras=extras)


def dji_estimate(views: PhotoViews, use=None) -> Estimate | None:
    """The mean of the photos' own laser targets (LRFTargetLat/Lon/AbsAlt, on the photos' altitude datum) in ENU,
    of the photos `use` (n,) bool (default all: those where the target is where the laser points); extras: per-photo
    points. None when no such photo has one."""
    pts = []
    for p, ok in zip(views.photos, np.ones(len(views.photos), bool) if use is None else use, strict=True):
        if p.dji_target_lla is None or not ok:
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


def locate_photos(photos: list[Photo], pixel_px=None, dem=None, rotation_deg: int = 0,
                  errors: PhotoErrorModel | None = None, dem_sigma_m: float | None = None,
                  methods=None) -> PhotoLocation:
    """Run every method (or `methods`) on the photos and one pixel per photo (see photo_observations), under the
    error model `errors` (default: the source's, pipeline.photo_errors). `dem` (pipeline.terrain.Dem) adds the
    `dem` method, and the MLE's terrain prior when its vertical sigma `dem_sigma_m` is stated (as a video flight's
    `terrain.vertical_sigma_m`: no stated sigma, no prior; docs/locate.md says why)."""
    views = photo_views(photos, rotation_deg=rotation_deg)
    obs = photo_observations(views, pixel_px, None if errors is None else errors.sigma)
    if errors is None:
        errors = photo_error_model(photos, obs.range_m)
    out = PhotoLocation(views, obs, errors)
    wanted = list(methods) if methods is not None else [*METHODS, "dem", "dji"]
    from pipeline.terrain.flight import terrain_prior

    terrain = terrain_prior(dem, dem_sigma_m, views.origin_lla)
    for m in wanted:
        try:
            if m == "dji":
                e = dji_estimate(views, at_laser_pixel(photos, pixel_px))
                if e is None:
                    out.unsolved[m] = ("insufficient_data", "no photo with the target where its laser points has "
                                                            "drone-dji:LRFTargetLat/Lon/AbsAlt")
                    continue
            elif m == "dem":
                if dem is None:
                    out.unsolved[m] = ("insufficient_data", "no DEM given (--dem)")
                    continue
                from pipeline.terrain import locate_dem
                e = locate_dem(obs, dem, views.origin_lla, labels=[p.name for p in photos],
                               pixels_shown=_file_pixels(photos, pixel_px))
            elif m == "mle":
                e = with_shared_offset(solve("mle", obs, **mle_options(errors, terrain)), errors)
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


def error_sources(errors: PhotoErrorModel) -> ErrorSources:
    """The errors propagated through the methods without a covariance of their own on a photo flight: the marked
    pixel and the laser per photo, the recorded attitude's photo-to-photo noise, the compass bias constant over the
    flight, the position offset every photo shares (`pipeline.photo_errors`)."""
    s = errors.sigma
    defaults = ErrorSources.from_sigma(s)
    return ErrorSources(pixel_px=defaults.pixel_px, range_m=defaults.range_m,
                        pointing_bias_deg=float(errors.bias_prior_deg), pointing_drift_deg=0.0,
                        pointing_noise_deg=float(s.attitude_deg or 0.0),
                        shared_covariance_m2=errors.shared_covariance_m2())


def photo_answer(loc: PhotoLocation, dem=None, dem_sigma_m: float | None = None) -> Answer:
    """The target's one answer from every method's estimate on the photos (`pipeline.answer`)."""
    from pipeline.terrain.flight import dem_answer_inputs

    unsolved = {m: reason for m, (_, reason) in loc.unsolved.items()}
    return choose_answer(loc.obs, loc.estimates, unsolved, loc.views.origin_lla, sources=error_sources(loc.errors),
                         **dem_answer_inputs(dem, dem_sigma_m, loc.obs, loc.views.origin_lla,
                                             loc.estimates.get("dem")))


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
    """InputError naming the photo when a pixel lies outside its image or is not a number (NaN in both
    coordinates: not marked there)."""
    for p, (u, v) in zip(photos, np.asarray(pixel_px, dtype=np.float64).reshape(-1, 2), strict=True):
        if np.isnan(u) and np.isnan(v):  # not marked in this photo
            continue
        if not in_image(u, v, p.width_px, p.height_px):
            raise InputError(f"pixel ({u:g}, {v:g}) is outside the {p.width_px}x{p.height_px} image", path=p.path)


def process_photo_group(config):
    """`ridgeloc run` of a flight config with `files: {photos: ...}` (issue 22): the photos located as `ridgeloc
    locate` does, marks from files.marks (else every image centre) as a GroupResult for the report; with named
    targets (`targets:` / `marks_file:`, a mark's image the photo's file name or its frame_index the photo's index in
    time order) a FlightResult of one GroupResult per target. Unreadable photos are left out with a note each; none
    readable is an InputError naming the config."""
    from pipeline.ingest.photo import read_photos
    from pipeline.results import FlightResult, TargetFailure
    from pipeline.targets import flight_targets

    photos, bad = read_photos(list(config.files.photos))
    notes = [f"photo left out: {err}" for _, err in bad]
    if not photos:
        raise InputError("no readable photo in files.photos", config.path)
    for p in photos:
        notes.extend(f"{p.name}: {w}" for w in p.warnings)
    from pipeline.terrain.flight import open_flight_dem

    dem = open_flight_dem(config.terrain)  # as a video flight: the `dem` method, a prior only with a stated sigma
    dem_sigma = None if config.terrain is None else config.terrain.vertical_sigma_m
    if not (config.targets or config.marks_file):
        pixels = read_marks(config.files.marks, photos) if config.files.marks else None
        if pixels is not None:
            check_pixels(photos, pixels)
        return _photo_result(config, photos, pixels, dem, dem_sigma, notes, config.truth_lla(), None)
    from pipeline.target_stage import truth_file_targets

    results, failed = [], []
    truth_entries = truth_file_targets(config)  # read once for every target
    for t in flight_targets(config):
        try:
            pixels = target_pixels(t, photos)
            check_pixels(photos, pixels)
            truth = t.truth_lla if t.truth_lla is not None else truth_entries.get(t.name)
            results.append(_photo_result(config, photos, pixels, dem, dem_sigma, notes, truth, t.name))
        except RidgelocError as exc:
            failed.append(TargetFailure(t.name, str(exc), tuple([*METHODS, "dem", "dji"])))
    if not results:
        raise InputError("no target could be located: " + "; ".join(f"{f.target}: {f.message}" for f in failed),
                         config.path)
    settings = {k: v for k, v in results[0].settings.items() if k != "solve_failures"}
    timings = {"locate": sum(r.timings_s["locate"] for r in results)}
    return FlightResult(name=config.name, targets=results, failed=failed, timings_s=timings, settings=settings)


def target_pixels(target, photos: list[Photo]) -> np.ndarray:
    """(n, 2) file pixels of a named target (pipeline.targets.NamedTarget) in the photos, NaN where it has no mark:
    a mark's image (a marks file's frame_or_image) names the photo, a frame_index is the photo's index in time
    order. ConfigError naming the mark's source for a photo not in the flight or marked twice."""
    from pipeline.errors import ConfigError

    by_path = {str(Path(p.path).resolve()): i for i, p in enumerate(photos)}
    px = np.full((len(photos), 2), np.nan)
    for m in target.marks:
        if m.template is not None:
            i = by_path.get(str(Path(m.template).resolve()))
            where, xy = Path(m.template).name, m.template_pixel
            if xy is None:
                raise ConfigError(f"{m.source}: a photo mark needs the target's pixel in {where}")
        else:
            i = m.frame_index if 0 <= m.frame_index < len(photos) else None
            where, xy = f"photo index {m.frame_index}", m.pixel
        if i is None:
            raise ConfigError(f"{m.source}: {where} is not one of the flight's {len(photos)} readable photos")
        if np.isfinite(px[i]).all():
            raise ConfigError(f"{m.source}: target {target.name!r} is marked twice in {photos[i].name}")
        px[i] = xy
    return px


def _photo_result(config, photos, pixels, dem, dem_sigma, notes, truth, target):
    """One target of a photo flight located: its GroupResult (target: its name, or None for the single target)."""
    import time

    from pipeline.geometry.rays import intersection_angle_deg
    from pipeline.results import GroupResult

    t0 = time.perf_counter()
    loc = locate_photos(photos, pixels, dem=dem, dem_sigma_m=dem_sigma)
    if not loc.estimates:
        reasons = "; ".join(f"{m}: {r}" for m, (_, r) in loc.unsolved.items())
        raise InputError(f"no method could locate the target from the photos: {reasons}", config.path)
    truth_m = None if truth is None else enu_from_lla(*truth, origin_lla=loc.views.origin_lla)
    ref = truth_m if truth_m is not None else next(iter(loc.estimates.values())).position_m
    seen = loc.obs.has_pixel | loc.obs.has_range
    gamma = intersection_angle_deg(loc.obs.platform_m[seen], ref) if seen.sum() >= 2 else float("nan")
    settings = config.to_dict()
    settings["notes"] = list(notes)
    settings["solve_failures"] = {m: {"status": s, "reason": r} for m, (s, r) in loc.unsolved.items()}
    settings["photos"] = [p.path for p in photos]
    settings["error_model"] = loc.errors.to_dict()
    answer = photo_answer(loc, dem, dem_sigma)
    return GroupResult(name=config.name, origin_lla=loc.views.origin_lla, observations=loc.obs,
                       estimates=loc.estimates, truth_m=truth_m, intersection_angle_deg=gamma,
                       timings_s={"locate": time.perf_counter() - t0}, settings=settings, target=target,
                       answer=answer)


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
            name, px = Path(r["photo"]).name, (float(r["x_px"]), float(r["y_px"]))
        except (KeyError, TypeError, ValueError):
            raise InputError(f"line {i}: want photo,x_px,y_px with numbers", path=path) from None
        if not np.isfinite(px).all():
            raise InputError(f"line {i}: the pixel ({px[0]:g}, {px[1]:g}) is not a finite number", path=path)
        if name in by_name:
            raise InputError(f"line {i}: a second mark for photo {name}", path=path)
        by_name[name] = px
    unknown = sorted(set(by_name) - {p.name for p in photos})
    if unknown:
        raise InputError(f"marks for photos not given: {', '.join(unknown[:5])}", path=path)
    return np.array([by_name.get(p.name, (np.nan, np.nan)) for p in photos])
