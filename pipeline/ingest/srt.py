"""DJI .SRT subtitle telemetry: one cue per frame or per second, parsed with regexes, whatever the model.

Layouts (the test corpus in tests/data/srt has one file per layout; docs/ingest.md lists them):
- bracketed keys `[latitude: 22.1] [longitude: 113.9] [rel_alt: 50.0 abs_alt: 120.0]` (Mavic 3, Air 2S, Mini,
  Avata, M30/M300), `[altitude: ..]` on Mavic Air 2 / Mavic 2, spaces before the colon and `longtitude` (sic) on
  Mavic 2 / Mavic Air; gimbal `[gb_yaw: .. gb_pitch: .. gb_roll: ..]`, aircraft `[drone_yaw: ..]`, focal length
  `[focal_len: ..]` (35 mm equivalent; x10 integers on older firmware) and digital zoom `[dzoom_ratio: ..]`
  (x10000 integers on some firmware) or `[dzoom: ..]`;
- `GPS (lon, lat, sats) ... H 38.00m ... F.PRY (p°, r°, y°), G.PRY (p°, r°, y°)` (Phantom 4 RTK / Pro), aircraft
  and gimbal pitch/roll/yaw in degrees (NED, ZYX, yaw from true north); a `DZOOM 2.000` token is read too;
- `HOME(lon,lat) date ... GPS(lon,lat,sats) BAROMETER:h` (Phantom 3/4, Mavic Pro);
- `GPS(lat,lon,12.3M)` (enterprise payloads: a decimal third value with an `M` is the altitude, an integer is
  the satellite count, which is what tells the coordinate order apart).
A file whose cues carry no altitude at all (Mavic 2 Pro firmware printing only `[latitude]` `[longtitude]`) gives
its horizontal track: altitude from the mapping's `altitude_m` (datum `abs_datum`) when set, else NaN on datum
"missing", which gives way to another log's positions when the flight has one (merge.py). Heights above the
take-off point alone (`H`, `BAROMETER`) keep the datum "relative" unless the mapping's `takeoff_altitude_m` states
the take-off point's altitude (datum `abs_datum`), which is added to them.
Cue times are the subtitle start times on the "video" clock; each cue's absolute date/time, when the layout
prints one, is kept as a ClockLink from "video" to "local" (the aircraft's wall clock, time zone unknown), or to
"unix" when `srt.utc_offset_h` states the zone.
"""

from __future__ import annotations

import math
import re
from array import array
from datetime import timedelta
from pathlib import Path

import numpy as np

from pipeline.errors import ConfigError, LogReadError
from pipeline.ingest.columns import sort_by_time
from pipeline.ingest.frames import quat_ned_from_frd_euler
from pipeline.ingest.model import (
    AttitudeSeries,
    ClockLink,
    FieldOfViewSeries,
    FlightLog,
    GimbalSeries,
    PositionSeries,
    StreamInfo,
)

NUM = r"[-+]?\d+(?:\.\d+)?"
VAL = r"(N/A|n/a|" + NUM + r")"
NO_TIME = np.iinfo(np.int64).min  # wall_ns of a cue without a date
_KEY = re.compile(r"([A-Za-z_]+)\s*:\s*" + VAL)
_GPS = re.compile(r"GPS\s*\(\s*" + VAL + r"\s*,\s*" + VAL + r"\s*(?:,\s*" + VAL + r"\s*([Mm])?\s*)?\)")
_PRY = re.compile(r"([FG])\.PRY\s*\(\s*(" + NUM + r")°?\s*,\s*(" + NUM + r")°?\s*,\s*(" + NUM + r")°?\s*\)")
_H = re.compile(r"(?:^|[\s,])H\s*:?\s*(" + NUM + r")\s*m", re.M)
_BARO = re.compile(r"BAROMETER\s*:\s*(" + NUM + r")")
_DZOOM = re.compile(r"\bDZOOM\s+(" + NUM + r")")
_DATE = re.compile(r"(\d{4})[-./](\d\d)[-./](\d\d)[ T]+(\d\d):(\d\d):(\d\d)(?:[,.](\d{1,3}))?(?:[,.](\d{1,3}))?")
# key spellings of each quantity across models and firmware (lower case)
ALIASES = {"latitude": ("latitude", "lat"), "longitude": ("longitude", "longtitude", "lon", "lng"),
           "abs_alt": ("abs_alt", "altitude"), "rel_alt": ("rel_alt",),
           "focal_len": ("focal_len",), "dzoom": ("dzoom_ratio", "dzoom"),
           "g_yaw": ("gb_yaw",), "g_pitch": ("gb_pitch",), "g_roll": ("gb_roll",),
           "f_yaw": ("drone_yaw",), "f_pitch": ("drone_pitch",), "f_roll": ("drone_roll",)}
