"""Drone photos (JPEG with EXIF and XMP): per photo its time, position, aircraft and gimbal attitude, intrinsics,
laser range and the maker's own laser target. Every tag read, and why, is in docs/ingest.md ("Drone photos").

Libraries: Pillow reads the image size, the EXIF and GPS IFDs and the raw XMP packet (APP1
"http://ns.adobe.com/xap/1.0/"); defusedxml parses the packet (hardened against entity expansion, as Pillow's own
getxmp uses it); exifread decodes the DJI MakerNote (older DJI photos carry the attitude only there). All three
are pure Python wheels (Pillow's C code is in its wheel); no system binary (exiftool) is needed.

Conventions: every maker's pose tags (pipeline.ingest.photo_makers) are read into DJI's: Gimbal*/Flight* Yaw,
Pitch, Roll degrees are the ZYX (yaw-pitch-roll) Euler angles of the gimbal / body FRD frame in the local NED frame
at the aircraft, yaw from true north, gimbal yaw earth-referenced; pitch -90 looks straight down.

Pixels are those of the stored image (its pixel grid as the file holds it, whatever EXIF Orientation says), which is
the camera's unless a desktop program re-saved the file (`resaved_by`): such a program may have turned the pixels
(pipeline.locate decides 0 or 180 degrees from two or more marked photos, or the user states it).
"""

from __future__ import annotations

import math
import warnings as warnings_module
from dataclasses import dataclass, field
from datetime import datetime, timedelta, timezone
from pathlib import Path

import numpy as np

from pipeline.errors import InputError
from pipeline.ingest.boundary import reader_boundary
from pipeline.ingest.photo_camera import PhotoIntrinsics, database_entry, dji_calibration, photo_intrinsics
from pipeline.ingest.photo_makers import NS_DJI, NS_RDF, POSE_TAGS_LOOKED_FOR, MakerPose, read_maker_pose

PHOTO_SUFFIXES = (".jpg", ".jpeg")
NS_XMP_MM = "http://ns.adobe.com/xap/1.0/mm/"
NS_ST_EVT = "http://ns.adobe.com/xap/1.0/sType/ResourceEvent#"
#: desktop programs (lower case, matched as substrings of EXIF Software, xmp:CreatorTool and the xmpMM:History
#: software agents) that re-save photos and may turn their pixels; a camera's firmware name is not among them
DESKTOP_PROGRAMS = ("photoshop", "lightroom", "camera raw", "windows photo", "microsoft photos", "gimp", "picasa",
                    "paint", "preview", "iphoto", "apple photos", "acdsee", "irfanview", "xnview", "faststone",
                    "snapseed", "digikam", "shotwell", "darktable", "rawtherapee", "capture one", "affinity",
                    "pixelmator", "luminar", "google photos", "photos app", "imagemagick")
LRF_VALID_STATUS = "normal"
ALT_DATUMS_PHOTO = ("amsl", "ellipsoid")
MAX_XMP_BYTES = 1 << 20  # DJI packets are ~10-20 kB; a larger one is refused rather than parsed


@dataclass(frozen=True)
class Photo:
    """What one drone photo states. Angles in degrees, (yaw, pitch, roll) ZYX in local NED; lengths in metres;
    NaN / None where the photo does not say.

    t_ns: EXIF DateTimeOriginal (+ SubSecTimeOriginal), as UTC when `time_zone` is known (OffsetTimeOriginal, or
    the zone the GPS time stamp implies), else the camera's local clock read as if it were UTC (`time_zone`
    "unknown"): fine for ordering photos, not for matching them with a log; the GPS time stamp when there is no
    DateTimeOriginal or it is off by no whole zone (see _photo_time). alt_m is on `alt_datum` (see docs for what
    AbsoluteAltitude means)."""

    path: str
    make: str
    model: str
    width_px: int
    height_px: int
    t_ns: int | None
    time_zone: str
    lat_deg: float
    lon_deg: float
    alt_m: float
    alt_datum: str
    alt_source: str
    relative_alt_m: float
    gps_alt_m: float
    gimbal_ypr_deg: tuple[float, float, float]
    flight_ypr_deg: tuple[float, float, float] | None
    attitude_source: str
    intrinsics: PhotoIntrinsics | None
    lrf_range_m: float = math.nan
    lrf_status: str = ""
    dji_target_lla: tuple[float, float, float] | None = None  # LRFTargetLat, Lon, AbsAlt (alt on alt_datum)
    rtk_flag: int | None = None
    rtk_std_m: tuple[float, float, float] | None = None  # RtkStdLon, RtkStdLat, RtkStdHgt
    gps_t_ns: int | None = None  # EXIF GPSDateStamp + GPSTimeStamp (UTC)
    warnings: tuple[str, ...] = field(default_factory=tuple)
    maker: str = "DJI"  # whose pose tags were read (pipeline.ingest.photo_makers)
    relative_alt_source: str = ""  # the tag of relative_alt_m (height above the take-off point)
    resaved_by: str = ""  # the desktop program that re-saved the file ("": none named; its pixels are the camera's)
    orientation: int = 1  # EXIF Orientation as written (pixels are always the stored image's)

    @property
    def lrf_valid(self) -> bool:
        return self.lrf_status.lower() == LRF_VALID_STATUS and math.isfinite(self.lrf_range_m) and self.lrf_range_m > 0

    @property
    def name(self) -> str:
        return Path(self.path).name

    @property
    def takeoff_ground_m(self) -> float:
        """The take-off point's height on `alt_datum`: alt_m - relative_alt_m (NaN where the photo does not state
        both)."""
        return self.alt_m - self.relative_alt_m


