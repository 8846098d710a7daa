"""MAVLink telemetry logs (.tlog): records of an 8-byte big-endian UNIX time in microseconds (when the ground
station received the packet) followed by one MAVLink 1 or 2 packet.

The file is memory-mapped and walked record by record from the packet headers; only the messages a quantity
needs are decoded (pymavlink, CRC checked), every other record is only counted for `inspect`. Garbage bytes are
skipped by resynchronising on the next plausible record; a file cut mid-record keeps what was read, with a
warning.
"""

from __future__ import annotations

import mmap
from collections import Counter
from pathlib import Path

import numpy as np
from pymavlink.dialects.v20 import ardupilotmega as mavlink

from pipeline.errors import LogReadError
from pipeline.ingest.clocks import map_clock
from pipeline.ingest.columns import Columns, one_source, sort_by_time
from pipeline.ingest.frames import quat_ned_from_frd_euler, quat_wxyz_from_rotation, rotation_from_quat_wxyz
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

SUPPLIES = {
    "GLOBAL_POSITION_INT": "position", "GPS_RAW_INT": "position",
    "ATTITUDE": "attitude", "ATTITUDE_QUATERNION": "attitude",
    "GIMBAL_DEVICE_ATTITUDE_STATUS": "gimbal", "MOUNT_STATUS": "gimbal", "MOUNT_ORIENTATION": "gimbal",
    "CAMERA_TRACKING_GEO_STATUS": "range", "RANGEFINDER": "range", "DISTANCE_SENSOR": "range",
    "CAMERA_FEEDBACK": "camera_events", "CAMERA_IMAGE_CAPTURED": "camera_events",
    "SYSTEM_TIME": "clock",
}
_ID_BY_NAME = {cls.msgname: mid for mid, cls in mavlink.mavlink_map.items()}
_NAME_BY_ID = {mid: cls.msgname for mid, cls in mavlink.mavlink_map.items()}
_MAX_LEN = {mid: cls.unpacker.size for mid, cls in mavlink.mavlink_map.items()}
_V1_MAGIC, _V2_MAGIC = 0xFE, 0xFD
_PLAUSIBLE_US = (946684800 * 10**6, 4102444800 * 10**6)  # 2000 .. 2100
GIMBAL_FLAG_YAW_LOCK, GIMBAL_FLAG_YAW_IN_VEHICLE, GIMBAL_FLAG_YAW_IN_EARTH = 16, 32, 64
_RELEASE_BYTES = 8 << 20


def _record_length(mm, pos: int, size: int) -> tuple[int, int] | None:
    """(msgid, packet length) of a plausible record at pos, or None if the bytes there do not look like one."""
    if pos + 8 + 8 > size:
        return None
    magic, plen = mm[pos + 8], mm[pos + 9]
    if magic == _V2_MAGIC:
        if pos + 18 > size:  # a v2 header cut by the end of the file
            return None
        msgid = mm[pos + 15] | (mm[pos + 16] << 8) | (mm[pos + 17] << 16)
        if mm[pos + 10] & ~0x01:
            return None
        length = 10 + plen + 2 + (13 if mm[pos + 10] & 0x01 else 0)
        ok = msgid in _MAX_LEN and plen <= _MAX_LEN[msgid]
    elif magic == _V1_MAGIC:
        msgid = mm[pos + 13]
        length = 6 + plen + 2
        ok = msgid in _MAX_LEN and plen <= _MAX_LEN[msgid]  # v1 packets omit extension fields
    else:
        return None
    return (msgid, length) if ok else None