_QUANTITY_OF = {name: (q, rank) for q, names in ALIASES.items() for rank, name in enumerate(names)}
FLOAT_COLS = ("lat", "lon", "alt", "abs_alt", "rel_alt", "f_roll", "f_pitch", "f_yaw", "g_roll", "g_pitch", "g_yaw",
              "focal_mm", "dzoom")


def _num(s: str | None) -> float:
    return float("nan") if s is None or s.upper() == "N/A" else float(s)


def _cues(text: str):
    """(start ns, body text) of every cue, split by the `srt` library (it keeps blank lines inside a cue, as the
    M300 writes them, and skips what is not a cue, such as a cut-off time line)."""
    import srt

    us = timedelta(microseconds=1)
    for sub in srt.parse(text, ignore_errors=True):
        yield (sub.start // us) * 1000, sub.content


_DAY_NS: dict[str, int] = {}


def _wall_ns(body: str) -> int:
    """The cue's printed date/time as naive nanoseconds since 1970 (no time zone), or NO_TIME."""
    d = _DATE.search(body)
    if d is None:
        return NO_TIME
    y, mo, da, h, mi, s, ms, us = d.groups()
    key = y + mo + da
    if key not in _DAY_NS:
        _DAY_NS[key] = int(np.datetime64(f"{y}-{mo}-{da}", "ns").astype(np.int64))
    return (_DAY_NS[key] + ((int(h) * 60 + int(mi)) * 60 + int(s)) * 10**9 + int((ms or "0").ljust(3, "0")) * 10**6
            + int((us or "0").ljust(3, "0")) * 10**3)


def _focal_mm(raw: str | None, scale) -> float:
    """35 mm-equivalent focal length in mm: older firmware prints x10 integers (`240` = 24 mm)."""
    if raw is None:
        return float("nan")
    v = _num(raw)
    if scale == "auto":
        return v / 10 if "." not in raw and v >= 100 else v
    return v * float(scale)


def _dzoom(raw: str | None) -> float:
    """Digital zoom factor: some firmware prints x10000 integers (`10000` = 1.0x)."""
    v = _num(raw)
    return v / 10000 if v >= 100 else v


def parse_srt(text: str, alt: str = "abs", gps_order: str = "auto", focal_len_scale="auto") -> dict[str, np.ndarray]:
    """Parse SRT text -> columns, one row per cue with a position: t_ns (start, video clock), lat, lon, alt
    (chosen by `alt`, NaN where absent) and rel (alt is relative to take-off), abs_alt and rel_alt (NaN where
    absent), aircraft f_* and gimbal g_* roll/pitch/yaw in degrees, focal_mm (35 mm equivalent) and dzoom (NaN
    where absent), wall_ns (the cue's printed date/time, naive, NO_TIME where absent). Also `n_no_fix` (cues
    with 0,0 or N/A positions), `n_cut` (cues cut off inside the position) and `n_cues` (every cue), 0-d."""
    if alt not in ("abs", "rel"):
        raise ConfigError(f"srt mapping: alt must be 'abs' or 'rel', not {alt!r}")
    if gps_order not in ("auto", "lat_lon", "lon_lat"):
        raise ConfigError(f"srt mapping: gps_order must be auto, lat_lon or lon_lat, not {gps_order!r}")
    text = text.lstrip("\ufeff").replace("\r\n", "\n").replace("\r", "\n")
    n_no_fix, n_cut, n_cues = 0, 0, 0
    col = {k: array("d") for k in FLOAT_COLS} | {"t_ns": array("q"), "wall_ns": array("q"), "rel": array("b")}
    appends = [(k, c.append) for k, c in col.items()]  # compact columns: 8 bytes a value, not a dict per cue
    nan = float("nan")
    for t_ns, body in _cues(text):
        n_cues += 1
        plain = body  # <font> tags need no removal: no pattern matches inside them
        got: dict[str, str] = {}
        ranks: dict[str, int] = {}
        for k, v in _KEY.findall(plain):
            qr = _QUANTITY_OF.get(k.lower())
            if qr is not None and qr[1] < ranks.get(qr[0], 99):
                got[qr[0]], ranks[qr[0]] = v, qr[1]
        row = dict.fromkeys(FLOAT_COLS, nan)
        row.update(t_ns=t_ns, wall_ns=_wall_ns(plain))
        for q in ("abs_alt", "rel_alt", "g_yaw", "g_pitch", "g_roll", "f_yaw", "f_pitch", "f_roll"):
            if q in got:
                row[q] = _num(got[q])
        row["focal_mm"] = _focal_mm(got.get("focal_len"), focal_len_scale)
        dz = got.get("dzoom") or (m.group(1) if "DZOOM" in plain and (m := _DZOOM.search(plain)) else None)
        row["dzoom"] = _dzoom(dz) if dz is not None else nan
        if ("latitude" in got) != ("longitude" in got):
            n_cut += 1
            continue  # half a position: the cue was cut off (end of file) inside it
        if "latitude" in got:
            row["lat"], row["lon"] = _num(got["latitude"]), _num(got["longitude"])
        elif "GPS" in plain and (g := _GPS.search(plain)) is not None:
            a, b, third, unit = g.groups()
            order = gps_order
            if order == "auto":  # GPS(lat, lon, 12.3M) carries an altitude; GPS(lon, lat, sats) a count
                order = "lat_lon" if third is not None and (unit or "." in third) else "lon_lat"
            lat, lon = (_num(b), _num(a)) if order == "lon_lat" else (_num(a), _num(b))
            if abs(lat) > 90 >= abs(lon):  # cannot be a latitude: the layout guess was wrong
                lat, lon = lon, lat
            row["lat"], row["lon"] = lat, lon
            if third is not None and (unit or "." in third):
                row["abs_alt"] = _num(third)
        else:
            continue  # no position in this cue (a camera-only cue, or cut off before it)
        if "rel_alt" not in got and ("H" in plain or "BAROMETER" in plain):
            hm = _H.search(plain) or _BARO.search(plain)
            row["rel_alt"] = float(hm.group(1)) if hm else nan
        if "PRY" in plain:
            for which, p, r, y in _PRY.findall(plain):
                pre = "f_" if which == "F" else "g_"
                row[pre + "pitch"], row[pre + "roll"], row[pre + "yaw"] = float(p), float(r), float(y)
        lat, lon = row["lat"], row["lon"]
        if not (math.isfinite(lat) and math.isfinite(lon)) or (lat == 0 and lon == 0):
            n_no_fix += 1
            continue  # no GPS fix yet (0, 0 or N/A)
        use_rel = alt == "rel" or math.isnan(row["abs_alt"])
        row["alt"], row["rel"] = (row["rel_alt"], True) if use_rel else (row["abs_alt"], False)
        for k, append in appends:
            append(row[k])
    out: dict[str, np.ndarray] = {"n_no_fix": np.array(n_no_fix), "n_cut": np.array(n_cut), "n_cues": np.array(n_cues)}
    if not col["t_ns"]:
        return out
    for k, c in col.items():
        out[k] = np.frombuffer(c, np.int64) if c.typecode == "q" else np.frombuffer(c, c.typecode).astype(
            bool if k == "rel" else float)
    return out


def fov_from_focal(focal35_mm: np.ndarray, dzoom: np.ndarray, sensor_aspect: tuple[float, float],
                   video_aspect: tuple[float, float]) -> tuple[np.ndarray, np.ndarray]:
    """(hfov_deg, vfov_deg) of the video from a 35 mm-equivalent focal length and a digital zoom factor.

    The 35 mm equivalent matches the diagonal of the full sensor (aspect `sensor_aspect`, e.g. 4:3) to the
    43.27 mm diagonal of a 36 x 24 mm frame; digital zoom multiplies the focal length. Video crops the sensor to
    `video_aspect` (e.g. 16:9) keeping its full width, so the horizontal field is the sensor's and the vertical
    one follows from the video's aspect ratio."""
    f = np.asarray(focal35_mm, float) * np.where(np.isfinite(dzoom), dzoom, 1.0)
    sw, sh = sensor_aspect
    vw, vh = video_aspect
    tan_half_diag = np.hypot(36.0, 24.0) / (2.0 * f)
    tan_half_h = tan_half_diag * sw / np.hypot(sw, sh)
    return np.degrees(2 * np.arctan(tan_half_h)), np.degrees(2 * np.arctan(tan_half_h * vh / vw))


def _aspect(value, name: str) -> tuple[float, float]:
    try:
        w, h = (float(x) for x in str(value).split(":"))
        if w > 0 and h > 0:
            return w, h
    except ValueError:
        pass
    raise ConfigError(f"srt mapping: {name} must look like '16:9', not {value!r}")


def _restarts(t: np.ndarray) -> np.ndarray:
    """Shift each run of cues whose times start again from the beginning (several SRT files joined) to follow
    the previous run, as the joined videos would play. Returns the shifted times."""
    t = t.copy()
    back = np.flatnonzero(np.diff(t) < 0) + 1
    for i in back:
        t[i:] += t[i - 1] - t[i] + (t[i - 1] - t[i - 2] if i >= 2 else 0)
    return t


def read_srt(path: str | Path, mapping: dict) -> FlightLog:
    """Read a DJI .SRT into a FlightLog on the "video" clock: position, aircraft and gimbal attitude, field of
    view (from focal length and digital zoom) where present, and the cues' wall-clock times as a ClockLink."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8", errors="replace")
    except OSError as exc:
        raise LogReadError(f"cannot read: {exc.strerror}", path=path) from None
    if not text.strip():
        raise LogReadError("empty SRT file", path=path)
    cols = parse_srt(text, mapping["alt"], mapping["gps_order"], mapping["focal_len_scale"])
    if "t_ns" not in cols:
        why = f"{int(cols['n_cues'])} cues, none with a GPS position"
        if cols["n_no_fix"]:
            why += f" ({int(cols['n_no_fix'])} at 0,0 or N/A: no GPS fix)"
        raise LogReadError(f"no subtitle with a GPS position ({why}; not DJI telemetry?)", path=path)
    log = FlightLog(path=str(path), formats=["srt"])
    src = path.name
    warn = log.warnings.append
    if cols["n_no_fix"]:
        warn(f"{path}: {int(cols['n_no_fix'])} cues without a GPS fix (0,0 or N/A) skipped")
    if cols["n_cut"]:
        warn(f"{path}: {int(cols['n_cut'])} cue(s) cut off inside the position (end of file?) skipped")
    t = cols["t_ns"]
    if (np.diff(t) < 0).any():
        warn(f"{path}: cue times start again {int((np.diff(t) < 0).sum())} time(s) (SRT files joined?); each run "
             "is placed after the previous one")
        t = _restarts(t)
    has_abs, has_rel = np.isfinite(cols["abs_alt"]), np.isfinite(cols["rel_alt"])
    if mapping["alt"] == "abs" and has_abs.all():
        ok, alt, datum = has_abs, cols["abs_alt"], mapping["abs_datum"]
    elif has_rel.all() or (mapping["alt"] == "rel" and has_rel.any()):
        ok, alt, datum = has_rel, cols["rel_alt"], "relative"
        if mapping["alt"] == "abs" and has_abs.any():
            warn(f"{path}: some cues lack the absolute altitude; using relative altitudes")
        takeoff = mapping.get("takeoff_altitude_m")
        if takeoff is not None:  # heights above the take-off point + the take-off point's own altitude
            alt, datum = alt + float(takeoff), mapping["abs_datum"]
            warn(f"{path}: heights above the take-off point plus the mapping's srt.takeoff_altitude_m "
                 f"{float(takeoff):g} m ({datum})")
    else:
        ok, alt, datum = has_abs, cols["abs_alt"], mapping["abs_datum"]
    if not ok.any():  # e.g. Mavic 2 Pro firmware printing only [latitude] [longtitude]
        tt, lat, lon = sort_by_time(t, cols["lat"], cols["lon"])
        const = mapping.get("altitude_m")
        if const is not None:
            a, datum = np.full(tt.size, float(const)), mapping["abs_datum"]
            warn(f"{path}: no altitude in the subtitles: horizontal track read, altitude {float(const):g} m "
                 f"({datum}) from the mapping's srt.altitude_m")
        else:
            a, datum = np.full(tt.size, np.nan), "missing"
            warn(f"{path}: no altitude in the subtitles: horizontal track read ({tt.size} positions), altitude "
                 "missing; give a log of the flight with altitudes, or set the mapping's srt.altitude_m")
        log.position = PositionSeries(tt, lat, lon, a, datum, source=src, clock="video")
    else:
        if not ok.all():
            warn(f"{path}: {int((~ok).sum())} of {ok.size} cues without an altitude skipped")
        tt, lat, lon, a = sort_by_time(t[ok], cols["lat"][ok], cols["lon"][ok], alt[ok])
        log.position = PositionSeries(tt, lat, lon, a, datum, source=src, clock="video")
    for pre, kind in (("f_", "attitude"), ("g_", "gimbal")):
        ang = np.column_stack([cols[pre + "roll"], cols[pre + "pitch"], cols[pre + "yaw"]])
        ok = np.isfinite(ang).all(axis=1)
        if ok.any():
            q = quat_ned_from_frd_euler(*np.radians(ang[ok]).T)
            tt, q = sort_by_time(t[ok], q)
            if kind == "attitude":
                log.attitude = AttitudeSeries(tt, q, source=src, clock="video")
            else:
                log.gimbal = GimbalSeries(tt, q, np.zeros(tt.size, bool), source=src, clock="video")
    ok = np.isfinite(cols["focal_mm"]) & (cols["focal_mm"] > 0)
    if ok.any():
        h, v = fov_from_focal(cols["focal_mm"][ok], cols["dzoom"][ok],
                              _aspect(mapping["sensor_aspect"], "sensor_aspect"),
                              _aspect(mapping["video_aspect"], "video_aspect"))
        tt, h, v = sort_by_time(t[ok], h, v)
        log.field_of_view = FieldOfViewSeries(tt, h, v, source=src, clock="video")
    ok = cols["wall_ns"] != NO_TIME
    if ok.any():
        off = mapping["utc_offset_h"]
        wall = cols["wall_ns"][ok] - (0 if off is None else round(float(off) * 3600e9))
        log.clock_links.append(ClockLink("video", "local" if off is None else "unix", t[ok], wall))
    sup = tuple(k for k in ("position", "attitude", "gimbal", "field_of_view") if getattr(log, k) is not None)
    log.streams.append(StreamInfo(src, "DJI SRT", int(cols["n_cues"]), int(t.min()), int(t.max()), sup))
    return log