def parse_xmp_tree(packet: bytes, path):
    """The root element of an XMP packet (defusedxml). Raises InputError (naming `path`) for a corrupt packet."""
    import defusedxml.ElementTree as DET
    from defusedxml import DefusedXmlException

    if len(packet) > MAX_XMP_BYTES:
        raise InputError(f"XMP packet of {len(packet)} bytes (more than {MAX_XMP_BYTES}): refused", path=path)
    text = packet.strip(b"\x00 \t\r\n")
    try:
        return DET.fromstring(text)
    except DefusedXmlException as exc:
        raise InputError(f"corrupt XMP packet (forbidden XML construct: {type(exc).__name__})", path=path) from None
    except Exception as exc:  # xml.etree.ElementTree.ParseError and friends
        raise InputError(f"corrupt XMP packet ({str(exc).splitlines()[0][:120] if str(exc) else type(exc).__name__})",
                         path=path) from None


def xmp_properties(root) -> dict[tuple[str, str], str]:
    """{(namespace URI, local name): text} of every property of an XMP tree written as an attribute of any element or
    as a simple child element (the first occurrence of a name wins; structs with repeated field names, as
    Skydio's, are read from the tree itself)."""
    out: dict[tuple[str, str], str] = {}
    for el in root.iter():
        for key, value in el.attrib.items():
            if key.startswith("{"):
                ns, name = key[1:].split("}", 1)
                out.setdefault((ns, name), value)
        tag = el.tag if isinstance(el.tag, str) else ""
        if tag.startswith("{") and len(el) == 0 and el.text and el.text.strip():
            ns, name = tag[1:].split("}", 1)
            if ns != NS_RDF:
                out.setdefault((ns, name), el.text.strip())
    return out


def _history_agents(root) -> list[str]:
    """The xmpMM:History software agents (stEvt:softwareAgent) of an XMP tree: the programs that saved the file."""
    if root is None:
        return []
    agents = []
    for el in root.iter():
        agent = el.attrib.get(f"{{{NS_ST_EVT}}}softwareAgent")
        if agent is None and isinstance(el.tag, str) and el.tag == f"{{{NS_ST_EVT}}}softwareAgent" and el.text:
            agent = el.text
        if agent and agent.strip() not in agents:
            agents.append(agent.strip())
    return agents


def desktop_program(names) -> str:
    """The first of `names` (EXIF Software, xmp:CreatorTool, history agents) that is a desktop program
    (DESKTOP_PROGRAMS), "" when none is."""
    for n in names:
        if n and any(p in n.lower() for p in DESKTOP_PROGRAMS):
            return n.strip()
    return ""


def _float(value) -> float:
    try:
        v = float(str(value).strip())
    except (TypeError, ValueError):
        return math.nan
    return v if math.isfinite(v) else math.nan


def _rational(v) -> float:
    try:
        return float(v)
    except (TypeError, ValueError, ZeroDivisionError):
        return math.nan


def _dms(value, ref, positive: str) -> float:
    try:
        d, m, s = (_rational(x) for x in value)
    except (TypeError, ValueError):
        return math.nan
    deg = d + m / 60.0 + s / 3600.0
    ref = ref.decode(errors="replace") if isinstance(ref, bytes) else str(ref or positive)
    return -deg if ref.strip().upper()[:1] not in (positive, "") else deg