def _resync(mm, pos: int, size: int, last_us: int | None) -> int:
    """Next position >= pos holding a plausible record (timestamp near the last good one), or size. Candidates
    are found with mmap.find on the two magic bytes, so long runs of garbage are skipped at C speed."""
    lo, hi = (_PLAUSIBLE_US if last_us is None else (last_us - 3600 * 10**6, last_us + 86400 * 10**6))
    while pos + 16 <= size:
        found = [i for i in (mm.find(b"\xfd", pos + 8), mm.find(b"\xfe", pos + 8)) if i >= 0]
        if not found:
            return size
        pos = min(found) - 8
        if _record_length(mm, pos, size) is not None and lo <= int.from_bytes(mm[pos:pos + 8], "big") <= hi:
            return pos
        pos += 1
    return size


class _Collector:
    """Decoded samples per message type of interest (columns keep the sender's system id)."""

    def __init__(self, mapping: dict):
        self.mapping = mapping
        self.cols: dict[str, Columns] = {}
        self.events: dict[str, Columns] = {}

    def add(self, name: str, msg, rec_ns: int, sysid: int, compid: int) -> None:
        fn = getattr(self, "_" + name.lower(), None)
        if fn is not None:
            fn(msg, rec_ns, sysid, compid)

    def _c(self, name: str, **typecodes) -> Columns:
        if name not in self.cols:
            dev = {"dev": "q"} if SUPPLIES[name] in ("gimbal", "range") else {}  # sender device, for _one_device
            self.cols[name] = Columns(rec_ns="q", boot_ns="q", sys="q", **dev, **typecodes)
        return self.cols[name]

    def _global_position_int(self, m, rec, sysid, compid):
        if m.lat == 0 and m.lon == 0:
            return  # no fix yet
        self._c("GLOBAL_POSITION_INT", lat="d", lon="d", alt="d").add(
            rec_ns=rec, boot_ns=m.time_boot_ms * 10**6, sys=sysid, lat=m.lat * 1e-7, lon=m.lon * 1e-7,
            alt=m.alt * 1e-3)

    def _gps_raw_int(self, m, rec, sysid, compid):
        if m.fix_type < 3:
            return
        self._c("GPS_RAW_INT", lat="d", lon="d", alt="d", alt_ell="d").add(
            rec_ns=rec, boot_ns=-1, sys=sysid, lat=m.lat * 1e-7, lon=m.lon * 1e-7, alt=m.alt * 1e-3,
            alt_ell=m.alt_ellipsoid * 1e-3)

    def _attitude(self, m, rec, sysid, compid):
        self._c("ATTITUDE", roll="d", pitch="d", yaw="d").add(
            rec_ns=rec, boot_ns=m.time_boot_ms * 10**6, sys=sysid, roll=m.roll, pitch=m.pitch, yaw=m.yaw)

    def _attitude_quaternion(self, m, rec, sysid, compid):
        self._c("ATTITUDE_QUATERNION", w="d", x="d", y="d", z="d").add(
            rec_ns=rec, boot_ns=m.time_boot_ms * 10**6, sys=sysid, w=m.q1, x=m.q2, y=m.q3, z=m.q4)

    def _gimbal_device_attitude_status(self, m, rec, sysid, compid):
        q = m.q
        flags = m.flags
        if flags & GIMBAL_FLAG_YAW_IN_VEHICLE:
            veh = True
        elif flags & GIMBAL_FLAG_YAW_IN_EARTH:
            veh = False
        else:
            veh = not flags & GIMBAL_FLAG_YAW_LOCK
        self._c("GIMBAL_DEVICE_ATTITUDE_STATUS", w="d", x="d", y="d", z="d", veh="b").add(
            rec_ns=rec, boot_ns=m.time_boot_ms * 10**6, sys=sysid, dev=compid, w=q[0], x=q[1], y=q[2], z=q[3], veh=veh)

    def _mount_status(self, m, rec, sysid, compid):
        self._c("MOUNT_STATUS", roll="d", pitch="d", yaw="d").add(
            rec_ns=rec, boot_ns=-1, sys=sysid, dev=compid, roll=m.pointing_b * 0.01, pitch=m.pointing_a * 0.01,
            yaw=m.pointing_c * 0.01)

    def _mount_orientation(self, m, rec, sysid, compid):
        earth = np.isfinite(m.yaw_absolute) and m.yaw_absolute != 0.0
        self._c("MOUNT_ORIENTATION", roll="d", pitch="d", yaw="d", veh="b").add(
            rec_ns=rec, boot_ns=m.time_boot_ms * 10**6, sys=sysid, dev=compid, roll=m.roll, pitch=m.pitch,
            yaw=m.yaw_absolute if earth else m.yaw, veh=not earth)

    def _camera_tracking_geo_status(self, m, rec, sysid, compid):
        self._c("CAMERA_TRACKING_GEO_STATUS", r="d", lo="d", hi="d").add(
            rec_ns=rec, boot_ns=-1, sys=sysid, dev=compid, r=m.dist, lo=0.0, hi=np.inf)

    def _rangefinder(self, m, rec, sysid, compid):
        self._c("RANGEFINDER", r="d", lo="d", hi="d").add(rec_ns=rec, boot_ns=-1, sys=sysid, dev=compid, r=m.distance,
                                                            lo=0.0, hi=np.inf)

    def _distance_sensor(self, m, rec, sysid, compid):
        want = self.mapping["range"]["instance"]
        if isinstance(want, int) and m.id != want:
            return
        r = np.nan if m.current_distance == 65535 else m.current_distance * 0.01
        self._c("DISTANCE_SENSOR", r="d", lo="d", hi="d", orient="q", quality="q").add(
            rec_ns=rec, boot_ns=m.time_boot_ms * 10**6, sys=sysid, dev=compid * 256 + m.id, r=r,
            lo=m.min_distance * 0.01, hi=m.max_distance * 0.01, orient=m.orientation,
            quality=getattr(m, "signal_quality", 0))

    def _camera_feedback(self, m, rec, sysid, compid):
        self._c("CAMERA_FEEDBACK", idx="q").add(rec_ns=rec, boot_ns=-1, sys=sysid, idx=m.img_idx)

    def _camera_image_captured(self, m, rec, sysid, compid):
        self._c("CAMERA_IMAGE_CAPTURED", idx="q").add(rec_ns=rec, boot_ns=m.time_boot_ms * 10**6, sys=sysid,
                                                      idx=m.image_index)

    def _system_time(self, m, rec, sysid, compid):
        if m.time_unix_usec == 0:
            return  # no UNIX time before the GPS fix
        self._c("SYSTEM_TIME", unix_ns="q").add(rec_ns=rec, boot_ns=m.time_boot_ms * 10**6, sys=sysid,
                                                unix_ns=m.time_unix_usec * 1000)


