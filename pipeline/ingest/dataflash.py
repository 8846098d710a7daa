"""ArduPilot DataFlash logs through pymavlink's DFReader: binary (.bin) and text (.log, Mission Planner's
conversion and old firmware's own text dumps: `NAME, v1, v2, ...` lines after `FMT, ...` lines).

DFReader indexes every record by type on open (no decoding) and `recv_match(type=...)` then jumps to and
decodes only the requested types; field names and scaling come from the log's FMT/FMTU records. Record times
come from each record's own boot-time field (TimeUS; old firmware: TimeMS, or GPS `T`); GPS week/ms pairs give
the boot -> UNIX link (GPS - UTC = `leap_seconds`), and every series is put on the UNIX clock when it exists.
Old logs whose records carry no time (ArduCopter <= 3.0: only GPS has its time of week) are timed by
interpolating, by file position, between the records that carry one; without a GPS week they stay on GPS time
of week (clock "unknown") unless `dataflash.gps_week` gives the week. pymavlink's own clock guess is not used
(it crashes on GPS records without a week).
"""

from __future__ import annotations

import contextlib
import io
import re
from pathlib import Path

import numpy as np

from pipeline.errors import ConfigError, LogReadError
from pipeline.ingest.clocks import map_clock, series_to_clock, unix_ns_from_gps
from pipeline.ingest.columns import Columns, one_source, sort_by_time
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
from pipeline.ingest.rangefinder import laser_facing, one_instance

SUPPLIES = {"GPS": ("position", "clock"), "POS": ("position",), "ATT": ("attitude",), "MNT": ("gimbal", "range"),
            "RFND": ("range",), "CAM": ("camera_events",), "TRIG": ("camera_events",)}


TIME_FIELDS = (("TimeUS", 1000), ("T", 10**6), ("TimeMS", 10**6))  # boot time of a record, by preference


def _field(columns: list[str], names: list[str]) -> str | None:
    return next((n for n in names if n in columns), None)


def _no_clock_guess(self) -> None:
    """Replaces DFReader.init_clock: records are timed from their own fields here, and pymavlink's guess raises
    TypeError on old GPS records without a week."""
    from pymavlink import DFReader

    self.clock = DFReader.DFReaderClock_usec()


def _open_reader(path: Path, text: bool):
    from pymavlink import DFReader

    base = DFReader.DFReader_text if text else DFReader.DFReader_binary
    cls = type("_Reader", (base,), {"init_clock": _no_clock_guess})
    return cls(str(path), zero_time_base=True)


def is_text_dataflash(head: bytes) -> bool:
    """True when the first bytes of a file look like a text DataFlash log (an `FMT,` line near the start)."""
    return head.startswith(b"FMT,") or re.search(rb"(^|\n)FMT, ?\d+, ?\d+, ?\w+,", head) is not None


def _types(df) -> list[tuple[object, object, int]]:
    """(index key, DFFormat, record count) of every record type present: the binary reader keys its counts
    and offsets by type id (lists), the text reader by name (dicts)."""
    if isinstance(df.counts, dict):
        return [(n, df.formats[n], c) for n, c in df.counts.items() if c > 0 and n in df.formats]
    return [(i, f, df.counts[i]) for i, f in df.formats.items() if df.counts[i] > 0]


def _time_field(columns: list[str], tow_field: str | None) -> tuple[str, int] | None:
    """(field, ns per unit) of a record's boot time, or None; the GPS time-of-week field is not a boot time."""
    return next(((f, k) for f, k in TIME_FIELDS if f in columns and f != tow_field), None)


