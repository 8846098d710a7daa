"""Real lines of sight (docs/locate.md, "Real lines of sight"): a Skydio X2's photos of ten RTK-surveyed points from
a public field test of OpenAthena (../shared/real_rays/, its README), each point's photos located together by
`pipeline.locate.locate_photos` (the MLE under the photo error model of pipeline/photo_errors.py, no laser, no
DEM), against OpenAthena's single-photo terrain answers logged for the same photos and pixels.

Adapter (`photo_of_row`): one `Photo` per CSV row, in pipeline/geometry's conventions (gimbal (yaw, pitch, roll)
ZYX in local NED, as the DJI tags): pitch = -cameraSlantAngleDeg, roll = cameraRollAngleDeg (Skydio's
CameraOrientationNED, as OpenAthena reads it), the drone's height as WGS84 ellipsoidal (droneElevationHAE), K from
f_x, f_y with the principal point at the image centre and the OpenCV lens (k1, k2, p1, p2, k3), the pixel =
imageSelectedProportionX/Y x the image size. The CSV has no camera azimuth: OpenAthena adds the pixel's yaw offset
to the camera's azimuth and casts the ray along the sum, so the camera's azimuth is the azimuth of its answer from
the drone minus yawOffsetDegSelectedPoint (+180 deg where raySlantAngleDeg > 90: the ray leans back past nadir),
one per photo (`camera_yaw_deg`). `adapter_checks` verifies this on the data (rows of one photo give one azimuth;
OpenAthena's logged offsets come back from the pixel fraction by its formula). Truth: the horizontal position of
the point the row was assigned to (the field test's rule, README); heights are not judged (the survey's and the
drone's differ by tens of metres).

Prints the fused answer per point, then figures that do not rest on ten points alone: a bootstrap over points,
leave-one-photo-out, random subsets of 2-8 photos, the compass bias prior fitted on nine points and used on the
tenth, the rays' error split (within one photo against across photos), and the fused answer when the line of
sight is taken as the drone-to-answer direction (OpenAthena's own ray) instead of the ray through the pixel.

    python scripts/real_rays.py [--folder ../shared/real_rays] [--subsets 20] [--bootstrap 2000] [--seed 0]
                                [--attitude-deg A] [--photo-position-m P] [--bias-prior-deg B]

The last three state the per-photo attitude and position sigmas and the compass bias prior instead of the error
model's (as a user states them to `ridgeloc locate`).
"""

from __future__ import annotations

import argparse
import csv
import dataclasses
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

CHI2_2DOF_95 = 5.991464547107979
DEFAULT_FOLDER = Path(__file__).resolve().parents[1].parent / "shared" / "real_rays"
DIST_KEYS = ("k1", "k2", "p1", "p2", "k3")  # OpenCV order (pipeline.geometry.lens)


@dataclass(frozen=True)
class RealRays:
    """n rows of openathena_rays.csv and m surveyed points. Angles in degrees.

    answer_lla, drone_lla (n, 3) latitude, longitude, WGS84 ellipsoidal height; slant_deg, roll_deg, ray_slant_deg,
    yaw_offset_deg, pitch_offset_deg (n,);
    fraction_xy (n, 2) the tapped pixel as a fraction of the image; size_px (w, h), f_px (fx, fy), dist (5,) OpenCV;
    point (n,) index into names / point_lla (m, 3) the survey's latitude, longitude, Elevation (a height on a datum
    tens of metres from the drone's); photo (n,) index of the photo a row came from (rows of one
    photo share the drone's position and camera angles)."""

    answer_lla: np.ndarray
    drone_lla: np.ndarray
    slant_deg: np.ndarray
    roll_deg: np.ndarray
    ray_slant_deg: np.ndarray
    yaw_offset_deg: np.ndarray
    pitch_offset_deg: np.ndarray
    fraction_xy: np.ndarray
    size_px: tuple[int, int]
    f_px: tuple[float, float]
    dist: tuple[float, ...]
    point: np.ndarray
    photo: np.ndarray
    names: tuple[str, ...]
    point_lla: np.ndarray

    def rows_of(self, k: int) -> np.ndarray:
        return np.flatnonzero(self.point == k)