def _wanted_names(mapping: dict) -> list[str]:
    names = ["SYSTEM_TIME"]
    for q in ("position", "attitude", "gimbal", "range", "camera"):
        names += mapping[q]["messages"]
    unknown = [n for n in names if n not in SUPPLIES]
    if unknown:
        from pipeline.errors import ConfigError
        raise ConfigError(f"tlog mapping: message(s) {', '.join(unknown)} cannot supply a quantity "
                          f"(known: {', '.join(sorted(SUPPLIES))})")
    return names


def read_tlog(path: str | Path, mapping: dict) -> FlightLog:
    """Read a .tlog into a FlightLog on the UNIX clock (see mappings/tlog.yaml)."""
    path = Path(path)
    wanted_ids = {_ID_BY_NAME[n] for n in _wanted_names(mapping)}
    mav = mavlink.MAVLink(None)
    mav.robust_parsing = True
    coll = _Collector(mapping)
    counts: Counter = Counter()
    first_us: dict[int, int] = {}
    last_us: dict[int, int] = {}
    warnings: list[str] = []
    skipped = bad_crc = 0
    truncated = False
    try:
        f = open(path, "rb")
    except OSError as exc:
        raise LogReadError(f"cannot open: {exc.strerror}", path=path) from None
    with f:
        size = path.stat().st_size
        if size == 0:
            raise LogReadError("empty file", path=path)
        mm = mmap.mmap(f.fileno(), 0, access=mmap.ACCESS_READ)
        try:
            pos, last = 0, None
            release_at = _RELEASE_BYTES
            while pos < size:
                rec = _record_length(mm, pos, size)
                ts_us = int.from_bytes(mm[pos:pos + 8], "big") if pos + 8 <= size else None
                plausible = ts_us is not None and (
                    _PLAUSIBLE_US[0] <= ts_us <= _PLAUSIBLE_US[1] if last is None
                    else last - 3600 * 10**6 <= ts_us <= last + 86400 * 10**6)
                if rec is None or not plausible:
                    if size - pos < 8 + 12 and rec is None and last is not None:
                        truncated = True
                        break
                    nxt = _resync(mm, pos + 1, size, last)
                    skipped += nxt - pos
                    pos = nxt
                    continue
                msgid, length = rec
                end = pos + 8 + length
                if end > size:
                    truncated = True
                    break
                if msgid in wanted_ids:
                    try:
                        msg = mav.decode(bytearray(mm[pos + 8:end]))
                    except mavlink.MAVError:
                        msg = None
                    if msg is None or msg.get_type() == "BAD_DATA":
                        bad_crc += 1
                        nxt = _resync(mm, pos + 1, size, last)
                        skipped += nxt - pos
                        pos = nxt
                        continue
                    coll.add(msg.get_type(), msg, ts_us * 1000, msg.get_srcSystem(), msg.get_srcComponent())
                counts[msgid] += 1
                if msgid not in first_us:
                    first_us[msgid] = ts_us
                last_us[msgid] = ts_us
                last = ts_us
                pos = end
                if pos >= release_at:  # drop mapped pages behind us: RSS stays flat on large files
                    if hasattr(mmap, "MADV_DONTNEED"):
                        mm.madvise(mmap.MADV_DONTNEED, 0, release_at)
                    release_at += _RELEASE_BYTES
        finally:
            mm.close()
    n_read = sum(counts.values())
    if n_read == 0:
        raise LogReadError("no MAVLink records found (not a .tlog, or garbage)", path=path)
    if skipped:
        warnings.append(f"{path}: skipped {skipped} bytes that are not MAVLink records ({bad_crc} bad CRC)")
    if truncated:
        span = (max(last_us.values()) - min(first_us.values())) / 1e6
        warnings.append(f"{path}: file ends mid-record (truncated); read {n_read} messages covering {span:.1f} s")
    streams = [StreamInfo(name=_NAME_BY_ID[mid], msg_type=_NAME_BY_ID[mid], count=n,
                          t_first_ns=first_us[mid] * 1000, t_last_ns=last_us[mid] * 1000,
                          supplies=(SUPPLIES[_NAME_BY_ID[mid]],) if _NAME_BY_ID[mid] in SUPPLIES else ())
               for mid, n in sorted(counts.items(), key=lambda kv: (-kv[1], _NAME_BY_ID[kv[0]]))]
    return _assemble(path, coll, mapping, streams, warnings)