def _text(value) -> str:
    if isinstance(value, bytes):
        value = value.decode(errors="replace")
    return str(value).replace("\x00", "").strip()


#: DateTimeOriginal and the GPS time stamp (whole seconds each) agree when they are this close (s)
TIME_TAG_TOLERANCE_S = 2.0
#: time zones are whole quarter hours
ZONE_STEP_S = 900


def _gps_time_ns(gps: dict) -> int | None:
    """UTC ns from EXIF GPSDateStamp (29, "YYYY:MM:DD") and GPSTimeStamp (7, hours, minutes, seconds rationals), or
    None when either is missing or unreadable."""
    try:
        d = datetime.strptime(_text(gps.get(29, "")), "%Y:%m:%d").replace(tzinfo=timezone.utc)
        h, m, sec = (_rational(x) for x in gps[7])
    except (KeyError, TypeError, ValueError):
        return None
    if not (0 <= h < 24 and 0 <= m < 60 and 0 <= sec < 61):  # NaN fails too
        return None
    t_ns = int(d.timestamp()) * 1_000_000_000 + round((h * 3600 + m * 60 + sec) * 1e9)
    return t_ns if 0 <= t_ns < 2**63 else None


def _zone_name(offset_s: int) -> str:
    sign = "-" if offset_s < 0 else "+"
    return f"{sign}{abs(offset_s) // 3600:02d}:{abs(offset_s) % 3600 // 60:02d}"


def _photo_time(exif_ifd: dict, gps: dict) -> tuple[int | None, str, int | None, str | None]:
    """(t_ns UTC or the camera's clock, time zone, GPS time ns, warning) from DateTimeOriginal (36867),
    SubSecTimeOriginal (37521), OffsetTimeOriginal (36881) and GPSDateStamp/GPSTimeStamp (docs/ingest.md, "Time").

    With OffsetTimeOriginal the GPS time is a check (a warning when they differ by more than TIME_TAG_TOLERANCE_S);
    without it the GPS time gives the zone (DateTimeOriginal minus the GPS time, whole quarter hours), or is the
    time itself when the two differ by no whole zone (a camera clock set wrong), or when DateTimeOriginal is
    missing."""
    gps_ns = _gps_time_ns(gps)
    text = _text(exif_ifd.get(36867, ""))
    try:
        t = datetime.strptime(text, "%Y:%m:%d %H:%M:%S").replace(tzinfo=timezone.utc)
    except ValueError:
        return (gps_ns, "UTC (GPS time stamp)", gps_ns, None) if gps_ns is not None else (None, "unknown", None, None)
    sub = _text(exif_ifd.get(37521, ""))
    if sub.isdigit():
        t += timedelta(seconds=int(sub) / 10 ** len(sub))
    zone = "unknown"
    offset = _text(exif_ifd.get(36881, ""))
    if len(offset) == 6 and offset[0] in "+-" and offset[1:3].isdigit() and offset[4:6].isdigit():
        delta = timedelta(hours=int(offset[1:3]), minutes=int(offset[4:6]))
        t = t - delta if offset[0] == "+" else t + delta
        zone = offset
    t_ns = int(t.timestamp()) * 1_000_000_000 + t.microsecond * 1000
    if not 0 <= t_ns < 2**63:  # before 1970 or past 2262: no int64 nanosecond time
        return gps_ns, ("unknown" if gps_ns is None else "UTC (GPS time stamp)"), gps_ns, None
    if gps_ns is None:
        return t_ns, zone, None, None
    diff_s = (t_ns - gps_ns) / 1e9
    if zone != "unknown":
        if abs(diff_s) > TIME_TAG_TOLERANCE_S:
            return t_ns, zone, gps_ns, (f"DateTimeOriginal (UTC with OffsetTimeOriginal {zone}) and the GPS time "
                                        f"stamp differ by {diff_s:+.0f} s: DateTimeOriginal used")
        return t_ns, zone, gps_ns, None
    step = round(diff_s / ZONE_STEP_S) * ZONE_STEP_S
    if abs(diff_s - step) <= TIME_TAG_TOLERANCE_S and abs(step) <= 14 * 3600:
        return t_ns - step * 1_000_000_000, f"{_zone_name(step)} (from the GPS time stamp)", gps_ns, None
    return gps_ns, "UTC (GPS time stamp)", gps_ns, (
        f"DateTimeOriginal is {diff_s:+.0f} s from the GPS time stamp, not a time-zone offset (the camera's clock "
        "was set wrong?): the GPS time used")