def read_real_rays(folder) -> RealRays:
    """The two CSVs of ../shared/real_rays; each row assigned to the surveyed point nearest (horizontally) to
    OpenAthena's answer, the field test's rule."""
    from pipeline.geometry.frames import enu_from_lla

    folder = Path(folder)
    with open(folder / "openathena_rays.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    with open(folder / "gcps.csv", newline="") as f:
        gcps = list(csv.DictReader(f))

    def col(*keys):
        return np.array([[float(r[k]) for k in keys] for r in rows]).squeeze()

    names = tuple(g["Remarks"].strip() for g in gcps)
    point_lla = np.array([[float(g["Latitude"]), float(g["Longitude"]), float(g["Elevation"])] for g in gcps])
    answer = col("lat", "lon", "hae")
    origin = tuple(point_lla.mean(axis=0))
    a_m = enu_from_lla(*answer.T, origin)
    p_m = enu_from_lla(*point_lla.T, origin)
    point = np.linalg.norm(a_m[:, None, :2] - p_m[None, :, :2], axis=2).argmin(axis=1)
    for key in ("imageWidth", "imageLength", "f_x", "f_y", *DIST_KEYS):
        if len({r[key] for r in rows}) != 1:
            raise ValueError(f"{folder / 'openathena_rays.csv'}: {key} differs between rows (one camera expected)")
    drone = col("droneLatitude", "droneLongitude", "droneElevationHAE")
    slant, roll = col("cameraSlantAngleDeg"), col("cameraRollAngleDeg")
    pose = [tuple(v) for v in np.c_[drone, slant, roll]]
    photo = np.array([list(dict.fromkeys(pose)).index(p) for p in pose])
    r0 = rows[0]
    return RealRays(answer_lla=answer, drone_lla=drone, slant_deg=slant, roll_deg=roll,
                    ray_slant_deg=col("raySlantAngleDeg"), yaw_offset_deg=col("yawOffsetDegSelectedPoint"),
                    pitch_offset_deg=col("pitchOffsetDegSelectedPoint"),
                    fraction_xy=col("imageSelectedProportionX", "imageSelectedProportionY"),
                    size_px=(int(float(r0["imageWidth"])), int(float(r0["imageLength"]))),
                    f_px=(float(r0["f_x"]), float(r0["f_y"])), dist=tuple(float(r0[k]) for k in DIST_KEYS),
                    point=point, photo=photo, names=names, point_lla=point_lla)


def answer_enu_m(rr: RealRays) -> np.ndarray:
    """(n, 3) OpenAthena's answer in ENU metres at the drone of its row."""
    from pipeline.geometry.frames import enu_from_lla

    return np.array([enu_from_lla(*a, tuple(d)) for a, d in zip(rr.answer_lla, rr.drone_lla, strict=True)])


def row_yaw_deg(rr: RealRays) -> tuple[np.ndarray, np.ndarray]:
    """((n,) each row's own camera azimuth (deg from true north): the answer's azimuth from the drone minus the
    pixel's yaw offset, +180 deg where the ray leans back past nadir (ray slant > 90); (n,) the answer's horizontal
    distance from the drone, m, which that azimuth's accuracy scales with)."""
    a = answer_enu_m(rr)
    az = np.degrees(np.arctan2(a[:, 0], a[:, 1]))
    return (az + np.where(rr.ray_slant_deg > 90.0, 180.0, 0.0) - rr.yaw_offset_deg) % 360.0, np.hypot(a[:, 0], a[:, 1])


def camera_yaw_deg(rr: RealRays) -> np.ndarray:
    """(n,) the camera azimuth of each row's photo: the mean direction of its rows' own azimuths, each weighted by
    its answer's horizontal distance (one photo, one azimuth; a near-nadir answer says little about it)."""
    az, w = row_yaw_deg(rr)
    out = np.empty(len(az))
    for p in np.unique(rr.photo):
        m = rr.photo == p
        s, c = (w[m] * np.sin(np.radians(az[m]))).sum(), (w[m] * np.cos(np.radians(az[m]))).sum()
        out[m] = np.degrees(np.arctan2(s, c)) % 360.0
    return out


def pixels_px(rr: RealRays, idx) -> np.ndarray:
    """(k, 2) file pixels of rows idx (the tapped point: fraction x image size, as OpenAthena computes it)."""
    return rr.fraction_xy[np.asarray(idx)] * np.array(rr.size_px, dtype=np.float64)


def photo_of_row(rr: RealRays, i: int, yaw_deg: float):
    """The `Photo` of row i: the drone's pose and the camera as the CSV states them (module docstring)."""
    from pipeline.ingest.photo import Photo
    from pipeline.ingest.photo_camera import PhotoIntrinsics

    w, h = rr.size_px
    intr = PhotoIntrinsics(rr.f_px[0], rr.f_px[1], w / 2.0, h / 2.0, rr.dist, "openathena_rays.csv f_x, f_y, k1-p2")
    lat, lon, alt = (float(v) for v in rr.drone_lla[i])
    return Photo(path=f"row{i:03d}.jpg", make="Skydio", model="X2", width_px=w, height_px=h, t_ns=int(i),
                 time_zone="unknown", lat_deg=lat, lon_deg=lon, alt_m=alt, alt_datum="ellipsoid",
                 alt_source="droneElevationHAE", relative_alt_m=float("nan"), gps_alt_m=float("nan"),
                 gimbal_ypr_deg=(float(yaw_deg), -float(rr.slant_deg[i]), float(rr.roll_deg[i])),
                 flight_ypr_deg=None, attitude_source="openathena_rays.csv", intrinsics=intr)


def openathena_offsets_deg(rr: RealRays, roll_sign: float = 1.0) -> np.ndarray:
    """(n, 2) the pixel's (yaw, pitch) offsets as OpenAthena for Android computed them for these rows
    (MetadataExtractor.getRayAnglesFromImgPixel: pixel minus the image centre over f, the k1, k2, p1, p2
    polynomial applied to that point, atan per axis, then rotated by the camera's roll; pitch logged up-positive).
    Only to check the adapter's pixel and roll conventions against the CSV (roll_sign -1: the roll taken the other
    way, to show the check can tell)."""
    k1, k2, p1, p2, _ = rr.dist
    x = (pixels_px(rr, np.arange(len(rr.point)))[:, 0] - rr.size_px[0] / 2.0) / rr.f_px[0]
    y = (pixels_px(rr, np.arange(len(rr.point)))[:, 1] - rr.size_px[1] / 2.0) / rr.f_px[1]
    r2 = x * x + y * y
    radial = 1 + k1 * r2 + k2 * r2 * r2
    xc = x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x)
    yc = y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y
    # theta: FRD pitch, up positive
    psi, theta, roll = np.arctan(xc), -np.arctan(yc), np.radians(roll_sign * rr.roll_deg)
    v = np.stack([np.cos(theta) * np.cos(psi), np.cos(theta) * np.sin(psi), np.sin(theta)])
    vy = np.cos(roll) * v[1] - np.sin(roll) * v[2]
    vz = np.sin(roll) * v[1] + np.cos(roll) * v[2]
    return np.degrees(np.c_[np.arctan2(vy, v[0]), np.arctan2(vz, np.hypot(v[0], vy))])