def read_dataflash(path: str | Path, mapping: dict, scan_all: bool = False) -> FlightLog:
    """Read an ArduPilot DataFlash log, binary or text, into a FlightLog (mappings/dataflash.yaml)."""
    path = Path(path)
    size = path.stat().st_size
    if size == 0:
        raise LogReadError("empty file", path=path)
    with open(path, "rb") as f:
        head = f.read(4096)
    text = not head.startswith(b"\xa3\x95") and is_text_dataflash(head)
    noise = io.StringIO()
    try:
        with contextlib.redirect_stdout(noise), contextlib.redirect_stderr(noise):
            df = _open_reader(path, text)
    except Exception as exc:  # DFReader raises assorted errors on garbage
        msg = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise LogReadError(f"not a readable DataFlash log: {msg}", path=path) from None
    warnings: list[str] = []
    try:
        types = _types(df)
        fmts = {f.name: f for _, f, _ in types}
        counts = {f.name: n for _, f, n in types}
        n_total = sum(counts.values())
        if n_total == 0 or set(counts) <= {"FMT", "FMTU", "UNIT", "MULT"}:
            raise LogReadError("no data records (not a DataFlash log, or only format records)", path=path)
        if text:  # a line cut by the end of the file is skipped by DFReader
            with open(path, "rb") as f:
                f.seek(max(0, size - 1))
                overrun = int(f.read(1) not in (b"\n", b"\r"))
        else:  # a record cut by the end of the file is indexed but cannot be decoded
            overrun = max(df.offsets[k][-1] + f.len for k, f, _ in types) - df.data_len
        cfg = {q: mapping[q] for q in ("position", "attitude", "gimbal", "range", "clock")}
        msgs = {c["message"] for c in cfg.values()} | set(mapping["camera"]["messages"])
        unknown = [m for m in msgs if m not in SUPPLIES]
        if unknown:
            raise ConfigError(f"dataflash mapping: message(s) {', '.join(unknown)} cannot supply a quantity "
                              f"(known: {', '.join(SUPPLIES)})")
        wanted = {m for m in msgs if m in counts}
        cols: dict[str, Columns] = {}
        fields: dict[str, dict] = {}
        tfield: dict[str, tuple[str, int] | None] = {}
        tow = mapping["clock"]["fields"]["ms"]
        for m in wanted:
            fields[m] = {}
            for c in cfg.values():
                if c["message"] == m:
                    for key, names in c["fields"].items():
                        f = _field(fmts[m].columns, names)
                        if f is not None:
                            fields[m][key] = f
            tfield[m] = _time_field(fmts[m].columns, _field(fmts[m].columns, tow)
                                    if m == cfg["clock"]["message"] else None)
            if m in mapping["camera"]["messages"]:
                fields[m]["idx"] = _field(fmts[m].columns, ["Img", "ImgNum", "I"]) or ""
            cols[m] = Columns(t="q", pos="q", **{k: "d" for k, v in fields[m].items() if v})
        n_read = n_bad = 0
        if text:
            for m in cols:
                _text_records(df, m, fmts[m].columns, fields[m], tfield[m], cols[m])
        with contextlib.redirect_stdout(noise), contextlib.redirect_stderr(noise):
            df.rewind()
            todo = set() if text else set(cols)
            while todo:
                try:
                    msg = df.recv_match(type=todo, strict=True)  # strict: no MODE/MSG/PARM extras
                except Exception as exc:
                    warnings.append(f"{path}: reading stopped after {n_read} records: {exc}")
                    break
                if msg is None:
                    break
                n_read += 1
                name = msg.get_type()
                if name not in cols:
                    continue
                try:
                    row = {k: float(getattr(msg, f)) for k, f in fields[name].items() if f}
                    tf = tfield[name]
                    t_ns = int(getattr(msg, tf[0])) * tf[1] if tf else -1  # -1: untimed, timed below
                except (TypeError, ValueError, AttributeError):
                    t_ns = None
                if t_ns is None or not -1 <= t_ns < 2**63:  # a damaged record: a time or value that cannot be one
                    n_bad += 1
                    continue
                cols[name].add(t=t_ns, pos=df.offset, **row)
        if n_bad:
            warnings.append(f"{path}: skipped {n_bad} of {n_read} records with an impossible time or value "
                            "(damaged)")
        arrays = {m: c.arrays() for m, c in cols.items()}
        streams = _streams(df, types, scan_all)
    finally:
        df.close() if hasattr(df, "close") else None
    clock = _time_untimed(arrays, tfield, cfg["clock"]["message"], mapping, warnings, path)
    if overrun > 0:
        t_all = [a["t"] for a in arrays.values() if a["t"].size]
        span = (max(t.max() for t in t_all) - min(t.min() for t in t_all)) / 1e9 if t_all else 0.0
        warnings.append(f"{path}: file ends mid-record (truncated); read {n_total - 1} records, the selected "
                        f"ones covering {span:.1f} s")
    log = FlightLog(path=str(path), streams=streams, warnings=warnings, formats=["dataflash"])
    _assemble(log, arrays, mapping, path, clock)
    return log


def _text_records(df, name: str, columns: list[str], fields: dict[str, str], tfield, out: Columns) -> None:
    """Decode the text lines of one record type straight into `out`, from the line offsets DFReader_text indexed:
    text values are already scaled, so each wanted field is one float() of its column (DFReader would build a
    message object per line; this is ~20x faster). Lines with too few columns or non-numbers are skipped, as
    DFReader skips them."""
    mm, delim = df.data_map, df.delimiter.encode()
    col = {c: i + 1 for i, c in enumerate(columns)}
    keys = [(k, col[f]) for k, f in fields.items() if f]
    t_col, t_mul = (col[tfield[0]], tfield[1]) if tfield else (None, 0)
    need = len(columns) + 1
    add = out.add
    size = len(mm)
    for off in df.offsets[name]:
        end = mm.find(b"\n", off)
        end = size if end < 0 else end
        parts = mm[off:end].rstrip().split(delim)
        if len(parts) < need:
            continue
        try:
            row = {k: float(parts[i]) for k, i in keys}
            t = int(float(parts[t_col])) * t_mul if t_col else -1
        except ValueError:
            continue
        add(t=t, pos=end + 1, **row)