def _pick(coll: _Collector, names: list[str], mapping: dict, what: str, warnings: list[str], path: Path):
    """The first message of `names` with samples, filtered to one system id: (name, dict of arrays) or None."""
    for name in names:
        cols = coll.cols.get(name)
        if cols is None or len(cols) == 0:
            continue
        a = cols.arrays()

        def warn(ids: np.ndarray, want: int, name: str = name) -> None:
            warnings.append(f"{path}: {name} comes from systems {ids.tolist()}; using system {want} for {what} "
                            "(set tlog.system_id to choose)")

        a = one_source(a, "sys", mapping["system_id"], most_samples=True, on_several=warn)
        if not a["sys"].size:
            continue
        if what in ("gimbal", "range"):
            a = _one_device(a, name, what, mapping, warnings, path)
        return name, a
    return None


def _one_device(a: dict, name: str, what: str, mapping: dict, warnings: list[str], path: Path) -> dict:
    """Samples of one device: a vehicle may carry two gimbals (components) or several rangefinders (DISTANCE_SENSOR
    ids); interleaving them would make one jumping series. `tlog.gimbal.component_id` chooses the gimbal, else the
    device with the most samples is used, with a warning; the rangefinder follows pipeline.ingest.rangefinder."""
    if what == "range":
        want = mapping["range"]["instance"]  # an int (DISTANCE_SENSOR.id) was applied while decoding
        label = ((lambda d: f"component {d // 256} sensor id {d % 256}") if name == "DISTANCE_SENSOR"
                 else (lambda d: f"component {d}"))
        return one_instance({**a, "instance": a["dev"]}, None if isinstance(want, int) else want, name, "tlog",
                            warnings, path, label)

    def warn(ids: np.ndarray, want: int) -> None:
        warnings.append(f"{path}: {name} from several devices ({', '.join(f'component {d}' for d in ids)}); using "
                        f"component {want} for {what} (set tlog.gimbal.component_id)")

    return one_source(a, "dev", mapping["gimbal"]["component_id"], most_samples=True, on_several=warn)