def adapter_checks(rr: RealRays) -> dict:
    """yaw_spread_deg: rows' own camera azimuths against their photo's, all rows but those off by more than 90 deg
    (far_side_rows: OpenAthena's answer lies on the other side of nadir from its ray; their photo's azimuth is used);
    offsets_max_diff_deg: the largest difference between OpenAthena's logged (yaw, pitch) offsets and its formula
    applied to the pixel fraction (pixel = fraction x size, centre w/2, h/2, roll as a ZYX roll), and
    offsets_roll_flipped_deg the same with the roll's sign flipped."""
    own, _ = row_yaw_deg(rr)
    d = np.abs((own - camera_yaw_deg(rr) + 180.0) % 360.0 - 180.0)
    logged = np.c_[rr.yaw_offset_deg, rr.pitch_offset_deg]
    return {"yaw_spread_deg": float(d[d <= 90.0].max()), "far_side_rows": np.flatnonzero(d > 90.0).tolist(),
            "offsets_max_diff_deg": float(np.abs(openathena_offsets_deg(rr) - logged).max()),
            "offsets_roll_flipped_deg": float(np.abs(openathena_offsets_deg(rr, -1.0) - logged).max())}


@dataclass(frozen=True)
class Fused:
    """One fused answer: horizontal error (m, against the surveyed point), m2 = e^T C^-1 e of the horizontal error
    under the answer's 2x2 covariance (inside the 95 % ellipse when <= 5.991), the MLE's Estimate."""

    error_m: float
    m2: float
    estimate: object