def _time_untimed(arrays: dict[str, dict], tfield: dict, clock_msg: str, mapping: dict, warnings: list[str],
                  path: Path) -> str:
    """Give records without their own boot time (old firmware) a time by linear interpolation over file
    position between the records that have one; when none has (ArduCopter <= 3.0), between the GPS records'
    time of week (UNIX when the week is logged or `gps_week` is set). Records outside the timed span are
    dropped. Returns the clock of every series: "boot", "unix" or "unknown" (GPS time of week)."""
    untimed = [m for m, a in arrays.items() if tfield[m] is None and a["t"].size]
    if not untimed:
        return "boot"
    clock = "boot"
    timed = [a for m, a in arrays.items() if tfield[m] is not None and a["t"].size]
    if timed:
        anchor_pos = np.concatenate([a["pos"] for a in timed])
        anchor_t = np.concatenate([a["t"] for a in timed])
    else:
        g = arrays.get(clock_msg)
        if g is None or "ms" not in g or not g["ms"].size:
            for m in untimed:
                warnings.append(f"{path}: {m} records carry no time and the log has no GPS time; not read")
                arrays[m] = {k: v[:0] for k, v in arrays[m].items()}
            return clock
        week = g["week"] if "week" in g else np.full(g["ms"].size, float(mapping["gps_week"] or 0))
        ok = g["ms"] > 0
        anchor_pos = g["pos"][ok]
        if (week[ok] > 0).all() and ok.any():
            anchor_t = unix_ns_from_gps(week[ok], g["ms"][ok], int(mapping["leap_seconds"]))
            clock = "unix"
        else:
            anchor_t = (g["ms"][ok] * 10**6).astype(np.int64)
            clock = "unknown"
            warnings.append(f"{path}: no GPS week in the log; times are GPS time of week (set dataflash.gps_week "
                            "to put them on UNIX time)")
        untimed = [m for m, a in arrays.items() if a["t"].size]
    if anchor_pos.size == 0:
        return clock
    order = np.argsort(anchor_pos, kind="stable")
    anchor_pos, anchor_t = anchor_pos[order], anchor_t[order]
    for m in untimed:
        a = arrays[m]
        inside = (a["pos"] >= anchor_pos[0]) & (a["pos"] <= anchor_pos[-1])
        a = {k: v[inside] for k, v in a.items()}
        a["t"] = np.round(np.interp(a["pos"], anchor_pos, anchor_t.astype(float))).astype(np.int64) \
            if anchor_t.size > 1 else np.full(a["pos"].size, anchor_t[0], np.int64)
        arrays[m] = a
    warnings.append(f"{path}: {', '.join(sorted(untimed))} records carry no time of their own (old firmware); "
                    "timed by interpolation between timed records")
    return clock


def _one_instance(a: dict | None, cfg: dict, quantity: str, warnings: list[str], path: Path) -> dict | None:
    """The records of one sensor instance (GPS, MNT, RFND carry an instance field `I`/`Instance` on firmware
    with several): `cfg["instance"]`, or the lowest one logged, with a warning when there are several."""
    def warn(ids: np.ndarray, want: int) -> None:
        warnings.append(f"{path}: {cfg['message']} records of instances {ids.astype(int).tolist()}; {quantity} from "
                        f"instance {want} (set dataflash.{quantity}.instance to choose)")

    return None if a is None else one_source(a, "instance", cfg.get("instance"), on_several=warn)


def _streams(df, types: list, scan_all: bool) -> list[StreamInfo]:
    """One StreamInfo per record type; first/last times (boot) by decoding the first and last record."""
    streams = []
    for key, fmt, n in types:
        t0 = t1 = None
        tf = _time_field(fmt.columns, None)
        if scan_all and tf is not None and not (fmt.name.startswith("GPS") and tf[0] == "TimeMS"):
            try:
                df.offset = df.offsets[key][0]
                m0 = df._parse_next()
                df.offset = df.offsets[key][-1]
                m1 = df._parse_next()
                t0, t1 = int(getattr(m0, tf[0])) * tf[1], int(getattr(m1, tf[0])) * tf[1]
                if not (0 <= t0 < 2**63 and 0 <= t1 < 2**63):  # a damaged record's time
                    t0 = t1 = None
            except Exception:
                t0 = t1 = None
        streams.append(StreamInfo(fmt.name, fmt.name, int(n), t0, t1, SUPPLIES.get(fmt.name, ())))
    streams.sort(key=lambda s: (-s.count, s.name))
    return streams