def _times(a: dict, mapping: dict, link: ClockLink | None, name: str = "", warnings: list | None = None):
    """(t_ns on the UNIX clock, "unix"): the record time, or with `time: boot` time_boot_ms mapped through
    SYSTEM_TIME (messages without time_boot_ms, or a log without SYSTEM_TIME, keep the record time)."""
    if mapping["time"] == "boot":
        if link is not None and (a["boot_ns"] >= 0).all():
            return map_clock(a["boot_ns"], link), "unix"
        if warnings is not None:
            why = "no SYSTEM_TIME with UNIX time" if link is None else "no time_boot_ms in the message"
            warnings.append(f"{name}: record time used ({why})")
    return a["rec_ns"], "unix"


def _distance_sensor_orientation(coll: _Collector, mapping: dict, warnings: list[str], path: Path) -> None:
    """Keep only DISTANCE_SENSOR samples facing as the laser does (before the message is picked, so that a log
    with only a down-facing altimeter falls through to the next range message)."""
    cols = coll.cols.get("DISTANCE_SENSOR")
    if cols is None or not len(cols):
        return
    coll.cols["DISTANCE_SENSOR"] = _Kept(laser_facing(cols.arrays(), mapping["range"]["orientations"],
                                                      "DISTANCE_SENSOR", "tlog", warnings, path))


class _Kept:
    """Already assembled columns standing in for a Columns object."""

    def __init__(self, arrays: dict):
        self._a = arrays

    def __len__(self) -> int:
        return int(self._a["rec_ns"].size)

    def arrays(self) -> dict:
        return self._a


