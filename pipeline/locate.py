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
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from pipeline.answer import Answer, choose_answer
from pipeline.errors import InputError, RidgelocError, none_located
from pipeline.geometry.frames import enu_from_lla
from pipeline.geometry.geodesic import pairwise_geodesic_m
from pipeline.ingest.photo import Photo
from pipeline.ingest.photo_views import PhotoViews, photo_heights_ellipsoid_m, photo_views
from pipeline.photo_errors import PhotoErrorModel, photo_error_model
from pipeline.solve import METHODS, Estimate, Status, solve, unsolved_status
from pipeline.solve.observations import Observations, Sigma
from pipeline.solve.propagate import ErrorSources
from pipeline.targets import in_image, unreadable_marks

#: a pixel within this fraction of the image width from the centre is taken to be where the laser points
LASER_PIXEL_TOLERANCE = 0.01
#: the rays of two or more marked photos agree under an image rotation when they meet in front of every camera
#: within this angle (deg) of each ray; one rotation is chosen when only it agrees, or when its worst angle is this
#: many times smaller than the other's (angles under ROTATION_FLOOR_DEG, a few pixels of a mark, count as equal)
ROTATION_AGREEMENT_DEG = 5.0
ROTATION_MARGIN = 4.0
ROTATION_FLOOR_DEG = 0.1
#: the `ground` method's defaults (docs/locate.md, "Answers with less"), 1 sigma: the relief between the take-off
#: point and the target (the take-off ground stands for the target's), the error of a stated ground height, the
#: barometric height above the take-off point (RelativeAltitude drifts by about a metre over a flight), and the
#: gimbal's tilt and roll (gravity-referenced: a few tenths of a degree; the heading's error is the compass bias)
GROUND_RELIEF_SIGMA_M = 5.0
GROUND_STATED_SIGMA_M = 2.0
RELATIVE_ALT_SIGMA_M = 1.0
GROUND_TILT_SIGMA_DEG = 0.5


@dataclass(frozen=True)
class GroundAssumption:
    """The level ground of the `ground` method: "takeoff" (each photo's alt_m - relative_alt_m) or "height"
    (`height_m` on the photos' altitude datum); `sigma_m` its 1-sigma error at the target (None: the default)."""

    kind: str
    height_m: float | None = None
    sigma_m: float | None = None


@dataclass
class PhotoLocation:
    """Every method's answer: estimates {method: Estimate} in ENU at views.origin_lla; unsolved {method: (status,
    reason)}; the observations built; notes (how the image rotation was found, the weaker flat-ground answer)."""

    views: PhotoViews
    obs: Observations
    errors: PhotoErrorModel
    estimates: dict[str, Estimate] = field(default_factory=dict)
    unsolved: dict[str, tuple[str, str]] = field(default_factory=dict)
    notes: list[str] = field(default_factory=list)
    #: method -> the part of its covariance (3, 3) ENU m^2 that moves it as a whole, not its geometry's (`ground`:
    #: the assumed ground's error, the camera's position offset); the answer rule leaves it out of "determined"
    whole_covariance_m2: dict[str, np.ndarray] = field(default_factory=dict)


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


def _ray_disagreement_deg(views: PhotoViews, pixel_px, marked: np.ndarray) -> float:
    """The worst angle (deg) between a marked photo's ray and the direction from its camera to the rays'
    least-squares meeting point, inf when that point lies behind a camera or the rays are parallel."""
    from pipeline.geometry.rays import camera_rays_m, meeting_point

    idx = np.flatnonzero(marked)
    C, d = camera_rays_m(views.P[idx], views.pinhole_pixels(np.asarray(pixel_px)[idx], idx))
    X, _, _ = meeting_point(C, d)
    if not np.isfinite(X).all():
        return float("inf")
    to_x = X - C
    depth = np.einsum("ij,ij->i", to_x, d)
    if (depth <= 0).any():
        return float("inf")
    cos = depth / np.linalg.norm(to_x, axis=1)
    return float(np.degrees(np.arccos(np.clip(cos, -1.0, 1.0))).max())