def _assemble(log: FlightLog, arrays: dict[str, dict], mapping: dict, path: Path, clock: str = "boot") -> None:
    src = path.name
    warnings = log.warnings
    c = mapping["clock"]
    a = arrays.get(c["message"])
    if clock == "boot" and a is not None and "week" in a and "ms" in a:
        ok = (a["week"] > 0) & (a["week"] < 5200) & (a["ms"] >= 0) & (a["ms"] < 604_800_000)  # 1980..2079
        if ok.any():
            unix = unix_ns_from_gps(a["week"][ok], a["ms"][ok], int(mapping["leap_seconds"]))
            log.clock_links.append(ClockLink("boot", "unix", a["t"][ok], unix))

    c = mapping["position"]
    a = _one_instance(arrays.get(c["message"]), c, "position", warnings, path)
    if a is not None and {"lat_deg", "lon_deg", "alt_m"} <= set(a):
        ok = np.isfinite(a["lat_deg"]) & ~((a["lat_deg"] == 0) & (a["lon_deg"] == 0))
        if "status" in a:
            ok &= a["status"] >= c["min_status"]
        if ok.any():
            t, lat, lon, alt = sort_by_time(a["t"][ok], a["lat_deg"][ok], a["lon_deg"][ok], a["alt_m"][ok])
            log.position = PositionSeries(t, lat, lon, alt, "amsl", source=f"{src}:{c['message']}", clock=clock)
        else:
            warnings.append(f"{path}: no GPS fix in {a['t'].size} {c['message']} records; no position read")

    c = mapping["attitude"]
    a = arrays.get(c["message"])
    if a is not None and {"roll_deg", "pitch_deg", "yaw_deg"} <= set(a) and a["t"].size:
        q = quat_ned_from_frd_euler(np.radians(a["roll_deg"]), np.radians(a["pitch_deg"]), np.radians(a["yaw_deg"]))
        t, q = sort_by_time(a["t"], q)
        log.attitude = AttitudeSeries(t, q, source=f"{src}:{c['message']}", clock=clock)

    c = mapping["gimbal"]
    a = _one_instance(arrays.get(c["message"]), c, "gimbal", warnings, path)
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
            log.gimbal = GimbalSeries(t, q, veh, source=f"{src}:{c['message']}", clock=clock)

    c = mapping["range"]
    a = arrays.get(c["message"])
    if a is not None and "range_m" in a and a["t"].size:
        a = laser_facing(a, c["orientations"], c["message"], "dataflash", warnings, path)
        a = one_instance(a, c["instance"], c["message"], "dataflash", warnings, path)
    if a is not None and "range_m" in a and a["t"].size:
        r = a["range_m"]
        valid = np.isfinite(r) & (r > float(c["min_m"])) & (r <= float(c["max_m"]))
        if "status" in a:
            valid &= a["status"] == c["good_status"]
        t, r, valid = sort_by_time(a["t"], r, valid)
        log.range = RangeSeries(t, r, valid, source=f"{src}:{c['message']}", clock=clock)

    for m in mapping["camera"]["messages"]:
        a = arrays.get(m)
        if a is not None and a["t"].size:
            idx = a["idx"].astype(np.int64) if "idx" in a else np.full(a["t"].size, -1, np.int64)
            t, idx = sort_by_time(a["t"], idx)
            log.camera_events = CameraEventSeries(t, idx, source=f"{src}:{m}", clock=clock)
            break

    if log.clock_links:
        link = log.clock_links[0]
        for q in ("position", "attitude", "gimbal", "range", "camera_events"):
            setattr(log, q, series_to_clock(getattr(log, q), log.clock_links, "unix"))
        log.streams = [StreamInfo(s.name, s.msg_type, s.count,
                                  None if s.t_first_ns is None else int(map_clock(np.array([s.t_first_ns]), link)[0]),
                                  None if s.t_last_ns is None else int(map_clock(np.array([s.t_last_ns]), link)[0]),
                                  s.supplies) for s in log.streams]
    elif clock == "boot" and any(getattr(log, q) is not None for q in ("position", "attitude", "gimbal", "range")):
        warnings.append(f"{path}: no GPS week/time in the log; series stay on the boot clock")
