"""Synthetic drone photo flights: JPEGs with EXIF GPS and DJI-style XMP (drone-dji: pose, calibrated intrinsics,
DewarpData, LRF fields), as a DJI Enterprise camera writes them, with a known target and known errors.

The truth: a target on the ground (on `Hills` terrain, pipeline.synth.dem, or a flat plane), n photos taken from
positions around it (azimuths spread over `spread_deg`, 250-600 m away, 60-150 m above it), each pointed at the
target (target at the principal point, where the laser points). The recorded tags carry the errors of a consumer
drone without RTK, drawn from families of their own (not the error model `ridgeloc locate` assumes,
pipeline.photo_errors): a compass bias constant over the flight (uniform 1-5 deg, random sign) added to every gimbal
yaw and a smaller gimbal pitch bias (uniform +-0.5 deg), frame-to-frame attitude jitter; a horizontal GNSS error
that wanders over minutes (first-order Gauss-Markov, 120 s correlation time, its sigma per axis drawn per flight
uniform in 0.5-2 m: a scale mixture, heavier-tailed than one Gaussian) plus a little noise per photo; an altitude
datum offset shared by all photos (uniform +-30 m); the laser's noise (DJI's +-(0.2 m + 0.15 %) read as 2 sigma).
DJI's own one-shot target
(LRFTargetLat/Lon/AbsAlt) is computed as the aircraft does: recorded position + recorded gimbal angles + range.

    from pipeline.synth.photos import PhotoFlightSpec, simulate_photo_flight, write_photo_flight
    flight = simulate_photo_flight(PhotoFlightSpec(seed=1))
    write_photo_flight(flight, "out/photos")      # DJI_0001.JPG ..., marks.csv, truth.json
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from pipeline.geometry.frames import enu_from_lla, lla_from_enu
from pipeline.geometry.geoid import geoid_undulation_m
from pipeline.geometry.lens import distort_pixels
from pipeline.synth.noise import gauss_markov_filter


@dataclass(frozen=True)
class PhotoFlightSpec:
    """What to generate. Angles in degrees, lengths in metres; the *_sigma are 1-sigma noise."""

    seed: int = 0
    n_photos: int = 5
    laser: bool = True
    lat_deg: float = 46.5
    lon_deg: float = 7.5
    ground_h_m: float = 600.0  # ellipsoidal height of the flat ground (used when hills is None)
    hills: object | None = None  # a pipeline.synth.dem.Hills: the terrain the target stands on
    width_px: int = 640
    height_px: int = 480
    fx_px: float = 1100.0
    dist: tuple[float, float, float, float, float] = (-0.08, 0.05, 0.0004, -0.0003, 0.0)
    spread_deg: tuple[float, float] = (60.0, 150.0)  # range of the azimuth spread of the photo positions
    range_m: tuple[float, float] = (250.0, 600.0)  # horizontal distance to the target
    height_above_m: tuple[float, float] = (60.0, 150.0)
    compass_bias_deg: tuple[float, float] = (1.0, 5.0)  # |bias|, random sign, constant over the flight
    pitch_bias_deg: float = 0.5  # gimbal pitch bias, uniform in +-this, constant over the flight
    attitude_jitter_deg: float = 0.3
    # the horizontal GNSS error: a Gauss-Markov process per axis, its sigma drawn per flight uniform in this range
    gnss_offset_sigma_m: tuple[float, float] = (0.5, 2.0)
    gnss_tau_s: float = 120.0
    gnss_noise_sigma_m: tuple[float, float] = (0.3, 0.5)  # photo to photo: horizontal, vertical
    datum_offset_m: tuple[float, float] = (-30.0, 30.0)  # added to every recorded altitude
    laser_sigma_m: tuple[float, float] = (0.1, 0.00075)  # a + b * range (m): DJI's 0.2 m + 0.15 % as 2 sigma
    # the RTK status written (drone-dji:RtkFlag, RtkStdLon/Lat/Hgt m): 16 single point, 50 fixed (the errors drawn
    # above are the caller's to match: RTK_FIXED_ERRORS)
    rtk_flag: int = 16
    rtk_std_m: tuple[float, float, float] = (1.5, 1.5, 2.0)
    mark_sigma_px: float = 1.0
    mark_offset_px: float = 0.0  # without laser: the target up to this far from the centre (uniform per axis)
    # further targets (name, east m, north m from the main one, on the terrain), marked where the photos see them;
    # the main target (the laser's, at the image centre) is then named main_target_name
    extra_targets: tuple[tuple[str, float, float], ...] = ()
    main_target_name: str = "laser_spot"
    dt_s: float = 20.0


#: the errors of an RTK-fixed flight (PhotoFlightSpec changes): centimetre GNSS, the altitude's datum known to a
#: decimetre; the compass and the laser as without RTK
RTK_FIXED_ERRORS = {"rtk_flag": 50, "rtk_std_m": (0.02, 0.02, 0.03), "gnss_offset_sigma_m": (0.01, 0.05),
                    "gnss_noise_sigma_m": (0.01, 0.02), "datum_offset_m": (-0.3, 0.3)}


@dataclass
class PhotoFlight:
    """Recorded tags per photo (dicts, one per photo) and the truth (target lla, errors drawn)."""

    spec: PhotoFlightSpec
    tags: list[dict]
    marks_px: np.ndarray  # (n, 2) the target's pixel as marked (with marking noise)
    truth: dict = field(default_factory=dict)
    extra_marks_px: dict = field(default_factory=dict)  # {name: (n, 2)} further targets' marks, NaN: not in view


def _ypr_towards(camera_lla, target_lla) -> tuple[float, float]:
    """(yaw, pitch) degrees of the direction from a camera to a target in the camera's own local NED frame."""
    e, n, u = enu_from_lla(*target_lla, origin_lla=tuple(camera_lla))
    return float(np.degrees(np.arctan2(e, n))), float(np.degrees(np.arctan2(u, np.hypot(e, n))))