def _maker_note_attitude(path) -> tuple[tuple[float, float, float] | None, tuple[float, float, float] | None]:
    """(gimbal, body) (yaw, pitch, roll) degrees from a DJI MakerNote (CameraYaw/Pitch/Roll, Yaw/Pitch/Roll)."""
    import logging

    import exifread

    logging.getLogger("exifread").setLevel(logging.CRITICAL)  # its complaints about damaged tags are not ours to print
    with open(path, "rb") as f:
        tags = exifread.process_file(f, details=True)

    def get(name):
        v = tags.get(f"MakerNote {name}")
        try:
            return float(v.values[0]) if v is not None else math.nan
        except (TypeError, ValueError, IndexError, AttributeError):
            return math.nan

    gimbal = (get("CameraYaw"), get("CameraPitch"), get("CameraRoll"))
    body = (get("Yaw"), get("Pitch"), get("Roll"))
    ok = lambda a: all(math.isfinite(x) for x in a)  # noqa: E731
    return (gimbal if ok(gimbal) else None), (body if ok(body) else None)


def _maker_note_pose(path) -> MakerPose | None:
    gimbal, body = _maker_note_attitude(path)
    if gimbal is None:
        return None
    return MakerPose(maker="DJI", gimbal_ypr_deg=gimbal, flight_ypr_deg=body,
                     attitude_source="DJI MakerNote CameraYaw/Pitch/Roll, Yaw/Pitch/Roll", alt_datum="amsl")


def _camera_size(exif_ifd: dict, width: int, height: int, resaved_by: str, p: Path,
                 warnings: list[str]) -> tuple[int, int] | None:
    """The camera's frame (EXIF PixelXDimension/PixelYDimension, 40962/40963) when the stored image was resized
    from it; None when they agree or are not stated. InputError when the stored image is the camera's turned by 90
    degrees, or cropped by the program that re-saved it (its pixels cannot be mapped back)."""
    try:
        cw, ch = int(exif_ifd.get(40962, 0) or 0), int(exif_ifd.get(40963, 0) or 0)
    except (TypeError, ValueError):
        return None
    if cw <= 0 or ch <= 0 or (cw, ch) == (width, height):
        return None
    if (cw, ch) == (height, width):
        raise InputError(f"stored {width}x{height} px, but the camera wrote {cw}x{ch} (EXIF PixelXDimension/"
                         "PixelYDimension): the image was turned by 90 degrees after capture; use the camera's "
                         "original file", path=p)
    if abs(width / cw * ch - height) <= 1.0:
        warnings.append(f"resized after capture from {cw}x{ch} to {width}x{height} px: intrinsics scaled by "
                        f"{width / cw:.4g}")
        return cw, ch
    if resaved_by:
        raise InputError(f"stored {width}x{height} px is not the camera's {cw}x{ch} (EXIF PixelXDimension/"
                         f"PixelYDimension) scaled: cropped by {resaved_by!r} after capture?; use the camera's "
                         "original file", path=p)
    warnings.append(f"EXIF PixelXDimension/PixelYDimension {cw}x{ch} differ from the stored {width}x{height} px: "
                    "ignored")
    return None


