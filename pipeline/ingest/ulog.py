"""PX4 ULog (.ulg) through pyulog (optional dependency: `pip install ridgeloc[ulog]`).

Only the topics the mapping names are parsed (`message_name_filter_list`). Topic `timestamp` is boot
microseconds; GPS `time_utc_usec` pairs give the boot -> UNIX link, and every series is put on the UNIX clock
when that link exists (else it stays on "boot", with a warning).
"""

from __future__ import annotations

import contextlib
import io
from pathlib import Path

import numpy as np

from pipeline.errors import LogReadError
from pipeline.ingest.clocks import series_to_clock
from pipeline.ingest.columns import sort_by_time
from pipeline.ingest.model import (
    AttitudeSeries,
    CameraEventSeries,
    ClockLink,
    FlightLog,
    GimbalSeries,
    PositionSeries,
    RangeSeries,
    StreamInfo,
)
from pipeline.ingest.rangefinder import laser_facing, one_instance
from pipeline.ingest.tlog import GIMBAL_FLAG_YAW_IN_EARTH, GIMBAL_FLAG_YAW_IN_VEHICLE, GIMBAL_FLAG_YAW_LOCK

SUPPLIES = {"vehicle_global_position": "position", "sensor_gps": "position", "vehicle_gps_position": "position",
            "vehicle_attitude": "attitude", "gimbal_device_attitude_status": "gimbal", "distance_sensor": "range",
            "camera_capture": "camera_events", "camera_trigger": "camera_events"}
GPS_TOPICS = ("sensor_gps", "vehicle_gps_position")


def _ends_mid_message(path: Path) -> bool:
    """True when the last ULog message is cut short (pyulog stops there silently): walk the 3-byte message
    headers (uint16 size, uint8 type) after the 16-byte file header."""
    import mmap
    import struct

    size = path.stat().st_size
    if size <= 16:
        return size > 0
    with open(path, "rb") as f, mmap.mmap(f.fileno(), 0, access=mmap.ACCESS_READ) as mm:
        pos, unpack = 16, struct.Struct("<H").unpack_from
        while pos + 3 <= size:
            pos += 3 + unpack(mm, pos)[0]
    return pos != size


def _quat(d: dict) -> np.ndarray:
    return np.column_stack([d[f"q[{i}]"] for i in range(4)]).astype(float)


def _position(name: str, d: dict, cfg: dict):
    """(t_boot_ns, lat, lon, alt, datum) of the samples with a fix, from any PX4 position/GPS topic version."""
    t = d["timestamp"].astype(np.int64) * 1000
    if "latitude_deg" in d:  # sensor_gps since PX4 1.14: float degrees and metres
        lat, lon = d["latitude_deg"], d["longitude_deg"]
        alt_msl, alt_ell = d.get("altitude_msl_m"), d.get("altitude_ellipsoid_m")
    elif name in GPS_TOPICS:  # int 1e-7 deg, mm
        lat, lon = d["lat"] * 1e-7, d["lon"] * 1e-7
        alt_msl = d["alt"] * 1e-3 if "alt" in d else None
        alt_ell = d["alt_ellipsoid"] * 1e-3 if "alt_ellipsoid" in d else None
    else:  # vehicle_global_position: float64 degrees, float m
        lat, lon = d["lat"], d["lon"]
        alt_msl, alt_ell = d.get("alt"), d.get("alt_ellipsoid")
    ok = np.isfinite(lat) & np.isfinite(lon) & ~((lat == 0) & (lon == 0))
    if "fix_type" in d:
        ok &= d["fix_type"] >= cfg["min_fix_type"]
    if cfg["datum"] == "ellipsoid" and alt_ell is not None:
        alt, datum = alt_ell, "ellipsoid"
    else:
        alt, datum = alt_msl, "amsl"
    return t[ok], np.asarray(lat, float)[ok], np.asarray(lon, float)[ok], np.asarray(alt, float)[ok], datum


class _ReadBudget(Exception):
    pass


class _BudgetedFile:
    """The file as pyulog reads it, failing once it has read `factor` times the file's size: on some damaged
    files pyulog seeks back further than it read and loops forever."""

    def __init__(self, path: Path, factor: int = 20):
        self._f = open(path, "rb")
        self._left = factor * path.stat().st_size + (1 << 20)

    def read(self, n: int = -1) -> bytes:
        data = self._f.read(n)
        self._left -= len(data) + 1
        if self._left < 0:
            raise _ReadBudget("the parser does not advance (damaged message sizes)")
        return data

    def seek(self, offset: int, whence: int = 0) -> int:
        return self._f.seek(offset, whence)

    def tell(self) -> int:
        return self._f.tell()

    def close(self) -> None:
        self._f.close()