def _point_along(camera_lla, yaw_deg, pitch_deg, range_m) -> np.ndarray:
    """(lat, lon, h) at range_m from a camera along gimbal (yaw, pitch) in its local NED."""
    y, p = np.radians(yaw_deg), np.radians(pitch_deg)
    enu = range_m * np.array([np.cos(p) * np.sin(y), np.cos(p) * np.cos(y), np.sin(p)])
    return lla_from_enu(enu, tuple(camera_lla))


def simulate_photo_flight(spec: PhotoFlightSpec) -> PhotoFlight:
    rng = np.random.default_rng(spec.seed)
    lat0, lon0 = spec.lat_deg, spec.lon_deg
    h_t = float(spec.hills.h_wgs84_m(lat0, lon0)) if spec.hills is not None else spec.ground_h_m
    target = (lat0, lon0, h_t)
    n = spec.n_photos
    spread = rng.uniform(*spec.spread_deg)
    az = rng.uniform(0, 360) + np.linspace(-spread / 2, spread / 2, n) + rng.normal(0, 3, n)
    dist_h = rng.uniform(*spec.range_m, n)
    up = rng.uniform(*spec.height_above_m, n)
    enu = np.c_[dist_h * np.sin(np.radians(az)), dist_h * np.cos(np.radians(az)), up]
    cams = lla_from_enu(enu, target)
    bias = rng.uniform(*spec.compass_bias_deg) * rng.choice([-1.0, 1.0])
    pitch_bias = rng.uniform(-spec.pitch_bias_deg, spec.pitch_bias_deg)
    offset = rng.uniform(*spec.datum_offset_m)
    # a consumer GNSS error wanders over minutes: over one photo flight it is mostly a shared offset
    gnss_sigma = rng.uniform(*spec.gnss_offset_sigma_m)
    gnss = np.zeros((n, 3))
    gnss[:, :2] = gauss_markov_filter(rng.normal(0, gnss_sigma, (n, 2)), spec.dt_s, spec.gnss_tau_s)
    N = geoid_undulation_m(cams[:, 0], cams[:, 1])  # EGM2008 (the grid window around them is read once)
    K = np.array([[spec.fx_px, 0, (spec.width_px - 1) / 2], [0, spec.fx_px, (spec.height_px - 1) / 2], [0, 0, 1]])
    tags, marks, rotations = [], [], []
    t0 = 1_700_000_000
    for i in range(n):
        yaw, pitch = _ypr_towards(cams[i], target)
        true_range = float(np.linalg.norm(enu_from_lla(*target, origin_lla=tuple(cams[i]))))
        offset_px = rng.uniform(-spec.mark_offset_px, spec.mark_offset_px, 2) if not spec.laser else np.zeros(2)
        # the camera is turned so that the target sits offset_px from the centre: the pointing moves by the angle
        d_yaw = np.degrees(np.arctan2(offset_px[0], spec.fx_px))
        d_pitch = -np.degrees(np.arctan2(offset_px[1], spec.fx_px))
        R = Rotation.from_euler("ZYX", [yaw - d_yaw, pitch - d_pitch, 0.0], degrees=True)
        rotations.append(R)
        marks.append(_true_pixel(cams[i], target, R, K, spec.dist) + rng.normal(0, spec.mark_sigma_px, 2))
        yaw_true, pitch_true = R.as_euler("ZYX", degrees=True)[:2]
        rec_yaw = yaw_true + bias + rng.normal(0, spec.attitude_jitter_deg)
        rec_pitch = pitch_true + pitch_bias + rng.normal(0, spec.attitude_jitter_deg)
        rec_roll = rng.normal(0, spec.attitude_jitter_deg / 3)
        noise = rng.normal(0, 1, 3) * np.array([*[spec.gnss_noise_sigma_m[0]] * 2, spec.gnss_noise_sigma_m[1]])
        rec = lla_from_enu(gnss[i] + noise + np.array([0.0, 0.0, offset]), tuple(cams[i]))
        tag = {"lat_deg": float(rec[0]), "lon_deg": float(rec[1]), "abs_alt_m": float(rec[2] - N[i]),
               "relative_alt_m": float(up[i]), "gimbal_ypr_deg": (float(rec_yaw), float(rec_pitch), float(rec_roll)),
               "flight_ypr_deg": (float(rec_yaw + rng.normal(0, 2)), float(rng.normal(0, 2)), float(rng.normal(0, 2))),
               "t_unix_s": t0 + spec.dt_s * i, "fx_px": spec.fx_px, "cx_px": float(K[0, 2]), "cy_px": float(K[1, 2]),
               "dist": tuple(spec.dist), "width_px": spec.width_px, "height_px": spec.height_px}
        if spec.laser:
            measured = true_range + rng.normal(0, spec.laser_sigma_m[0] + spec.laser_sigma_m[1] * true_range)
            dji = _point_along(rec, rec_yaw, rec_pitch, measured)
            n_dji = float(geoid_undulation_m(dji[0], dji[1]))
            tag.update(lrf_range_m=float(measured), lrf_status="Normal", dji_target=(float(dji[0]), float(dji[1]),
                                                                                      float(dji[2] - n_dji)))
        tag.update(rtk_flag=spec.rtk_flag, rtk_std_m=tuple(spec.rtk_std_m))
        tags.append(tag)
    truth = {"target_lla": [lat0, lon0, h_t], "target_alt_datum": "ellipsoid", "compass_bias_deg": float(bias),
             "pitch_bias_deg": float(pitch_bias), "datum_offset_m": float(offset),
             "gnss_sigma_m": float(gnss_sigma), "gnss_error_enu_m": gnss.tolist(),
             "camera_lla_true": cams.tolist(), "spec": _spec_dict(spec)}
    extra = _extra_targets(spec, target, cams, rotations, K)
    if extra:
        truth["targets"] = [{"name": spec.main_target_name, "lat_deg": lat0, "lon_deg": lon0, "alt_m": h_t}] + [
            {"name": name, "lat_deg": lla[0], "lon_deg": lla[1], "alt_m": lla[2]} for name, (lla, _) in extra.items()]
    return PhotoFlight(spec, tags, np.array(marks), truth, {name: px for name, (_, px) in extra.items()})