def _assemble(path: Path, coll: _Collector, mapping: dict, streams, warnings) -> FlightLog:
    log = FlightLog(path=str(path), streams=streams, warnings=warnings, formats=["tlog"])
    src = path.name
    link = None
    if mapping["time"] not in ("record", "boot"):
        from pipeline.errors import ConfigError
        raise ConfigError(f"tlog mapping: time must be 'record' or 'boot', not {mapping['time']!r}")
    st = coll.cols.get("SYSTEM_TIME")
    if st is not None and len(st):
        a = st.arrays()
        link = ClockLink("boot", "unix", a["boot_ns"], a["unix_ns"])
        log.clock_links.append(link)

    got = _pick(coll, mapping["position"]["messages"], mapping, "position", warnings, path)
    if got is None:
        n_pos = sum(s.count for s in streams if s.name in mapping["position"]["messages"])
        if n_pos:
            warnings.append(f"{path}: no GPS fix in {n_pos} position messages; no position read")
    else:
        name, a = got
        t, clock = _times(a, mapping, link, f"{path}: {name}", warnings)
        if name == "GPS_RAW_INT" and (a["alt_ell"] != 0).all():
            alt, datum = a["alt_ell"], "ellipsoid"
        else:
            alt, datum = a["alt"], "amsl"
        t, lat, lon, alt = sort_by_time(t, a["lat"], a["lon"], alt)
        log.position = PositionSeries(t, lat, lon, alt, datum, source=f"{src}:{name}", clock=clock)

    got = _pick(coll, mapping["attitude"]["messages"], mapping, "attitude", warnings, path)
    if got is not None:
        name, a = got
        t, clock = _times(a, mapping, link, f"{path}: {name}", warnings)
        if name == "ATTITUDE":
            q = quat_ned_from_frd_euler(a["roll"], a["pitch"], a["yaw"])
        else:
            q = quat_wxyz_from_rotation(rotation_from_quat_wxyz(np.column_stack([a["w"], a["x"], a["y"], a["z"]])))
        t, q = sort_by_time(t, q)
        log.attitude = AttitudeSeries(t, q, source=f"{src}:{name}", clock=clock)

    got = _pick(coll, mapping["gimbal"]["messages"], mapping, "gimbal", warnings, path)
    if got is not None:
        name, a = got
        t, clock = _times(a, mapping, link, f"{path}: {name}", warnings)
        if name == "GIMBAL_DEVICE_ATTITUDE_STATUS":
            q = np.column_stack([a["w"], a["x"], a["y"], a["z"]])
            ok = np.isfinite(q).all(axis=1) & (np.linalg.norm(q, axis=1) > 0.5)
            if not ok.all():
                warnings.append(f"{path}: {int((~ok).sum())} {name} samples without a valid quaternion dropped")
            t, q, veh = t[ok], quat_wxyz_from_rotation(rotation_from_quat_wxyz(q[ok])), a["veh"][ok].astype(bool)
        else:
            q = quat_ned_from_frd_euler(np.radians(a["roll"]), np.radians(a["pitch"]), np.radians(a["yaw"]))
            if name == "MOUNT_STATUS":
                veh = np.full(t.shape, mapping["gimbal"]["mount_status_yaw"] == "vehicle")
            else:
                veh = a["veh"].astype(bool)
        t, q, veh = sort_by_time(t, q, veh)
        log.gimbal = GimbalSeries(t, q, veh, source=f"{src}:{name}", clock=clock)

    _distance_sensor_orientation(coll, mapping, warnings, path)
    got = _pick(coll, mapping["range"]["messages"], mapping, "range", warnings, path)
    if got is not None:
        name, a = got
        t, clock = _times(a, mapping, link, f"{path}: {name}", warnings)
        r = a["r"]
        lo = np.maximum(a["lo"], float(mapping["range"]["min_m"]))
        hi = np.minimum(a["hi"], float(mapping["range"]["max_m"]))
        with np.errstate(invalid="ignore"):
            valid = np.isfinite(r) & (r > lo) & (r <= hi) if name != "DISTANCE_SENSOR" else \
                np.isfinite(r) & (r >= lo) & (r <= hi) & (r > float(mapping["range"]["min_m"])) & (a["quality"] != 1)
        t, r, valid = sort_by_time(t, r, valid)
        log.range = RangeSeries(t, r, valid, source=f"{src}:{name}", clock=clock)

    got = _pick(coll, mapping["camera"]["messages"], mapping, "camera", warnings, path)
    if got is not None:
        name, a = got
        t, clock = _times(a, mapping, link, f"{path}: {name}", warnings)
        t, idx = sort_by_time(t, a["idx"])
        log.camera_events = CameraEventSeries(t, idx, source=f"{src}:{name}", clock=clock)
    return log
