"""DJI-style .SRT subtitle telemetry: one subtitle block per frame or per second, parsed with regexes.

Variants handled (FIELD_NOTES):
- `[latitude: 22.1] [longitude: 113.9] [rel_alt: 50.0 abs_alt: 120.0]` (Mavic 3, Air 2S, Mini; `[altitude: ..]`
  on some), optional `[gb_yaw: .. gb_pitch: .. gb_roll: ..]` gimbal angles;
- `GPS (lon, lat, sats) ... H 38.00m ... F.PRY (p°, r°, y°), G.PRY (p°, r°, y°)` (P4 RTK / P4 Pro), aircraft
  and gimbal pitch/roll/yaw in degrees (NED, ZYX, yaw from true north);
- `HOME(lon,lat) ... GPS(lon,lat,sats) BAROMETER:h` (Phantom 4) and `GPS(lat,lon,alt)` (M300).
Times are the subtitle start times on the "video" clock.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from pipeline.errors import ConfigError, LogReadError
from pipeline.ingest.columns import sort_by_time
from pipeline.ingest.frames import quat_ned_from_frd_euler
from pipeline.ingest.model import AttitudeSeries, FlightLog, GimbalSeries, PositionSeries, StreamInfo

NUM = r"[-+]?\d+(?:\.\d+)?"
_TIME = re.compile(r"(\d+):(\d\d):(\d\d)[,.](\d{1,3})\s*-->")
_BRACKET = re.compile(r"\[?\s*([a-z_]+)\s*:\s*(" + NUM + r")", re.I)
_GPS = re.compile(r"GPS\s*\(\s*(" + NUM + r")\s*,\s*(" + NUM + r")\s*(?:,\s*(" + NUM + r")\s*m?)?\s*\)")
_PRY = re.compile(r"([FG])\.PRY\s*\(\s*(" + NUM + r")°?\s*,\s*(" + NUM + r")°?\s*,\s*(" + NUM + r")°?\s*\)")
_H = re.compile(r"(?:^|[\s,])H\s+(" + NUM + r")\s*m", re.M)
_BARO = re.compile(r"BAROMETER\s*:\s*(" + NUM + r")")


def _block_values(text: str) -> dict[str, float]:
    """key -> value from `[key: value]` and `key: value` pairs of one block (lower-case keys)."""
    return {k.lower(): float(v) for k, v in _BRACKET.findall(text)}


def parse_srt(text: str, alt: str = "abs", gps_order: str = "auto") -> dict[str, np.ndarray]:
    """Parse SRT text -> columns t_ns, lat, lon, alt (NaN where absent), alt_is_rel (bool), and where present
    aircraft and gimbal roll/pitch/yaw in degrees (NaN where absent)."""
    if alt not in ("abs", "rel"):
        raise ConfigError(f"srt mapping: alt must be 'abs' or 'rel', not {alt!r}")
    if gps_order not in ("auto", "lat_lon", "lon_lat"):
        raise ConfigError(f"srt mapping: gps_order must be auto, lat_lon or lon_lat, not {gps_order!r}")
    rows = []
    for block in re.split(r"\n\s*\n", text.replace("\r\n", "\n").strip()):
        m = _TIME.search(block)
        if m is None:
            continue
        h, mi, s, ms = m.groups()
        t_ns = ((int(h) * 60 + int(mi)) * 60 + int(s)) * 10**9 + int(ms.ljust(3, "0")) * 10**6
        body = block[m.end():]
        body_plain = re.sub(r"<[^>]+>", " ", body)
        kv = _block_values(body_plain)
        nan = float("nan")
        row = {"t_ns": t_ns, "lat": nan, "lon": nan, "alt": nan, "rel": alt == "rel",
               "f_roll": nan, "f_pitch": nan, "f_yaw": nan, "g_roll": nan, "g_pitch": nan, "g_yaw": nan}
        if "latitude" in kv and "longitude" in kv:
            row["lat"], row["lon"] = kv["latitude"], kv["longitude"]
            if alt == "abs" and ("abs_alt" in kv or "altitude" in kv):
                row["alt"] = kv.get("abs_alt", kv.get("altitude"))
            elif "rel_alt" in kv:
                row["alt"], row["rel"] = kv["rel_alt"], True
            for src, dst in (("gb_yaw", "g_yaw"), ("gb_pitch", "g_pitch"), ("gb_roll", "g_roll"),
                             ("drone_yaw", "f_yaw"), ("drone_pitch", "f_pitch"), ("drone_roll", "f_roll")):
                if src in kv:
                    row[dst] = kv[src]
        else:
            g = _GPS.search(body_plain)
            if g is None:
                continue
            a, b = float(g.group(1)), float(g.group(2))
            order = gps_order
            if order == "auto":
                lon_first = "PRY" in body_plain or "HOME" in body_plain or re.search(r"GPS\s+\(", body_plain)
                order = "lon_lat" if lon_first else "lat_lon"
            lat, lon = (b, a) if order == "lon_lat" else (a, b)
            if abs(lat) > 90 >= abs(lon):  # cannot be a latitude: the variant guess was wrong
                lat, lon = lon, lat
            row["lat"], row["lon"] = lat, lon
            hm, bm = _H.search(body_plain), _BARO.search(body_plain)
            if g.group(3) is not None and "." in g.group(3) and alt == "abs":
                row["alt"] = float(g.group(3))  # M300: GPS(lat, lon, alt m)
            elif hm or bm:
                row["alt"], row["rel"] = float((hm or bm).group(1)), True
            for which, p, r, y in _PRY.findall(body_plain):
                pre = "f_" if which == "F" else "g_"
                row[pre + "pitch"], row[pre + "roll"], row[pre + "yaw"] = float(p), float(r), float(y)
        if row["lat"] == 0 and row["lon"] == 0:
            continue  # no GPS fix yet
        rows.append(row)
    if not rows:
        return {}
    return {k: np.array([r[k] for r in rows], dtype=np.int64 if k == "t_ns" else (bool if k == "rel" else float))
            for k in rows[0]}


def read_srt(path: str | Path, mapping: dict) -> FlightLog:
    """Read a DJI .SRT into a FlightLog on the "video" clock (position, and attitudes where present)."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8", errors="replace")
    except OSError as exc:
        raise LogReadError(f"cannot read: {exc.strerror}", path=path) from None
    if not text.strip():
        raise LogReadError("empty SRT file", path=path)
    cols = parse_srt(text, mapping["alt"], mapping["gps_order"])
    if not cols:
        raise LogReadError("no subtitle with a GPS position (not DJI telemetry, or no fix)", path=path)
    log = FlightLog(path=str(path), formats=["srt"])
    src = path.name
    t = cols["t_ns"]
    ok = np.isfinite(cols["alt"])
    if not ok.any():
        log.warnings.append(f"{path}: no altitude in the subtitles; position not read")
    else:
        rel = cols["rel"][ok]
        datum = "relative" if rel.any() else mapping["abs_datum"]
        if rel.any() and not rel.all():
            log.warnings.append(f"{path}: some subtitles lack the absolute altitude; using relative altitudes")
        tt, lat, lon, alt = sort_by_time(t[ok], cols["lat"][ok], cols["lon"][ok], cols["alt"][ok])
        log.position = PositionSeries(tt, lat, lon, alt, datum, source=src, clock="video")
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
    sup = tuple(k for k in ("position", "attitude", "gimbal") if getattr(log, k) is not None)
    log.streams.append(StreamInfo(src, "DJI SRT", int(t.size), int(t.min()), int(t.max()), sup))
    return log