def image_rotations(photos: list[Photo], pixel_px=None, stated: int | None = None) -> tuple[np.ndarray, str | None]:
    """(n,) the rotation (0 or 180 deg) of each photo's stored pixels against its camera's, and a note saying how it
    was found (None when nothing was in doubt). `stated` applies to every photo. Otherwise a photo re-saved by a
    desktop program (Photo.resaved_by) whose pixel is off its centre is in doubt: with two or more marked photos the
    rotation (one for all re-saved photos) is the one under which their rays meet in front of every camera
    (ROTATION_AGREEMENT_DEG, ROTATION_MARGIN); InputError naming the photo when that cannot tell, or when it is the
    only marked photo."""
    n = len(photos)
    if stated is not None:
        if stated not in (0, 180):
            raise InputError(f"image rotation must be 0 or 180 degrees, got {stated}")
        return np.full(n, int(stated)), None
    zeros = np.zeros(n, dtype=int)
    if pixel_px is None:
        return zeros, None
    px = _file_pixels(photos, pixel_px)
    marked = np.isfinite(px).all(axis=1)
    resaved = np.array([bool(p.resaved_by) for p in photos])
    doubt = resaved & marked & ~at_laser_pixel(photos, np.where(marked[:, None], px, 0.0))
    if not doubt.any():
        return zeros, None
    first = photos[int(np.flatnonzero(doubt)[0])]
    what = (f"re-saved after capture by {first.resaved_by!r}, which may have turned its pixels against the pose: "
            "mark the target in a second overlapping photo (the rotation is then found from the rays), or state "
            "--image-rotation 0 or 180")
    if marked.sum() < 2 or any(p.intrinsics is None for p in photos):
        raise InputError(what, path=first.path)
    worst = {}
    for h in (0, 180):
        worst[h] = _ray_disagreement_deg(photo_views(photos, rotation_deg=np.where(resaved, h, 0)), px, marked)
    good = [h for h in (0, 180) if worst[h] <= ROTATION_AGREEMENT_DEG]
    if len(good) == 2:
        best, other = sorted(good, key=lambda h: worst[h])
        good = [best] if worst[other] > ROTATION_MARGIN * max(worst[best], ROTATION_FLOOR_DEG) else []
    if len(good) != 1:
        raise InputError(f"{what} (the {int(marked.sum())} marked photos' rays do not tell: worst angle "
                         f"{worst[0]:.1f} deg unturned, {worst[180]:.1f} deg turned by 180)", path=first.path)
    h = good[0]
    names = ", ".join(p.name for p, r in zip(photos, resaved, strict=True) if r)
    other = "behind a camera" if not np.isfinite(worst[180 - h]) else f"{worst[180 - h]:.1f} deg"
    return np.where(resaved, h, 0), (f"image rotation {h} deg for the photos re-saved by a desktop program ({names}), "
                                     f"found from the marked photos' rays (they meet within {worst[h]:.2f} deg; "
                                     f"{other} under {180 - h}); state --image-rotation to override")