def fuse(rr: RealRays, idx, yaw_deg: np.ndarray, errors=None, line_of_sight: str = "pixel") -> Fused | None:
    """The MLE of `locate_photos` on rows idx (one view per row) under `errors` (default: the photos' own error
    model, pipeline.photo_errors); None when it does not solve. line_of_sight "answer": each view looks along the
    drone-to-answer direction instead (OpenAthena's ray: no lens, pixel at the centre, roll 0)."""
    from pipeline.geometry.frames import enu_from_lla
    from pipeline.locate import locate_photos

    idx = np.asarray(idx)
    photos = [photo_of_row(rr, int(i), yaw_deg[i]) for i in idx]
    px = pixels_px(rr, idx)
    if line_of_sight == "answer":
        a = answer_enu_m(rr)[idx]
        dep = np.degrees(np.arctan2(-a[:, 2], np.hypot(a[:, 0], a[:, 1])))
        az = np.degrees(np.arctan2(a[:, 0], a[:, 1]))
        photos = [dataclasses.replace(p, gimbal_ypr_deg=(float(z), -float(d), 0.0),
                                      intrinsics=dataclasses.replace(p.intrinsics, dist=(0.0,) * 5))
                  for p, z, d in zip(photos, az, dep, strict=True)]
        px = np.tile([rr.size_px[0] / 2.0, rr.size_px[1] / 2.0], (len(idx), 1))
    loc = locate_photos(photos, px, errors=errors, methods=["mle"])
    e = loc.estimates.get("mle")
    if e is None:
        return None
    k = int(rr.point[idx[0]])
    d = (e.position_m - enu_from_lla(*rr.point_lla[k], loc.views.origin_lla))[:2]
    cov = np.asarray(e.covariance_m2)[:2, :2]
    return Fused(float(np.hypot(*d)), float(d @ np.linalg.solve(cov, d)), e)


def single_photo_errors_m(rr: RealRays) -> np.ndarray:
    """(n,) horizontal error of OpenAthena's single-photo terrain answer against the row's surveyed point."""
    from pipeline.geometry.frames import enu_from_lla

    return np.array([float(np.hypot(*enu_from_lla(*rr.point_lla[k], tuple(a))[:2]))
                     for a, k in zip(rr.answer_lla, rr.point, strict=True)])


