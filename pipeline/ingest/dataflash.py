"""ArduPilot DataFlash binary logs (.bin) through pymavlink's DFReader.

DFReader indexes every record by type on open (no decoding) and `recv_match(type=...)` then jumps to and
decodes only the requested types; field names and scaling come from the log's FMT/FMTU records. TimeUS is boot
time; GPS week/ms pairs give the boot -> UNIX link (GPS - UTC = `leap_seconds`), and every series is put on the
UNIX clock when it exists.
"""

from __future__ import annotations

import contextlib
import io
from pathlib import Path

import numpy as np

from pipeline.errors import ConfigError, LogReadError
from pipeline.ingest.clocks import map_clock, series_to_clock, unix_ns_from_gps
from pipeline.ingest.columns import Columns, sort_by_time
from pipeline.ingest.frames import quat_ned_from_frd_euler
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

SUPPLIES = {"GPS": ("position", "clock"), "POS": ("position",), "ATT": ("attitude",), "MNT": ("gimbal", "range"),
            "RFND": ("range",), "CAM": ("camera_events",), "TRIG": ("camera_events",)}


def _field(columns: list[str], names: list[str]) -> str | None:
    return next((n for n in names if n in columns), None)


def read_dataflash(path: str | Path, mapping: dict, scan_all: bool = False) -> FlightLog:
    """Read an ArduPilot .bin into a FlightLog (mappings/dataflash.yaml)."""
    from pymavlink import DFReader

    path = Path(path)
    if path.stat().st_size == 0:
        raise LogReadError("empty file", path=path)
    noise = io.StringIO()
    try:
        with contextlib.redirect_stdout(noise), contextlib.redirect_stderr(noise):
            df = DFReader.DFReader_binary(str(path), zero_time_base=True)
    except Exception as exc:  # DFReader raises assorted errors on garbage
        text = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise LogReadError(f"not a readable DataFlash log: {text}", path=path) from None
    warnings: list[str] = []
    try:
        fmts = {df.formats[i].name: df.formats[i] for i in df.formats}
        counts = {df.formats[i].name: df.counts[i] for i in df.formats if df.counts[i] > 0}
        n_total = sum(counts.values())
        if n_total == 0 or set(counts) <= {"FMT", "FMTU", "UNIT", "MULT"}:
            raise LogReadError("no data records (not a DataFlash log, or only format records)", path=path)
        # a record cut by the end of the file is indexed but cannot be decoded
        overrun = max(df.offsets[i][-1] + df.formats[i].len for i in df.formats if df.counts[i] > 0) - df.data_len
        cfg = {q: mapping[q] for q in ("position", "attitude", "gimbal", "range", "clock")}
        msgs = {c["message"] for c in cfg.values()} | set(mapping["camera"]["messages"])
        unknown = [m for m in msgs if m not in SUPPLIES]
        if unknown:
            raise ConfigError(f"dataflash mapping: message(s) {', '.join(unknown)} cannot supply a quantity "
                              f"(known: {', '.join(SUPPLIES)})")
        wanted = {m for m in msgs if m in counts}
        cols: dict[str, Columns] = {}
        fields: dict[str, dict] = {}
        for m in wanted:
            fields[m] = {}
            for c in cfg.values():
                if c["message"] == m:
                    for key, names in c["fields"].items():
                        f = _field(fmts[m].columns, names)
                        if f is not None:
                            fields[m][key] = f
            if "TimeUS" not in fmts[m].columns:
                warnings.append(f"{path}: {m} has no TimeUS field (firmware too old); not read")
                continue
            if m in mapping["camera"]["messages"]:
                fields[m]["idx"] = _field(fmts[m].columns, ["Img", "ImgNum", "I"]) or ""
            cols[m] = Columns(t="q", **{k: "d" for k, v in fields[m].items() if v})
        n_read = 0
        with contextlib.redirect_stdout(noise), contextlib.redirect_stderr(noise):
            df.rewind()
            types = set(cols)
            while types:
                try:
                    msg = df.recv_match(type=types)
                except Exception as exc:
                    warnings.append(f"{path}: reading stopped after {n_read} records: {exc}")
                    break
                if msg is None:
                    break
                n_read += 1
                name = msg.get_type()
                if name not in cols:
                    continue
                row = {k: getattr(msg, f) for k, f in fields[name].items() if f}
                cols[name].add(t=int(msg.TimeUS) * 1000, **row)
        arrays = {m: c.arrays() for m, c in cols.items()}
        streams = _streams(df, counts, scan_all)
    finally:
        df.close() if hasattr(df, "close") else None
    if overrun > 0:
        t_all = [a["t"] for a in arrays.values() if a["t"].size]
        span = (max(t.max() for t in t_all) - min(t.min() for t in t_all)) / 1e9 if t_all else 0.0
        warnings.append(f"{path}: file ends mid-record (truncated); read {n_total - 1} records, the selected "
                        f"ones covering {span:.1f} s")
    log = FlightLog(path=str(path), streams=streams, warnings=warnings, formats=["dataflash"])
    _assemble(log, arrays, mapping, path)
    return log