def level_ground(photos: list[Photo], ground: GroundAssumption, errors: PhotoErrorModel):
    """(FlatGround at an ellipsoidal height, sigma of the ground against the cameras, sigma of its absolute height,
    a phrase describing it). The take-off ground is the median over the photos of alt_m - relative_alt_m (InputError
    naming a photo that does not state its height above the take-off point)."""
    from pipeline.terrain.flat import FlatGround

    if ground.kind == "takeoff":
        missing = [p for p in photos if not np.isfinite(p.takeoff_ground_m)]
        if missing:
            raise InputError("--ground takeoff needs the photo's height above the take-off point (drone-dji:"
                             "RelativeAltitude), which it does not state: give the ground's height with "
                             "--ground-height-m", path=missing[0].path)
        h = photo_heights_ellipsoid_m([_with_alt(p, p.lat_deg, p.lon_deg, p.takeoff_ground_m) for p in photos])
        relief = GROUND_RELIEF_SIGMA_M if ground.sigma_m is None else ground.sigma_m
        rel = float(np.hypot(RELATIVE_ALT_SIGMA_M, relief))
        ab = float(np.sqrt(errors.shared_v_m ** 2 + rel ** 2))
        p0 = photos[0]
        what = (f"level ground at the take-off point's height ({np.median([p.takeoff_ground_m for p in photos]):.1f} "
                f"m {p0.alt_datum}: {p0.alt_source.split(' (')[0]} - {p0.relative_alt_source.split(' (')[0]}), "
                f"the target's ground assumed within {relief:g} m (1 sigma) of it")
    elif ground.kind == "height":
        if ground.height_m is None or not np.isfinite(ground.height_m) or abs(ground.height_m) > 20_000:
            raise InputError(f"--ground-height-m must be a height in metres, got {ground.height_m}")
        p0 = photos[0]
        h = photo_heights_ellipsoid_m([_with_alt(p0, p0.lat_deg, p0.lon_deg, float(ground.height_m))])
        stated = GROUND_STATED_SIGMA_M if ground.sigma_m is None else ground.sigma_m
        rel, ab = float(np.hypot(stated, errors.shared_v_m)), float(stated)
        what = (f"level ground at the stated {ground.height_m:g} m ({p0.alt_datum}, as the photos' altitude), within "
                f"{stated:g} m (1 sigma)")
    else:
        raise InputError(f"unknown ground {ground.kind!r} (takeoff, or a height with --ground-height-m)")
    if ground.sigma_m is not None and not (0 <= ground.sigma_m < float("inf")):
        raise InputError(f"--ground-sigma-m must be a finite number >= 0, got {ground.sigma_m}")
    return FlatGround(float(np.median(h)), what), rel, ab, what


def ground_estimate(obs: Observations, views: PhotoViews, photos: list[Photo], ground, errors: PhotoErrorModel,
                    pixel_px) -> tuple[Estimate, np.ndarray]:
    """The `ground` method: the rays cast onto level ground (as `dem` onto a DEM), with a covariance from the
    assumed ground's error and the pose's (pipeline.terrain.flat.ground_covariance_m2): per photo, the mean of the
    photos' covariances for several (their errors are mostly shared, so averaging photos shrinks little of it).
    Also the part of that covariance that moves the answer as a whole, as the DEM's own error moves `dem`'s: the
    assumed ground's height and the camera's position offset (the rest is the pose's: heading, tilt, pixel)."""
    import dataclasses

    from pipeline.terrain import ground_covariance_m2, locate_dem

    flat, rel, ab, what = ground
    e = locate_dem(obs, flat, views.origin_lla, labels=[p.name for p in photos],
                   pixels_shown=_file_pixels(photos, pixel_px))
    covs, pose = [], []
    for i, pt in enumerate(e.extras["points_m"]):
        if pt is None:
            continue
        for out, r, a, h in ((covs, rel, ab, errors.shared_h_m), (pose, 0.0, 0.0, 0.0)):
            out.append(ground_covariance_m2(
                views.camera_m[i], views.R_enu0_from_optical[i], obs.pixel[i], views.K[i], np.asarray(pt),
                sigma_relative_m=r, sigma_absolute_m=a, sigma_h_m=h,
                sigma_yaw_deg=float(np.hypot(errors.bias_prior_deg, errors.sigma.attitude_deg)),
                sigma_tilt_deg=float(np.hypot(GROUND_TILT_SIGMA_DEG, errors.sigma.attitude_deg)),
                sigma_px=errors.sigma.pixel_px))
    extras = dict(e.extras, assumption=f"a weaker answer: {what}")
    cov = np.mean(covs, axis=0)
    return dataclasses.replace(e, method="ground", covariance_m2=cov, extras=extras), cov - np.mean(pose, axis=0)