def ray_geometry(rr: RealRays, yaw_deg: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(n,) each: pan, the angle (deg), seen from the drone, between the ray through the row's pixel and its
    surveyed point across the ray (positive: the point lies right of it): the point's horizontal distance from the
    ray's vertical plane (across_m, independent of the heights' datum) over the ray's slant range there; gap, the
    angle (deg) between that ray and the direction to OpenAthena's answer (its own ray)."""
    from pipeline.geometry.frames import enu_from_lla
    from pipeline.geometry.rays import camera_rays_m
    from pipeline.ingest.photo_views import photo_views

    answer = answer_enu_m(rr)
    pan, gap, across_m = (np.empty(len(rr.point)) for _ in range(3))
    for i in range(len(pan)):
        v = photo_views([photo_of_row(rr, i, yaw_deg[i])], origin_lla=tuple(rr.drone_lla[i]))
        _, d = camera_rays_m(v.P, v.pinhole_pixels(pixels_px(rr, [i])))
        d = d[0]
        t = enu_from_lla(*rr.point_lla[rr.point[i]], v.origin_lla)
        h = d[:2] / np.linalg.norm(d[:2])
        across = float(h[1] * t[0] - h[0] * t[1])
        slant = abs(float(t[:2] @ h)) / max(float(np.hypot(d[0], d[1])), 1e-9)
        pan[i], across_m[i] = np.degrees(np.arctan2(across, slant)), across
        gap[i] = np.degrees(np.arccos(np.clip(d @ answer[i] / np.linalg.norm(answer[i]), -1.0, 1.0)))
    return pan, gap, across_m


def robust_sd(x) -> float:
    """1.4826 x the median absolute deviation."""
    x = np.asarray(x, dtype=np.float64)
    return float(1.4826 * np.median(np.abs(x - np.median(x))))


def inside(f: Fused | None) -> bool:
    return f is not None and f.m2 <= CHI2_2DOF_95


def azimuth_span_deg(az_deg) -> float:
    """The smallest arc (deg) that holds all the azimuths."""
    a = np.sort(np.asarray(az_deg, dtype=np.float64) % 360.0)
    gaps = np.diff(np.r_[a, a[0] + 360.0])
    return float(360.0 - gaps.max())


def per_point_table(rr: RealRays, yaw: np.ndarray, single: np.ndarray, errors=None) -> list:
    """Each point's photos fused (under `errors`, default the photos' own error model); prints one line per point
    (azimuths: the arc the point's photos look from; widened: the factor the MLE's fit check grew the ellipse's axes
    by, from the residuals' spread); the Fused list."""
    print("point        rows photos  azimuths  single-photo median m  fused m  95% ellipse m  widened  e'C-1e  "
          "inside  rows given no weight")
    fused = []
    for k, name in enumerate(rr.names):
        idx = rr.rows_of(k)
        f = fuse(rr, idx, yaw, errors)
        fused.append(f)
        head = (f"{name:11s} {len(idx):4d} {len(np.unique(rr.photo[idx])):6d}  {azimuth_span_deg(yaw[idx]):5.0f} deg  "
                f"{np.median(single[idx]):21.2f}")
        if f is None:
            print(f"{head}  not solved")
            continue
        cov = np.asarray(f.estimate.covariance_m2)[:2, :2]
        major, minor = np.sqrt(np.maximum(np.linalg.eigvalsh(cov), 0.0) * CHI2_2DOF_95)[::-1]
        widened = np.sqrt(f.estimate.extras.get("fit", {}).get("covariance_inflation", 1.0))
        nought = len({r["frame"] for r in f.estimate.extras.get("rejected", [])})
        print(f"{head}  {f.error_m:7.2f}  {major:5.1f} x {minor:4.1f}  {widened:5.1f} x  {f.m2:6.2f}  "
              f"{'yes' if inside(f) else 'NO':6s}  {nought}")
    return fused


def photo_subsets(rr: RealRays, yaw: np.ndarray, single: np.ndarray, rows: np.ndarray, sizes, per_point: int,
                  rng, errors=None) -> list[tuple[int, int, float, float, float]]:
    """Random subsets of `size` photos of a point (all their rows among `rows`, a boolean mask), per_point draws per
    point with more photos than that: (size, fusions, median error m, median error over the single-photo median
    of the same rows, share inside the 95 % ellipse)."""
    out = []
    for size in sizes:
        res = []
        for k in range(len(rr.names)):
            idx = np.flatnonzero((rr.point == k) & rows)
            photos = np.unique(rr.photo[idx])
            if len(photos) <= size:
                continue
            for _ in range(per_point):
                sub = idx[np.isin(rr.photo[idx], rng.choice(photos, size, replace=False))]
                f = fuse(rr, sub, yaw, errors)
                if f is not None:
                    res.append((f.error_m, f.error_m / np.median(single[sub]), inside(f)))
        if res:
            res = np.array(res)
            out.append((size, len(res), float(np.median(res[:, 0])), float(np.median(res[:, 1])),
                        float(res[:, 2].mean())))
    return out