def _extra_targets(spec: PhotoFlightSpec, target, cams, rotations, K) -> dict:
    """{name: ((lat, lon, h), (n, 2) marked pixels)} of spec.extra_targets as the true cameras see them (marking
    noise from a generator of their own, so that the main flight's draws do not change); NaN where a target is
    behind the camera or outside the image."""
    rng = np.random.default_rng([spec.seed, 1])
    out = {}
    for name, e_m, n_m in spec.extra_targets:
        lat, lon, _ = lla_from_enu(np.array([e_m, n_m, 0.0]), target)
        h = float(spec.hills.h_wgs84_m(lat, lon)) if spec.hills is not None else spec.ground_h_m
        lla = (float(lat), float(lon), h)
        px = np.full((len(cams), 2), np.nan)
        for i, R in enumerate(rotations):
            pix = _true_pixel(cams[i], lla, R, K, spec.dist)
            if pix is None:
                continue
            pix = pix + rng.normal(0, spec.mark_sigma_px, 2)
            if 0 <= pix[0] <= spec.width_px - 1 and 0 <= pix[1] <= spec.height_px - 1:
                px[i] = pix
        out[name] = (lla, px)
    return out


def _true_pixel(camera_lla, target_lla, R: Rotation, K: np.ndarray, dist) -> np.ndarray | None:
    """(2,) distorted pixel of a target (lat, lon, h) seen from a camera at camera_lla whose gimbal attitude is R
    (local NED from gimbal FRD); None when it is behind the camera."""
    d_g = R.inv().apply(_ned_towards(camera_lla, target_lla))
    d_opt = np.array([d_g[1], d_g[2], d_g[0]])  # optical (x right, y down, z forward) from FRD (x fwd, y right, z down)
    if d_opt[2] <= 0:
        return None
    pin = K @ (d_opt / d_opt[2])
    return distort_pixels(pin[None, :2], K, dist)[0]


