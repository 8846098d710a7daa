"""Drone photos (JPEG with EXIF and XMP): per photo its time, position, aircraft and gimbal attitude, intrinsics,
laser range and the maker's own laser target. Every tag read, and why, is in docs/ingest.md ("Drone photos").

Libraries: Pillow reads the image size, the EXIF and GPS IFDs and the raw XMP packet (APP1
"http://ns.adobe.com/xap/1.0/"); defusedxml parses the packet (hardened against entity expansion, as Pillow's own
getxmp uses it); exifread decodes the DJI MakerNote (older DJI photos carry the attitude only there). All three
are pure Python wheels (Pillow's C code is in its wheel); no system binary (exiftool) is needed.

Conventions (DJI): Gimbal*/Flight* Yaw, Pitch, Roll degrees are the ZYX (yaw-pitch-roll) Euler angles of the
gimbal / body FRD frame in the local NED frame at the aircraft, yaw from true north, gimbal yaw earth-referenced;
pitch -90 looks straight down.
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
from pipeline.ingest.photo_camera import PhotoIntrinsics, photo_intrinsics

PHOTO_SUFFIXES = (".jpg", ".jpeg")
NS_DJI = "http://www.dji.com/drone-dji/1.0/"
NS_RDF = "http://www.w3.org/1999/02/22-rdf-syntax-ns#"
# Namespaces of other makers whose pose tags this reader recognises but does not read (conventions unverified).
OTHER_MAKER_NAMESPACES = {
    "http://www.parrot.com/drone-parrot/1.0/": "Parrot (drone-parrot)",
    "https://www.skydio.com/drone-skydio/1.0/": "Skydio (drone-skydio)",
    "http://pix4d.com/camera/1.0/": "Autel / Pix4D camera (Camera:)",
}
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

    @property
    def lrf_valid(self) -> bool:
        return self.lrf_status.lower() == LRF_VALID_STATUS and math.isfinite(self.lrf_range_m) and self.lrf_range_m > 0

    @property
    def name(self) -> str:
        return Path(self.path).name


def parse_xmp(packet: bytes, path) -> dict[tuple[str, str], str]:
    """{(namespace URI, local name): text} of every property in an XMP packet, written as attributes of
    rdf:Description or as simple child elements. Raises InputError (naming `path`) for a corrupt packet."""
    import defusedxml.ElementTree as DET
    from defusedxml import DefusedXmlException

    if len(packet) > MAX_XMP_BYTES:
        raise InputError(f"XMP packet of {len(packet)} bytes (more than {MAX_XMP_BYTES}): refused", path=path)
    text = packet.strip(b"\x00 \t\r\n")
    try:
        root = DET.fromstring(text)
    except DefusedXmlException as exc:
        raise InputError(f"corrupt XMP packet (forbidden XML construct: {type(exc).__name__})", path=path) from None
    except Exception as exc:  # xml.etree.ElementTree.ParseError and friends
        raise InputError(f"corrupt XMP packet ({str(exc).splitlines()[0][:120] if str(exc) else type(exc).__name__})",
                         path=path) from None
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


def _is_camera_firmware(text: str, make: str) -> bool:
    """True for an EXIF Software value a camera writes (DJI: a firmware version such as 'v01.02.5318' or the
    model), False for a desktop program's name."""
    t = text.strip().lower()
    return bool(t) and (t[0] in "v0123456789" or (make and t.startswith(make.strip().lower())))