def read_photo(path, alt_datum: str | None = None) -> Photo:
    """One photo's metadata. alt_datum overrides the datum of the altitude tag (default: the maker's, see
    docs/ingest.md). Raises InputError naming the file when it is not a readable JPEG, has no GPS position,
    no camera attitude of any maker ridgeloc reads, a corrupt XMP packet, a position or angle out of range, or
    pixels that cannot be mapped to the camera's (turned by 90 degrees, or cropped, after capture)."""
    from PIL import Image, UnidentifiedImageError

    p = Path(path)
    if alt_datum is not None and alt_datum not in ALT_DATUMS_PHOTO:
        raise InputError(f"unknown altitude datum {alt_datum!r} (choose {' or '.join(ALT_DATUMS_PHOTO)})", path=p)
    caught: list = []
    try:
        with warnings_module.catch_warnings(record=True) as caught, Image.open(p) as im:
            if im.format not in ("JPEG", "MPO"):  # MPO: a JPEG with a multi-picture (preview) index
                raise InputError(f"not a JPEG photo ({im.format})", path=p)
            width, height = im.size
            packet = im.info.get("xmp", b"")
            exif = im.getexif()
            exif_ifd = dict(exif.get_ifd(0x8769))
            gps = dict(exif.get_ifd(0x8825))
            base = dict(exif)
    except UnidentifiedImageError:
        raise InputError("not an image file (its bytes are no JPEG, TIFF or other image format)", path=p) from None
    except OSError as exc:
        if exc.errno is not None:
            raise
        raise InputError(f"damaged image ({str(exc)[:120]})", path=p) from None
    if isinstance(packet, str):
        packet = packet.encode()
    warnings: list[str] = [f"Pillow: {str(w.message).strip()[:160]}" for w in caught
                           if issubclass(w.category, UserWarning)]  # e.g. "Corrupt EXIF data"
    root = parse_xmp_tree(packet, p) if packet else None
    xmp = xmp_properties(root) if root is not None else {}
    dji = {name: v for (ns, name), v in xmp.items() if ns == NS_DJI}
    make = _text(base.get(271, "")) or xmp.get(("http://ns.adobe.com/tiff/1.0/", "Make"), "")
    model = _text(base.get(272, "")) or xmp.get(("http://ns.adobe.com/tiff/1.0/", "Model"), "")

    pose = read_maker_pose(xmp, root, make, model)
    if pose is None and make.upper().startswith("DJI"):
        pose = _maker_note_pose(p)
    if pose is None:
        raise InputError(f"no gimbal attitude (none of {POSE_TAGS_LOOKED_FOR})", path=p)
    warnings += pose.notes

    lat = _dms(gps.get(2), gps.get(1), "N") if 2 in gps else pose.lat_deg
    lon = _dms(gps.get(4), gps.get(3), "E") if 4 in gps else pose.lon_deg
    if not (math.isfinite(lat) and math.isfinite(lon)):
        raise InputError("no GPS position (EXIF GPSLatitude/GPSLongitude, drone-dji:GpsLatitude/GpsLongitude, "
                         "drone-skydio:Latitude/Longitude)", path=p)
    if not (-90 <= lat <= 90 and -180 <= lon <= 180) or (lat == 0 and lon == 0):
        raise InputError(f"GPS position out of range or unset ({lat:.6f}, {lon:.6f})", path=p)
    gps_alt = _rational(gps.get(6)) if 6 in gps else math.nan
    if math.isfinite(gps_alt) and _text(gps.get(5, b"\x00")) in ("\x01", "1"):
        gps_alt = -gps_alt  # GPSAltitudeRef 1: below sea level
    if math.isfinite(pose.alt_m):
        alt, alt_source = pose.alt_m, pose.alt_source
    elif math.isfinite(gps_alt):
        alt, alt_source = gps_alt, "EXIF GPSAltitude"
    else:
        raise InputError("no altitude (drone-dji:AbsoluteAltitude, drone-skydio:AbsoluteAltitude, EXIF GPSAltitude)",
                         path=p)
    if not -1000.0 < alt < 20000.0:
        raise InputError(f"altitude {alt} m out of range ({alt_source})", path=p)

    gimbal = pose.gimbal_ypr_deg
    if not (-360 <= gimbal[0] <= 360 and -180 <= gimbal[1] <= 180 and -180 <= gimbal[2] <= 180):
        raise InputError(f"gimbal angles out of range (yaw, pitch, roll = {gimbal})", path=p)
    body = pose.flight_ypr_deg
    flight = body if body is not None and all(math.isfinite(v) and abs(v) <= 360 for v in body) else None

    software = _text(base.get(305, ""))
    creator = xmp.get(("http://ns.adobe.com/xap/1.0/", "CreatorTool"), "")
    resaved_by = desktop_program([software, creator, *_history_agents(root)])
    if resaved_by:
        warnings.append(f"re-saved after capture by {resaved_by!r} (EXIF Software / xmp:CreatorTool / xmpMM:History):"
                        " it may have turned the pixels against the pose; locate finds out from two or more photos "
                        "marked, else state --image-rotation (docs/locate.md)")
    orientation = base.get(274, 1)
    orientation = orientation if isinstance(orientation, int) and 1 <= orientation <= 8 else 1
    if orientation != 1:
        warnings.append(f"EXIF Orientation {orientation}: viewers show this photo turned or mirrored; its pixels here "
                        "(and in `ridgeloc mark`) are the stored image's, which are the camera's")
    camera_size = _camera_size(exif_ifd, width, height, resaved_by, p, warnings)

    focal_mm = _rational(exif_ifd.get(37386))
    f35 = _rational(exif_ifd.get(41989))
    calibration = pose.calibration
    if pose.maker in ("DJI", "Autel") and dji:
        calibration = dji_calibration(dji, camera_size or (width, height), warnings)
    elif calibration is not None and pose.maker == "Skydio":
        entry = database_entry(make, model)  # Skydio's optical centre is in the full sensor's pixels
        if entry is not None:
            import dataclasses

            calibration = dataclasses.replace(calibration, ref_size_px=(int(entry["widthPixels"]),
                                                                        int(entry["heightPixels"])))
    intr = photo_intrinsics(width, height, make, model, calibration, pose.fov_deg,
                            focal_mm if math.isfinite(focal_mm) else None, f35 if math.isfinite(f35) else None,
                            warnings, camera_size, pose.thermal)
    t_ns, zone, gps_t_ns, time_warning = _photo_time(exif_ifd, gps)
    if t_ns is None:
        warnings.append("no EXIF DateTimeOriginal or GPSDateStamp/GPSTimeStamp: photos are ordered by name")
    if time_warning:
        warnings.append(time_warning)

    lrf_range = _float(dji.get("LRFTargetDistance"))
    lrf_status = dji.get("LRFStatus", "").strip() if "LRFTargetDistance" in dji or "LRFStatus" in dji else ""
    target = None
    t_lat, t_lon = _float(dji.get("LRFTargetLat")), _float(dji.get("LRFTargetLon"))
    t_alt = _float(dji.get("LRFTargetAbsAlt"))
    if all(math.isfinite(v) for v in (t_lat, t_lon, t_alt)) and abs(t_lat) <= 90 and abs(t_lon) <= 180:
        target = (t_lat, t_lon, t_alt)
    rtk_flag = _float(dji.get("RtkFlag"))
    rtk_std = tuple(_float(dji.get(k)) for k in ("RtkStdLon", "RtkStdLat", "RtkStdHgt"))
    return Photo(
        path=str(p), make=make, model=model, width_px=int(width), height_px=int(height), t_ns=t_ns, time_zone=zone,
        lat_deg=float(lat), lon_deg=float(lon), alt_m=float(alt), alt_datum=alt_datum or pose.alt_datum,
        alt_source=alt_source, relative_alt_m=float(pose.relative_alt_m), gps_alt_m=float(gps_alt),
        gimbal_ypr_deg=tuple(float(v) for v in gimbal), flight_ypr_deg=flight, attitude_source=pose.attitude_source,
        intrinsics=intr, lrf_range_m=lrf_range, lrf_status=lrf_status, dji_target_lla=target,
        rtk_flag=int(rtk_flag) if math.isfinite(rtk_flag) and abs(rtk_flag) < 2**31 else None,
        rtk_std_m=rtk_std if all(math.isfinite(v) for v in rtk_std) else None, gps_t_ns=gps_t_ns,
        warnings=tuple(warnings), maker=pose.maker, relative_alt_source=pose.relative_alt_source,
        resaved_by=resaved_by, orientation=int(orientation))