def _ned_towards(camera_lla, target_lla) -> np.ndarray:
    e, n, u = enu_from_lla(*target_lla, origin_lla=tuple(camera_lla))
    d = np.array([n, e, -u])
    return d / np.linalg.norm(d)


def _spec_dict(spec: PhotoFlightSpec) -> dict:
    d = asdict(spec)
    d["hills"] = None if spec.hills is None else {"lat0_deg": spec.hills.lat0_deg, "lon0_deg": spec.hills.lon0_deg,
                                                   "base_m": spec.hills.base_m, "ridges": list(spec.hills.ridges)}
    return d


def _dms(value: float) -> tuple[float, float, float]:
    v = abs(value)
    d = int(v)
    m = int((v - d) * 60)
    return float(d), float(m), round((v - d - m / 60) * 3600, 6)


def dji_xmp(tag: dict) -> bytes:
    """The XMP packet of one photo, drone-dji attributes on one rdf:Description as DJI cameras write them."""
    g, f = tag["gimbal_ypr_deg"], tag["flight_ypr_deg"]
    k1, k2, p1, p2, k3 = tag["dist"]
    dcx, dcy = tag["cx_px"] - tag["width_px"] / 2, tag["cy_px"] - tag["height_px"] / 2
    attrs = {
        "AbsoluteAltitude": f"{tag['abs_alt_m']:+.3f}", "RelativeAltitude": f"{tag['relative_alt_m']:+.3f}",
        "GimbalYawDegree": f"{g[0]:+.2f}", "GimbalPitchDegree": f"{g[1]:+.2f}", "GimbalRollDegree": f"{g[2]:+.2f}",
        "FlightYawDegree": f"{f[0]:+.2f}", "FlightPitchDegree": f"{f[1]:+.2f}", "FlightRollDegree": f"{f[2]:+.2f}",
        "CalibratedFocalLength": f"{tag['fx_px']:.4f}", "CalibratedOpticalCenterX": f"{tag['cx_px']:.4f}",
        "CalibratedOpticalCenterY": f"{tag['cy_px']:.4f}",
        "DewarpData": f"2024-01-01;{tag['fx_px']:.4f},{tag['fx_px']:.4f},{dcx:.4f},{dcy:.4f},"
                      f"{k1:.6f},{k2:.6f},{p1:.6f},{p2:.6f},{k3:.6f}",
        "RtkFlag": str(tag.get("rtk_flag", 16)),
        **dict(zip(("RtkStdLon", "RtkStdLat", "RtkStdHgt"), (f"{v:.3f}" for v in tag.get("rtk_std_m", (1.5, 1.5, 2.0))),
                   strict=True)),
    }
    if "lrf_range_m" in tag:
        lat, lon, alt = tag["dji_target"]
        attrs.update(LRFStatus=tag["lrf_status"], LRFTargetDistance=f"{tag['lrf_range_m']:.3f}",
                     LRFTargetLon=f"{lon:.9f}", LRFTargetLat=f"{lat:.9f}",
                     LRFTargetAlt=f"{alt - tag['abs_alt_m'] + tag['relative_alt_m']:.3f}",
                     LRFTargetAbsAlt=f"{alt:.3f}")
    body = " ".join(f'drone-dji:{k}="{v}"' for k, v in attrs.items())
    return ('<?xpacket begin="\ufeff" id="W5M0MpCehiHzreSzNTczkc9d"?>\n'
            '<x:xmpmeta xmlns:x="adobe:ns:meta/">\n <rdf:RDF xmlns:rdf="http://www.w3.org/1999/02/22-rdf-syntax-ns#">\n'
            '  <rdf:Description rdf:about="DJI Meta Data" xmlns:tiff="http://ns.adobe.com/tiff/1.0/" '
            'xmlns:drone-dji="http://www.dji.com/drone-dji/1.0/" tiff:Make="DJI" tiff:Model="ZH20T" '
            f'{body}/>\n </rdf:RDF>\n</x:xmpmeta>\n<?xpacket end="w"?>').encode()