#: photos of one target lie within this of each other (km): twice the farthest a drone camera resolves a target
#: (about 25 km, the longest laser rangefinders' reach); farther apart they were taken of different places
ONE_SITE_KM = 50.0


def check_one_site(photos: list[Photo], pixel_px=None) -> None:
    """InputError naming the two photos farthest apart when the photos that see the target (the marked ones;
    all without pixels) were taken more than ONE_SITE_KM apart: one target is not seen from both."""
    use = [p for p, (u, v) in zip(photos, _file_pixels(photos, pixel_px), strict=True)
           if not (np.isnan(u) and np.isnan(v))] if pixel_px is not None else photos
    if len(use) < 2:
        return
    d_km = pairwise_geodesic_m([p.lat_deg for p in use], [p.lon_deg for p in use]) / 1000.0
    i, j = np.unravel_index(int(np.argmax(d_km)), d_km.shape)
    if d_km[i, j] > ONE_SITE_KM:
        raise InputError(f"{use[i].name} and {use[j].name} were taken {d_km[i, j]:,.0f} km apart: photos of one "
                         f"target lie within {ONE_SITE_KM:.0f} km of each other; locate each site's photos apart")


def locate_photos(photos: list[Photo], pixel_px=None, dem=None, rotation_deg: int | None = None,
                  errors: PhotoErrorModel | None = None, dem_sigma_m: float | None = None,
                  methods=None, ground: GroundAssumption | None = None) -> PhotoLocation:
    """Run every method (or `methods`) on the photos and one pixel per photo (see photo_observations), under the
    error model `errors` (default: the source's, pipeline.photo_errors). `dem` (pipeline.terrain.Dem) adds the
    `dem` method, and the MLE's terrain prior when its vertical sigma `dem_sigma_m` is stated (as a video flight's
    `terrain.vertical_sigma_m`: no stated sigma, no prior; docs/locate.md says why). rotation_deg: the files' pixels
    against the cameras' (0 or 180 for all), None to find it (image_rotations; its note in out.notes). `ground`
    (GroundAssumption) adds the `ground` method: the weaker answer on assumed level ground, with its note."""
    check_one_site(photos, pixel_px)
    rotations, note = image_rotations(photos, pixel_px, rotation_deg)
    views = photo_views(photos, rotation_deg=rotations)
    obs = photo_observations(views, pixel_px, None if errors is None else errors.sigma)
    if errors is None:
        errors = photo_error_model(photos, obs.range_m)
    out = PhotoLocation(views, obs, errors, notes=[note] if note else [])
    wanted = list(methods) if methods is not None else [*METHODS, "dem", "dji", *(["ground"] if ground else [])]
    from pipeline.terrain.flight import terrain_prior

    terrain = terrain_prior(dem, dem_sigma_m, views.origin_lla)
    flat = level_ground(photos, ground, errors) if ground is not None else None
    if flat is not None:
        out.notes.append(f"ground: {flat[3]}; a weaker answer than a laser's or a DEM's, its uncertainty includes "
                         "the assumed ground's (docs/locate.md)")
    for m in wanted:
        try:
            if m == "ground":
                if flat is None:
                    out.unsolved[m] = ("insufficient_data", "no ground assumed (--ground takeoff or "
                                                            "--ground-height-m)")
                    continue
                e, out.whole_covariance_m2[m] = ground_estimate(obs, views, photos, flat, errors, pixel_px)
            elif m == "dji":
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
    flight in pan (in tilt, the gimbal's gravity-referenced pitch: as large as its noise), the position offset every
    photo shares (`pipeline.photo_errors`)."""
    s = errors.sigma
    defaults = ErrorSources.from_sigma(s)
    # the compass's bias is the pan's; the gimbal's pitch, referenced to gravity, errs by its photo-to-photo noise
    return ErrorSources(pixel_px=defaults.pixel_px, range_m=defaults.range_m,
                        pointing_bias_deg=float(errors.bias_prior_deg), pointing_drift_deg=0.0,
                        pointing_noise_deg=float(s.attitude_deg or 0.0),
                        shared_covariance_m2=errors.shared_covariance_m2(),
                        pointing_bias_tilt_deg=min(float(errors.bias_prior_deg), float(s.attitude_deg or 0.0)))


def photo_answer(loc: PhotoLocation, dem=None, dem_sigma_m: float | None = None) -> Answer:
    """The target's one answer from every method's estimate on the photos (`pipeline.answer`)."""
    from pipeline.terrain.flight import dem_answer_inputs

    unsolved = {m: reason for m, (_, reason) in loc.unsolved.items()}
    answer = choose_answer(loc.obs, loc.estimates, unsolved, loc.views.origin_lla,
                           sources=error_sources(loc.errors), whole_covariance=loc.whole_covariance_m2,
                           **dem_answer_inputs(dem, dem_sigma_m, loc.obs, loc.views.origin_lla,
                                               loc.estimates.get("dem")))
    why = None if answer.located else _one_method_reason(loc, answer)
    return answer if why is None else replace(answer, reason=why)


def _one_method_reason(loc: PhotoLocation, answer: Answer) -> str | None:
    """Why the photos' target is not located where one method alone could run (had the data it needs) and gave
    no answer: that method and its own reason (a ray that misses the DEM, a ray above the horizon), which says
    what to do, rather than the MLE's want of a second pixel; None where none or several could."""
    tried = [(m, r) for m, (status, r) in loc.unsolved.items() if status != "insufficient_data"]
    tried += [(m, answer.verdicts[m].reason) for m in loc.estimates
              if m in answer.verdicts and not answer.verdicts[m].determined]
    if len(tried) != 1:
        return None
    method, why = tried[0]
    return why if why.startswith(f"{method}: ") else f"{method}: {why}"


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
    for key in ("n_points", "missed", "assumption"):
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
        if not (np.isfinite(u) and np.isfinite(v)):
            raise InputError(f"pixel ({u:g}, {v:g}) is not a pair of finite numbers", path=p.path)
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
        raise none_located(failed, config.path)
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

    t0 = time.perf_counter()
    loc = locate_photos(photos, pixels, dem=dem, dem_sigma_m=dem_sigma)
    if not loc.estimates:
        reasons = "; ".join(r if r.startswith(f"{m}: ") else f"{m}: {r}" for m, (_, r) in loc.unsolved.items())
        unmarked = unmarked_reason(loc, pixels, "files.marks, marks_file:")
        raise InputError(f"no method could locate the target from the photos: {unmarked}{reasons}", config.path)
    return location_result(config.name, config.to_dict(), loc, notes, truth, target, dem, dem_sigma,
                           time.perf_counter() - t0)


def unmarked_reason(loc: PhotoLocation, pixels, how: str) -> str:
    """Why several photos without a marked target and without a laser locate nothing, to lead their reason: each
    image centre is another ground point, which no baseline makes meet (`how`: where the marks go). Empty
    otherwise."""
    if pixels is not None or loc.obs.n < 2 or loc.obs.has_range.any():
        return ""
    return (f"the target is not marked ({how}), so each photo's image centre is taken, where a laser would point, "
            "and these photos have no laser range: mark the target in the photos with `ridgeloc mark`; ")


def location_result(name: str, settings: dict, loc: PhotoLocation, notes: list[str], truth=None, target=None,
                    dem=None, dem_sigma_m: float | None = None, elapsed_s: float = 0.0, unmarked: str = ""):
    """A photo location as the GroupResult the outputs take (`ridgeloc run` of a photo flight, `ridgeloc locate
    -o`): its estimates, the answer (`photo_answer`), the truth (lat, lon, h) where known, the error model in
    the settings. `unmarked` (`unmarked_reason`) leads the reason of an answer that is not located."""
    from pipeline.geometry.rays import intersection_angle_deg
    from pipeline.results import GroupResult

    truth_m = None if truth is None else enu_from_lla(*truth, origin_lla=loc.views.origin_lla)
    answer = photo_answer(loc, dem, dem_sigma_m)
    if unmarked and not answer.located:
        answer = replace(answer, reason=unmarked + answer.reason)
    ref = truth_m if truth_m is not None else (answer.position_m if answer.located else next(
        (e.position_m for e in loc.estimates.values()), None))
    seen = loc.obs.has_pixel | loc.obs.has_range
    gamma = intersection_angle_deg(loc.obs.platform_m[seen], ref) if seen.sum() >= 2 and ref is not None else \
        float("nan")
    settings = dict(settings)
    settings["notes"] = list(notes)
    settings["solve_failures"] = {m: {"status": s, "reason": r} for m, (s, r) in loc.unsolved.items()}
    settings["photos"] = [p.path for p in loc.views.photos]
    # the zone of the first photo's time (pipeline.ingest.photo): "unknown" is the camera's local clock, not UTC
    settings["photo_time_zone"] = loc.views.photos[0].time_zone if loc.views.photos else "unknown"
    settings["error_model"] = loc.errors.to_dict()
    return GroupResult(name=name, origin_lla=loc.views.origin_lla, observations=loc.obs,
                       estimates=loc.estimates, truth_m=truth_m, intersection_angle_deg=gamma,
                       timings_s={"locate": elapsed_s}, settings=settings, target=target, answer=answer)


def marks_target_name(path: str) -> str | None:
    """The target's name in a marks CSV of `ridgeloc mark` (`name,frame_or_image,x_px,y_px`, one target), None for
    a `photo,x_px,y_px` file (no name). The file is read as `read_marks` reads it (its errors are raised there)."""
    try:
        with open(path, encoding="utf-8-sig") as f:
            if not f.readline().strip().startswith("name,"):
                return None
    except (OSError, UnicodeDecodeError):
        return None
    from pipeline.targets import read_marks_csv

    targets = read_marks_csv(path)
    return targets[0].name if len(targets) == 1 else None


def read_marks(path: str, photos) -> list:
    """(n, 2) pixels (NaN where a photo is not listed) from a marks CSV `photo,x_px,y_px`, or from the marks CSV of
    `ridgeloc mark` (`name,frame_or_image,x_px,y_px`, pipeline.targets) holding one target."""
    try:
        with open(path, encoding="utf-8-sig") as f:
            first = f.readline()
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(unreadable_marks(exc), path=path) from None
    if first.strip().startswith("name,"):
        from pipeline.targets import read_marks_csv

        targets = read_marks_csv(path)
        if len(targets) != 1:
            names = ", ".join(t.name for t in targets[:5])
            raise InputError(f"holds {len(targets)} targets ({names}): locate takes one; keep one target's rows, or "
                             "name the file in a photo flight config's marks_file: and use `ridgeloc run`", path=path)
        return target_pixels(targets[0], photos)
    try:
        with open(path, newline="") as f:
            rows = list(csv.DictReader(f))
    except (OSError, UnicodeDecodeError, csv.Error) as exc:
        raise InputError(unreadable_marks(exc), path=path) from None
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
    if not by_name:  # an empty file, or a header alone: not "no target pixel anywhere" further on
        raise InputError("holds no marks: want a header photo,x_px,y_px and a row per marked photo", path=path)
    unknown = sorted(set(by_name) - {p.name for p in photos})
    if unknown:
        raise InputError(f"marks for photos not given: {', '.join(unknown[:5])}", path=path)
    return np.array([by_name.get(p.name, (np.nan, np.nan)) for p in photos])
