"""MAVLink 2 telemetry log (.tlog, ardupilotmega dialect) as a ground station records it.

Each record: 8-byte big-endian UNIX time in microseconds + one MAVLink packet. Records are written at the
measurement time (no link latency). Messages: HEARTBEAT and SYSTEM_TIME at 1 Hz, GLOBAL_POSITION_INT (alt AMSL =
ellipsoid height - geoid separation), ATTITUDE, GIMBAL_DEVICE_ATTITUDE_STATUS (from component 154), and the laser
range as CAMERA_TRACKING_GEO_STATUS.dist (float metres, from component 100), since DISTANCE_SENSOR is uint16 cm
and stops at 655 m. An invalid shot has dist = NaN and tracking_status ERROR.
"""

from __future__ import annotations

import math
import os
import struct
from pathlib import Path

from scipy.spatial.transform import Rotation

os.environ.setdefault("MAVLINK20", "1")
from pymavlink.dialects.v20 import ardupilotmega as mav

from pipeline.synth.telemetry import Telemetry

GIMBAL_FLAG_YAW_IN_VEHICLE_FRAME = 32
GIMBAL_FLAG_YAW_IN_EARTH_FRAME = 64
COMP_AUTOPILOT, COMP_CAMERA, COMP_GIMBAL = 1, 100, 154


def _boot_ms(t_ns, boot_ns: int) -> int:
    return int((int(t_ns) - boot_ns) // 1_000_000)


def write_tlog(path: Path, tel: Telemetry, geoid_separation_m: float, home_alt_m: float) -> int:
    """Write the log; returns the number of records. home_alt_m: home (take-off) height above the ellipsoid."""
    links = {c: mav.MAVLink(None, srcSystem=1, srcComponent=c) for c in (COMP_AUTOPILOT, COMP_CAMERA, COMP_GIMBAL)}
    recs: list[tuple[int, int, int, object]] = []  # (t_ns, order, component, message)
    nan = float("nan")

    for t in tel.system_time_t_ns:
        recs.append((t, 0, COMP_AUTOPILOT, mav.MAVLink_heartbeat_message(
            mav.MAV_TYPE_FIXED_WING, mav.MAV_AUTOPILOT_ARDUPILOTMEGA, 217, 10, mav.MAV_STATE_ACTIVE, 3)))
        recs.append((t, 1, COMP_AUTOPILOT, mav.MAVLink_system_time_message(
            int(t) // 1000, _boot_ms(t, tel.boot_ns))))
    for t, lla, v in zip(tel.gps_t_ns, tel.gps_lla, tel.gps_vel_ned, strict=True):
        hdg = round(math.degrees(math.atan2(v[1], v[0])) * 100) % 36000
        recs.append((t, 2, COMP_AUTOPILOT, mav.MAVLink_global_position_int_message(
            _boot_ms(t, tel.boot_ns), round(lla[0] * 1e7), round(lla[1] * 1e7),
            round((lla[2] - geoid_separation_m) * 1000), round((lla[2] - home_alt_m) * 1000),
            round(v[0] * 100), round(v[1] * 100), round(v[2] * 100), hdg)))
    ypr = Rotation.from_quat(tel.att_quat_wxyz, scalar_first=True).as_euler("ZYX")
    for t, (y, p, r), w in zip(tel.att_t_ns, ypr, tel.att_rates_frd, strict=True):
        recs.append((t, 3, COMP_AUTOPILOT, mav.MAVLink_attitude_message(
            _boot_ms(t, tel.boot_ns), r, p, y, w[0], w[1], w[2])))
    flags = GIMBAL_FLAG_YAW_IN_VEHICLE_FRAME if tel.gimbal_yaw_in_vehicle else GIMBAL_FLAG_YAW_IN_EARTH_FRAME
    for t, q, dy in zip(tel.gimbal_t_ns, tel.gimbal_quat_wxyz, tel.gimbal_delta_yaw_rad, strict=True):
        recs.append((t, 4, COMP_GIMBAL, mav.MAVLink_gimbal_device_attitude_status_message(
            0, 0, _boot_ms(t, tel.boot_ns), flags, [float(x) for x in q], nan, nan, nan, 0, float(dy), nan, 0)))
    for t, rng, ok in zip(tel.laser_t_ns, tel.laser_range_m, tel.laser_valid, strict=True):
        recs.append((t, 5, COMP_CAMERA, mav.MAVLink_camera_tracking_geo_status_message(
            mav.CAMERA_TRACKING_STATUS_FLAGS_ACTIVE if ok else mav.CAMERA_TRACKING_STATUS_FLAGS_ERROR,
            0, 0, nan, nan, nan, nan, nan, nan, nan, float(rng) if ok else nan, nan, nan)))

    recs.sort(key=lambda r: (r[0], r[1]))
    with open(path, "wb") as f:
        for t, _, comp, msg in recs:
            f.write(struct.pack(">Q", int(t) // 1000) + msg.pack(links[comp]))
    return len(recs)


def tlog_summary(path: Path) -> dict[str, int]:
    """Message counts by type, read back with pymavlink (used by tests and `ridgeloc synth` output)."""
    from pymavlink import mavutil
    conn = mavutil.mavlink_connection(str(path), dialect="ardupilotmega")
    counts: dict[str, int] = {}
    while (m := conn.recv_match()) is not None:
        counts[m.get_type()] = counts.get(m.get_type(), 0) + 1
    conn.close()
    return dict(sorted(counts.items()))


__all__ = ["tlog_summary", "write_tlog"]