def expand_photo_paths(paths) -> list[Path]:
    """Photos named, and the .jpg/.jpeg files in folders named, sorted by name within a folder."""
    out: list[Path] = []
    for p in map(Path, paths):
        if p.is_dir():
            out += sorted(c for c in p.iterdir() if c.suffix.lower() in PHOTO_SUFFIXES and c.is_file())
        else:
            out.append(p)
    return out


def read_photos(paths, alt_datum: str | None = None) -> tuple[list[Photo], list[tuple[str, str]]]:
    """(photos read, sorted by time then name; [(path, one-line error)] of the ones that could not be read).
    A folder stands for the photos in it."""
    photos, bad = [], []
    for p in expand_photo_paths(paths):
        try:
            photos.append(read_photo_checked(p, alt_datum))
        except InputError as exc:  # damaged or unreadable (permissions, I/O): listed, the folder goes on
            bad.append((str(p), str(exc)))
    photos.sort(key=lambda ph: (ph.t_ns if ph.t_ns is not None else np.iinfo(np.int64).max, ph.name))
    return photos, bad


def read_photo_checked(path, alt_datum: str | None = None) -> Photo:
    """read_photo, with anything a third-party parser raises on damaged bytes, or an I/O failure, turned into one
    InputError naming the file (`boundary.reader_boundary`; the fuzz target checks that ridgeloc's own code
    raises nothing else)."""
    if not Path(path).is_file():
        raise InputError("no such photo", path=path)
    with reader_boundary(path, "photo"):
        return read_photo(path, alt_datum)