def read_ulog(path: str | Path, mapping: dict, scan_all: bool = False) -> FlightLog:
    """Read a .ulg into a FlightLog (mappings/ulog.yaml)."""
    try:
        from pyulog import ULog
    except ImportError:
        raise LogReadError("reading ULog needs pyulog: pip install 'ridgeloc[ulog]'", path=path) from None
    path = Path(path)
    topics = [t for q in ("position", "attitude", "gimbal", "range", "camera", "clock") for t in mapping[q]["topics"]]
    err = io.StringIO()
    try:
        with contextlib.redirect_stdout(err), contextlib.redirect_stderr(err):
            fh = _BudgetedFile(path)
            try:
                ulog = ULog(fh, message_name_filter_list=None if scan_all else sorted(set(topics)))
            finally:
                fh.close()
    except Exception as exc:  # pyulog raises bare Exception / struct.error / IndexError on bad files
        text = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise LogReadError(f"not a readable ULog: {text}", path=path) from None
    if not ulog.message_formats:
        raise LogReadError("no ULog message formats (garbage after the header, or not a ULog)", path=path)
    warnings: list[str] = []
    n_read = sum(len(d.data["timestamp"]) for d in ulog.data_list)
    if getattr(ulog, "file_corruption", False) or _ends_mid_message(path):
        topics = "every topic" if scan_all else "the selected topics"
        warnings.append(f"{path}: file is corrupt or cut off; read {n_read} messages of {topics} covering "
                        f"{_streams_span_s(ulog):.1f} s")
    data: dict[str, dict] = {}
    for d in ulog.data_list:
        if d.multi_id == 0 and len(d.data["timestamp"]):
            data[d.name] = d.data
        elif d.multi_id > 0 and d.name in mapping["range"]["topics"] and len(d.data["timestamp"]):
            data[f"{d.name}[{d.multi_id}]"] = d.data  # several rangefinders: chosen by orientation
        elif d.multi_id > 0 and d.name in topics:
            warnings.append(f"{path}: {d.name} has several instances; using instance 0")
    log = FlightLog(path=str(path), warnings=warnings, formats=["ulog"])

    fill_from_topics(log, data, mapping, path)
    link = log.clock_links[0] if log.clock_links else None
    to_clock = (lambda t: int(series_to_clock_scalar(t, link))) if link else (lambda t: int(t))
    for d in ulog.data_list:
        ts = d.data["timestamp"]
        name = d.name if d.multi_id == 0 else f"{d.name}[{d.multi_id}]"
        first = to_clock(int(ts[0]) * 1000) if len(ts) else None
        last = to_clock(int(ts[-1]) * 1000) if len(ts) else None
        log.streams.append(StreamInfo(name, d.name, len(ts), first, last,
                                      (SUPPLIES[d.name],) if d.name in SUPPLIES else ()))
    log.streams.sort(key=lambda s: (-s.count, s.name))
    return log


def _streams_span_s(ulog) -> float:
    """Seconds from the first to the last timestamp of the topics read with two or more messages (0 without).
    Not pyulog's last_timestamp - start_timestamp: that is the largest timestamp of any message, and a topic
    logged once carries the time of its last publication, or another clock's (a PX4 sample log's `mission` at
    1194 s in a 6.5 s log)."""
    streams = [d.data["timestamp"] for d in ulog.data_list if len(d.data["timestamp"]) >= 2]
    if not streams:
        return 0.0
    return (max(int(t.max()) for t in streams) - min(int(t.min()) for t in streams)) / 1e6


def series_to_clock_scalar(t_ns: int, link: ClockLink) -> int:
    from pipeline.ingest.clocks import map_clock
    return int(map_clock(np.array([t_ns], np.int64), link)[0])


def _laser_instance(name: str, data: dict[str, dict], rng: dict, warnings: list[str], path: Path) -> dict | None:
    """Samples of the laser among the instances of a distance_sensor topic (`name`, `name[1]`, ...), chosen by
    pipeline.ingest.rangefinder (orientation, then `ulog.range.instance`). None if there is none."""
    keys = sorted((k for k in data if k == name or (k.startswith(name + "[") and k.endswith("]"))), key=len)
    if not keys:
        return None
    fields = set.intersection(*(set(data[k]) for k in keys))
    a = {f: np.concatenate([np.asarray(data[k][f]) for k in keys]) for f in fields}
    a["instance"] = np.concatenate([np.full(len(data[k]["timestamp"]), 0 if k == name else int(k[len(name) + 1:-1]))
                                    for k in keys])
    if "orientation" in a:
        a["orient"] = a["orientation"]
    a = laser_facing(a, rng["orientations"], name, "ulog", warnings, path)
    a = one_instance(a, rng["instance"], name, "ulog", warnings, path)
    return a if a["instance"].size else None