def read_photo(path, alt_datum: str | None = None) -> Photo:
    """One photo's metadata. alt_datum overrides the datum of AbsoluteAltitude / GPSAltitude ("amsl" by default:
    see docs/ingest.md). Raises InputError naming the file when it is not a readable JPEG, has no GPS position,
    no gimbal attitude, a corrupt XMP packet, or a position or angle out of range."""
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
        raise InputError("not an image Pillow can identify", path=p) from None
    except OSError as exc:
        if exc.errno is not None:
            raise
        raise InputError(f"damaged image ({str(exc)[:120]})", path=p) from None
    if isinstance(packet, str):
        packet = packet.encode()
    warnings: list[str] = [f"Pillow: {str(w.message).strip()[:160]}" for w in caught
                           if issubclass(w.category, UserWarning)]  # e.g. "Corrupt EXIF data"
    xmp = parse_xmp(packet, p) if packet else {}
    dji = {name: v for (ns, name), v in xmp.items() if ns == NS_DJI}
    others = sorted({OTHER_MAKER_NAMESPACES[ns] for ns, _ in xmp if ns in OTHER_MAKER_NAMESPACES})
    make = _text(base.get(271, "")) or xmp.get(("http://ns.adobe.com/tiff/1.0/", "Make"), "")
    model = _text(base.get(272, "")) or xmp.get(("http://ns.adobe.com/tiff/1.0/", "Model"), "")

    lat = _dms(gps.get(2), gps.get(1), "N") if 2 in gps else _float(dji.get("GpsLatitude"))
    lon = _dms(gps.get(4), gps.get(3), "E") if 4 in gps else _float(dji.get("GpsLongitude", dji.get("GpsLongtitude")))
    if not (math.isfinite(lat) and math.isfinite(lon)):
        raise InputError("no GPS position (EXIF GPSLatitude/GPSLongitude, drone-dji:GpsLatitude/GpsLongitude)", path=p)
    if not (-90 <= lat <= 90 and -180 <= lon <= 180) or (lat == 0 and lon == 0):
        raise InputError(f"GPS position out of range or unset ({lat:.6f}, {lon:.6f})", path=p)
    gps_alt = _rational(gps.get(6)) if 6 in gps else math.nan
    if math.isfinite(gps_alt) and _text(gps.get(5, b"\x00")) in ("\x01", "1"):
        gps_alt = -gps_alt  # GPSAltitudeRef 1: below sea level
    abs_alt = _float(dji.get("AbsoluteAltitude"))
    if math.isfinite(abs_alt):
        alt, alt_source = abs_alt, "drone-dji:AbsoluteAltitude"
    elif math.isfinite(gps_alt):
        alt, alt_source = gps_alt, "EXIF GPSAltitude"
    else:
        raise InputError("no altitude (drone-dji:AbsoluteAltitude, EXIF GPSAltitude)", path=p)
    if not -1000.0 < alt < 20000.0:
        raise InputError(f"altitude {alt} m out of range ({alt_source})", path=p)

    gimbal = tuple(_float(dji.get(f"Gimbal{a}Degree")) for a in ("Yaw", "Pitch", "Roll"))
    body = tuple(_float(dji.get(f"Flight{a}Degree")) for a in ("Yaw", "Pitch", "Roll"))
    attitude_source = "drone-dji XMP Gimbal*/Flight*Degree"
    if not all(math.isfinite(v) for v in gimbal):
        mn_gimbal, mn_body = _maker_note_attitude(p) if make.upper().startswith("DJI") else (None, None)
        if mn_gimbal is None:
            extra = f"; {', '.join(others)} pose tags are not read (conventions unverified)" if others else ""
            raise InputError("no gimbal attitude (drone-dji:GimbalYawDegree/GimbalPitchDegree/GimbalRollDegree, "
                             f"DJI MakerNote CameraYaw/CameraPitch/CameraRoll){extra}", path=p)
        gimbal, attitude_source = mn_gimbal, "DJI MakerNote CameraYaw/Pitch/Roll, Yaw/Pitch/Roll"
        body = mn_body if mn_body is not None else (math.nan,) * 3
    if not (-360 <= gimbal[0] <= 360 and -180 <= gimbal[1] <= 180 and -180 <= gimbal[2] <= 180):
        raise InputError(f"gimbal angles out of range (yaw, pitch, roll = {gimbal})", path=p)
    flight = body if all(math.isfinite(v) and abs(v) <= 360 for v in body) else None

    focal_mm = _rational(exif_ifd.get(37386))
    f35 = _rational(exif_ifd.get(41989))
    intr = photo_intrinsics(width, height, make, model, dji, focal_mm if math.isfinite(focal_mm) else None,
                            f35 if math.isfinite(f35) else None, warnings)
    software = _text(base.get(305, ""))
    creator = xmp.get(("http://ns.adobe.com/xap/1.0/", "CreatorTool"), "")
    editor = next((t for t in (software, creator) if t and not _is_camera_firmware(t, make)), "")
    if editor:
        warnings.append(f"re-saved after capture by {editor!r} (EXIF Software / xmp:CreatorTool): an editor may "
                        "have rotated the pixels against the recorded pose (see locate --image-rotation)")
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
        lat_deg=float(lat), lon_deg=float(lon), alt_m=float(alt), alt_datum=alt_datum or "amsl",
        alt_source=alt_source, relative_alt_m=_float(dji.get("RelativeAltitude")), gps_alt_m=float(gps_alt),
        gimbal_ypr_deg=tuple(float(v) for v in gimbal), flight_ypr_deg=flight, attitude_source=attitude_source,
        intrinsics=intr, lrf_range_m=lrf_range, lrf_status=lrf_status, dji_target_lla=target,
        rtk_flag=int(rtk_flag) if math.isfinite(rtk_flag) else None,
        rtk_std_m=rtk_std if all(math.isfinite(v) for v in rtk_std) else None, gps_t_ns=gps_t_ns,
        warnings=tuple(warnings))


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