def write_photo(path, tag: dict, rng: np.random.Generator) -> Path:
    """One JPEG (grey noise) with EXIF (Make, Model, DateTimeOriginal + OffsetTimeOriginal, GPS) and DJI XMP."""
    from datetime import datetime, timezone

    from PIL import Image

    w, h = tag["width_px"], tag["height_px"]
    img = Image.fromarray(rng.integers(90, 170, (h // 8, w // 8), dtype=np.uint8)).resize((w, h))
    exif = Image.Exif()
    exif[271], exif[272], exif[305] = "DJI", "ZH20T", "v01.00.0000"
    t = datetime.fromtimestamp(tag["t_unix_s"], tz=timezone.utc)
    ex = exif.get_ifd(0x8769)
    ex[36867], ex[36881] = t.strftime("%Y:%m:%d %H:%M:%S"), "+00:00"
    gps = exif.get_ifd(0x8825)
    gps[0] = b"\x02\x03\x00\x00"
    gps[1], gps[2] = ("N" if tag["lat_deg"] >= 0 else "S"), _dms(tag["lat_deg"])
    gps[3], gps[4] = ("E" if tag["lon_deg"] >= 0 else "W"), _dms(tag["lon_deg"])
    gps[5], gps[6] = (b"\x00" if tag["abs_alt_m"] >= 0 else b"\x01"), round(abs(tag["abs_alt_m"]), 3)
    path = Path(path)
    img.save(path, "JPEG", quality=70, exif=exif, xmp=dji_xmp(tag))
    return path


def write_photo_flight(flight: PhotoFlight, out_dir) -> list[Path]:
    """DJI_0001.JPG ... in out_dir, with marks.csv (photo,x_px,y_px: the main target's pixel as marked), truth.json
    (`target` {lat_deg, lon_deg, alt_m ellipsoidal}, with further targets `targets` [{name, lat_deg, lon_deg,
    alt_m}], the errors drawn, the tags written), with further targets targets.csv (every target's marks,
    `name,frame_or_image,x_px,y_px` with the photo's file name) and flight.yaml (its flight config for `ridgeloc
    run`: files.marks, or marks_file targets.csv)."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(flight.spec.seed + 1)
    paths = [write_photo(out / f"DJI_{i + 1:04d}.JPG", tag, rng) for i, tag in enumerate(flight.tags)]
    with open(out / "marks.csv", "w") as f:
        f.write("photo,x_px,y_px\n")
        for p, (u, v) in zip(paths, flight.marks_px, strict=True):
            f.write(f"{p.name},{u:.2f},{v:.2f}\n")
    lat, lon, h = flight.truth["target_lla"]
    truth = dict(flight.truth, target={"lat_deg": lat, "lon_deg": lon, "alt_m": h}, tags=flight.tags,
                 marks_px=flight.marks_px.tolist())
    (out / "truth.json").write_text(json.dumps(truth, indent=1, default=list))
    name = "".join(c if c.isalnum() or c in "-_" else "_" for c in out.name) or "photos"
    if flight.extra_marks_px:  # every target in a marks file (docs/run.md, "Many targets per flight")
        with open(out / "targets.csv", "w") as f:
            f.write("name,frame_or_image,x_px,y_px\n")
            marks = {flight.spec.main_target_name: flight.marks_px, **flight.extra_marks_px}
            for target, px in marks.items():
                for p, (u, v) in zip(paths, px, strict=True):
                    if np.isfinite(u):
                        f.write(f"{target},{p.name},{u:.2f},{v:.2f}\n")
        marks_line = "marks_file: targets.csv\n"
    else:
        marks_line = ""
    files = "files:\n  photos: .\n" + ("" if marks_line else "  marks: marks.csv\n")
    (out / "flight.yaml").write_text(f"# a synthetic DJI photo flight (pipeline/synth/photos.py): ridgeloc run this\n"
                                     f"name: {name}\n{files}{marks_line}truth_file: truth.json\n")
    return paths


def write_photo_sample(out_dir, spec: PhotoFlightSpec, dem: bool) -> PhotoFlight:
    """A photo flight as `ridgeloc synth --photos` and scripts/make_sample_data.py write it: with dem, the target on
    synthetic hills (pipeline.synth.dem.Hills at the spec's place) and their GeoTIFF dem.tif (4 km, 30 m posts, UTM
    32N), named in flight.yaml's `terrain:` with a 2 m vertical sigma. out_dir must not exist or be empty."""
    import dataclasses

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    if dem:
        from pipeline.synth.dem import Hills, write_dem

        hills = Hills(spec.lat_deg, spec.lon_deg, base_m=spec.ground_h_m)
        spec = dataclasses.replace(spec, hills=hills)
        write_dem(out / "dem.tif", hills, extent_m=4000.0, post_m=30.0, crs="EPSG:32632")
    flight = simulate_photo_flight(spec)
    write_photo_flight(flight, out)
    if dem:
        with open(out / "flight.yaml", "a") as f:
            f.write("terrain:\n  dem: dem.tif\n  vertical_sigma_m: 2.0\n")
    return flight