def fill_from_topics(log: FlightLog, data: dict[str, dict], mapping: dict, path: Path) -> None:
    """Fill `log` from topic name -> {field: numpy column} (pyulog's `ULog.Data.data` of instance 0), and put
    the series on the UNIX clock when GPS UTC time links it to boot time."""
    warnings = log.warnings
    src = Path(path).name
    for name in mapping["clock"]["topics"]:
        d = data.get(name)
        if d is not None and "time_utc_usec" in d:
            ok = d["time_utc_usec"] > 0
            if ok.sum() >= 1:
                log.clock_links.append(ClockLink("boot", "unix", d["timestamp"][ok].astype(np.int64) * 1000,
                                                 d["time_utc_usec"][ok].astype(np.int64) * 1000))
                break

    for name in mapping["position"]["topics"]:
        d = data.get(name)
        if d is None:
            continue
        t, lat, lon, alt, datum = _position(name, d, mapping["position"])
        if t.size == 0:
            warnings.append(f"{path}: no GPS fix in {len(d['timestamp'])} {name} messages")
            continue
        if t.size < len(d["timestamp"]):  # a user seeing fewer positions than messages should know why
            why = (f"no fix (fix_type below {mapping['position']['min_fix_type']}, mapping.ulog.position."
                   "min_fix_type) or no coordinates" if "fix_type" in d else "no coordinates (NaN or 0, 0)")
            warnings.append(f"{path}: {len(d['timestamp']) - t.size} of {len(d['timestamp'])} {name} messages "
                            f"dropped: {why}")
        t, lat, lon, alt = sort_by_time(t, lat, lon, alt)
        log.position = PositionSeries(t, lat, lon, alt, datum, source=f"{src}:{name}", clock="boot")
        break
    for name in mapping["attitude"]["topics"]:
        if name in data:
            d = data[name]
            t, q = sort_by_time(d["timestamp"].astype(np.int64) * 1000, _quat(d))
            log.attitude = AttitudeSeries(t, q, source=f"{src}:{name}", clock="boot")
            break
    for name in mapping["gimbal"]["topics"]:
        if name in data:
            d = data[name]
            flags = d.get("device_flags", d.get("flags", np.zeros(len(d["timestamp"]), int))).astype(int)
            veh = np.where(flags & GIMBAL_FLAG_YAW_IN_VEHICLE, True,
                           np.where(flags & GIMBAL_FLAG_YAW_IN_EARTH, False, (flags & GIMBAL_FLAG_YAW_LOCK) == 0))
            t, q, veh = sort_by_time(d["timestamp"].astype(np.int64) * 1000, _quat(d), veh.astype(bool))
            log.gimbal = GimbalSeries(t, q, veh, source=f"{src}:{name}", clock="boot")
            break
    for name in mapping["range"]["topics"]:
        d = _laser_instance(name, data, mapping["range"], warnings, path)
        if d is not None:
            r = d["current_distance"].astype(float)
            lo = np.maximum(d["min_distance"].astype(float), float(mapping["range"]["min_m"]))
            hi = np.minimum(d["max_distance"].astype(float), float(mapping["range"]["max_m"]))
            valid = np.isfinite(r) & (r >= lo) & (r <= hi)
            if "signal_quality" in d:
                valid &= d["signal_quality"] != 0  # 0: invalid signal, -1: unknown
            t, r, valid = sort_by_time(d["timestamp"].astype(np.int64) * 1000, r, valid)
            log.range = RangeSeries(t, r, valid, source=f"{src}:{name}", clock="boot")
            break
    for name in mapping["camera"]["topics"]:
        if name in data:
            d = data[name]
            idx = d.get("seq", np.full(len(d["timestamp"]), -1)).astype(np.int64)
            t, idx = sort_by_time(d["timestamp"].astype(np.int64) * 1000, idx)
            log.camera_events = CameraEventSeries(t, idx, source=f"{src}:{name}", clock="boot")
            break

    if log.clock_links:
        for q in ("position", "attitude", "gimbal", "range", "camera_events"):
            setattr(log, q, series_to_clock(getattr(log, q), log.clock_links, "unix"))
    elif any(getattr(log, q) is not None for q in ("position", "attitude", "gimbal", "range")):
        warnings.append(f"{path}: no GPS UTC time in the log; series stay on the boot clock")