def _streams(df, counts: dict[str, int], scan_all: bool) -> list[StreamInfo]:
    """One StreamInfo per record type; first/last times (boot) by decoding the first and last record."""
    streams = []
    for i, fmt in df.formats.items():
        n = df.counts[i]
        if n == 0:
            continue
        t0 = t1 = None
        if scan_all and "TimeUS" in fmt.columns:
            try:
                df.offset = df.offsets[i][0]
                m0 = df._parse_next()
                df.offset = df.offsets[i][-1]
                m1 = df._parse_next()
                t0, t1 = int(m0.TimeUS) * 1000, int(m1.TimeUS) * 1000
            except Exception:
                t0 = t1 = None
        streams.append(StreamInfo(fmt.name, fmt.name, int(n), t0, t1, SUPPLIES.get(fmt.name, ())))
    streams.sort(key=lambda s: (-s.count, s.name))
    return streams


def _assemble(log: FlightLog, arrays: dict[str, dict], mapping: dict, path: Path) -> None:
    src = path.name
    warnings = log.warnings
    c = mapping["clock"]
    a = arrays.get(c["message"])
    if a is not None and "week" in a and "ms" in a:
        ok = a["week"] > 0
        if ok.any():
            unix = unix_ns_from_gps(a["week"][ok], a["ms"][ok], int(mapping["leap_seconds"]))
            log.clock_links.append(ClockLink("boot", "unix", a["t"][ok], unix))

    c = mapping["position"]
    a = arrays.get(c["message"])
    if a is not None and {"lat_deg", "lon_deg", "alt_m"} <= set(a):
        ok = np.isfinite(a["lat_deg"]) & ~((a["lat_deg"] == 0) & (a["lon_deg"] == 0))
        if "status" in a:
            ok &= a["status"] >= c["min_status"]
        if ok.any():
            t, lat, lon, alt = sort_by_time(a["t"][ok], a["lat_deg"][ok], a["lon_deg"][ok], a["alt_m"][ok])
            log.position = PositionSeries(t, lat, lon, alt, "amsl", source=f"{src}:{c['message']}", clock="boot")
        else:
            warnings.append(f"{path}: no GPS fix in {a['t'].size} {c['message']} records; no position read")

    c = mapping["attitude"]
    a = arrays.get(c["message"])
    if a is not None and {"roll_deg", "pitch_deg", "yaw_deg"} <= set(a) and a["t"].size:
        q = quat_ned_from_frd_euler(np.radians(a["roll_deg"]), np.radians(a["pitch_deg"]), np.radians(a["yaw_deg"]))
        t, q = sort_by_time(a["t"], q)
        log.attitude = AttitudeSeries(t, q, source=f"{src}:{c['message']}", clock="boot")

    c = mapping["gimbal"]
    a = arrays.get(c["message"])
    if a is not None and {"roll_deg", "pitch_deg"} <= set(a) and a["t"].size:
        if "yaw_earth_deg" in a:
            yaw, veh = a["yaw_earth_deg"], np.zeros(a["t"].size, bool)
        elif "yaw_vehicle_deg" in a:
            yaw, veh = a["yaw_vehicle_deg"], np.ones(a["t"].size, bool)
        else:
            yaw = None
        if yaw is not None:
            q = quat_ned_from_frd_euler(np.radians(a["roll_deg"]), np.radians(a["pitch_deg"]), np.radians(yaw))
            t, q, veh = sort_by_time(a["t"], q, veh)
            log.gimbal = GimbalSeries(t, q, veh, source=f"{src}:{c['message']}", clock="boot")

    c = mapping["range"]
    a = arrays.get(c["message"])
    if a is not None and "range_m" in a and a["t"].size:
        r = a["range_m"]
        valid = np.isfinite(r) & (r > float(c["min_m"])) & (r <= float(c["max_m"]))
        if "status" in a:
            valid &= a["status"] == c["good_status"]
        t, r, valid = sort_by_time(a["t"], r, valid)
        log.range = RangeSeries(t, r, valid, source=f"{src}:{c['message']}", clock="boot")

    for m in mapping["camera"]["messages"]:
        a = arrays.get(m)
        if a is not None and a["t"].size:
            idx = a["idx"].astype(np.int64) if "idx" in a else np.full(a["t"].size, -1, np.int64)
            t, idx = sort_by_time(a["t"], idx)
            log.camera_events = CameraEventSeries(t, idx, source=f"{src}:{m}", clock="boot")
            break

    if log.clock_links:
        link = log.clock_links[0]
        for q in ("position", "attitude", "gimbal", "range", "camera_events"):
            setattr(log, q, series_to_clock(getattr(log, q), log.clock_links, "unix"))
        log.streams = [StreamInfo(s.name, s.msg_type, s.count,
                                  None if s.t_first_ns is None else int(map_clock(np.array([s.t_first_ns]), link)[0]),
                                  None if s.t_last_ns is None else int(map_clock(np.array([s.t_last_ns]), link)[0]),
                                  s.supplies) for s in log.streams]
    elif any(getattr(log, q) is not None for q in ("position", "attitude", "gimbal", "range")):
        warnings.append(f"{path}: no GPS week/time in the log; series stay on the boot clock")