def main() -> int:
    from scipy.stats import theilslopes

    from pipeline.photo_errors import photo_error_model

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--folder", default=str(DEFAULT_FOLDER))
    ap.add_argument("--subsets", type=int, default=20, help="random photo subsets per point and size")
    ap.add_argument("--bootstrap", type=int, default=2000, help="bootstrap resamples of the points")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--attitude-deg", type=float, help="per-photo attitude sigma instead of the error model's")
    ap.add_argument("--photo-position-m", type=float, help="per-photo position sigma instead of the error model's")
    ap.add_argument("--bias-prior-deg", type=float, help="compass bias prior instead of the error model's")
    args = ap.parse_args()
    missing = [n for n in ("openathena_rays.csv", "gcps.csv") if not (Path(args.folder) / n).is_file()]
    if missing:
        print(f"{args.folder}: no {' or '.join(missing)} (the real rays of ../shared/real_rays)", file=sys.stderr)
        return 1
    rr = read_real_rays(args.folder)
    yaw = camera_yaw_deg(rr)
    chk = adapter_checks(rr)
    single = single_photo_errors_m(rr)
    pan, gap, across_m = ray_geometry(rr, yaw)
    m = len(rr.names)
    model = photo_error_model([photo_of_row(rr, 0, yaw[0])])
    stated = {"attitude_deg": args.attitude_deg, "position_m": args.photo_position_m}
    stated = {k: v for k, v in stated.items() if v is not None}
    errors = None
    if stated or args.bias_prior_deg is not None:
        errors = model = dataclasses.replace(model, sigma=dataclasses.replace(model.sigma, **stated),
                                             bias_prior_deg=args.bias_prior_deg or model.bias_prior_deg,
                                             source=model.source + ", sigmas stated")
    print(f"{len(rr.point)} rows from {len(np.unique(rr.photo))} photos, {m} points. Adapter: rows' own camera "
          f"azimuths within {chk['yaw_spread_deg']:.3f} deg of their photo's (rows whose answer lies beyond nadir: "
          f"{chk['far_side_rows']}); OpenAthena's logged pixel offsets reproduced to "
          f"{chk['offsets_max_diff_deg']:.4f} deg ({chk['offsets_roll_flipped_deg']:.2f} deg with the roll flipped); "
          f"OpenAthena's ray against the ray through the pixel: median {np.median(gap):.2f} deg, at most "
          f"{gap.max():.1f} deg")
    print(f"error model: {model.source}; compass bias prior {model.bias_prior_deg} deg; per photo "
          f"{model.sigma.to_dict()}; shared offset {model.shared_h_m} m horizontal per axis\n")

    fused = per_point_table(rr, yaw, single, errors)
    err = np.array([f.error_m if f else np.nan for f in fused])
    ins = np.array([inside(f) for f in fused])
    ratio = np.nanmedian(err) / np.median(single)
    per_point = err / np.array([np.median(single[rr.rows_of(k)]) for k in range(m)])
    print(f"\nall photos of a point fused: median {np.nanmedian(err):.2f} m against {np.median(single):.2f} m for "
          f"the {len(single)} single-photo answers: ratio {ratio:.2f}; truth inside the 95 % ellipse on "
          f"{int(ins.sum())}/{m} points. Per point, fused over its own single-photo median: median "
          f"{np.nanmedian(per_point):.2f}, at most 0.5 on {int((per_point <= 0.5).sum())}/{m}")
    far = [f"{rr.names[k]} {int((np.abs(across_m[rr.rows_of(k)]) > 10.0).sum())}/{len(rr.rows_of(k))}"
           for k in range(m)]
    print(f"rays passing more than 10 m from their point (across the ray): {', '.join(far)}")

    rng = np.random.default_rng(args.seed)
    boot = []
    for _ in range(args.bootstrap):
        pick = rng.integers(0, m, m)
        rows = np.concatenate([rr.rows_of(k) for k in pick])
        boot.append((np.nanmedian(err[pick]) / np.median(single[rows]), ins[pick].mean()))
    (rlo, clo), (rhi, chi) = np.percentile(boot, [5, 95], axis=0)
    print(f"bootstrap over the points ({args.bootstrap}): ratio 90 % interval {rlo:.2f}-{rhi:.2f}, coverage "
          f"{clo * 100:.0f}-{chi * 100:.0f} %")
    jack = [fuse(rr, idx[rr.photo[idx] != p], yaw, errors) for idx in map(rr.rows_of, range(m))
            for p in np.unique(rr.photo[idx])]
    jack_err = np.array([f.error_m for f in jack if f is not None])
    print(f"leave one photo out ({len(jack)} fusions): median {np.median(jack_err):.2f} m, truth inside the 95 % "
          f"ellipse in {np.mean([inside(f) for f in jack]) * 100:.0f} %")

    bias = np.array([np.median(pan[rr.rows_of(k)]) for k in range(m)])
    priors = [float(np.sqrt(np.mean(np.delete(bias, k) ** 2))) for k in range(m)]
    loo = [fuse(rr, rr.rows_of(k), yaw, errors=dataclasses.replace(model, bias_prior_deg=priors[k]))
           for k in range(m)]
    print(f"compass bias prior from the other nine points (rms of their rays' median angle to the truth across the "
          f"ray, {min(priors):.2f}-{max(priors):.2f} deg; instead of {model.bias_prior_deg}): median "
          f"{np.median([f.error_m for f in loo]):.2f} m, inside on {sum(map(inside, loo))}/{m}")

    consistent = gap <= 1.0
    print("random subsets of a point's photos (the rows of a photo kept together): photos, fusions, median m, median "
          "over the single-photo median of the same rows, inside the 95 % ellipse")
    for label, rows in (("all rows", np.ones(len(gap), bool)),
                        (f"the {int(consistent.sum())} rows whose OpenAthena answer lies within 1 deg of the ray "
                         "through the pixel", consistent)):
        print(f"  {label}:")
        for size, n, med, rel, cov in photo_subsets(rr, yaw, single, rows, (2, 3, 5, 8), args.subsets, rng, errors):
            print(f"    {size:2d}  {n:4d}  {med:6.2f}  {rel:5.2f}  {cov * 100:4.0f} %")

    within = [pan[a] - pan[b] for a in range(len(pan)) for b in range(a + 1, len(pan))
              if rr.photo[a] == rr.photo[b] and rr.point[a] != rr.point[b]]
    across = [pan[a] - pan[b] for a in range(len(pan)) for b in range(a + 1, len(pan))
              if rr.photo[a] != rr.photo[b] and rr.point[a] == rr.point[b]]
    offset = np.degrees(np.arctan((rr.fraction_xy[:, 0] - 0.5) * rr.size_px[0] / rr.f_px[0]))
    steep = rr.slant_deg >= 50.0
    slopes = [theilslopes(pan[s], offset[s])[0] for s in (~steep, steep)]
    print(f"rays' angle to the truth across the ray: robust sd {robust_sd(pan):.2f} deg; of the difference of two "
          f"rays of one photo to different points (the photo's attitude error cancels) {robust_sd(within):.2f} deg, "
          f"of two photos of one point {robust_sd(across):.2f} deg; its slope against the pixel's angle from the "
          f"image centre: {slopes[0]:+.2f} where the camera looks less than 50 deg down, {slopes[1]:+.2f} steeper")

    oa = [fuse(rr, rr.rows_of(k), yaw, errors, line_of_sight="answer") for k in range(m)]
    print(f"OpenAthena's ray (the drone-to-answer direction) as the line of sight instead: median "
          f"{np.median([f.error_m for f in oa]):.2f} m, inside on {sum(map(inside, oa))}/{m}")
    return 0

if __name__ == "__main__":
    raise SystemExit(main())
