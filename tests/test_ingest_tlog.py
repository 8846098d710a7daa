"""MAVLink .tlog reader: units, frames, clocks, bad input, and the real ArduPilot tlog."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from pymavlink import mavutil
from pymavlink.dialects.v20 import ardupilotmega as ml
from scipy.spatial.transform import Rotation

from pipeline.errors import ConfigError, LogReadError
from pipeline.ingest import read_flight
from support.writers import TlogWriter

LOGS = Path(__file__).resolve().parents[1] / ".." / "shared" / "logs"
T0_US = 1_700_000_000_000_000


def _write_flight(path: Path, n: int = 20) -> None:
    with TlogWriter(path) as w:
        for i in range(n):
            t = T0_US + i * 100_000
            boot_ms = 5000 + i * 100
            w.write(t, ml.MAVLink_heartbeat_message(2, 3, 0, 0, 0, 3))
            w.write(t + 1, ml.MAVLink_system_time_message(T0_US - 4_000_000 + i * 100_000 - 250, boot_ms))
            w.write(t + 2, ml.MAVLink_global_position_int_message(boot_ms, 473977419, 85455939, 500123, 100000,
                                                                  0, 0, 0, 65535))
            w.write(t + 3, ml.MAVLink_attitude_message(boot_ms, 0.0, math.radians(30), math.radians(90), 0, 0, 0))
            w.write(t + 4, ml.MAVLink_gimbal_device_attitude_status_message(
                0, 0, boot_ms, 64 if i % 2 else 32, [math.cos(0.25), 0.0, math.sin(0.25), 0.0],
                0, 0, 0, 0), src_component=154)
            w.write(t + 5, ml.MAVLink_distance_sensor_message(boot_ms, 20, 4000, [1234, 5000, 10, 65535][i % 4],
                                                              0, 0, 0, 0), src_component=1)
            w.write(t + 6, ml.MAVLink_camera_tracking_geo_status_message(
                0, 0, 0, 0.0, 0, 0, 0, 0, 0, 0, [2500.5, float("nan"), -1.0, 812.25][i % 4], 0, 0))


def test_units_and_frames_hand_computed(tmp_path):
    p = tmp_path / "f.tlog"
    _write_flight(p)
    log = read_flight([p])
    assert log.position.alt_datum == "amsl" and log.position.clock == "unix"
    assert log.position.lat_deg[0] == pytest.approx(47.3977419, abs=1e-9)
    assert log.position.lon_deg[0] == pytest.approx(8.5455939, abs=1e-9)
    assert log.position.alt_m[0] == pytest.approx(500.123)
    assert log.position.t_ns[0] == (T0_US + 2) * 1000
    # heading east (yaw 90 deg), nose up 30 deg: body forward -> NED (0, cos30, -sin30)
    fwd = Rotation.from_quat(log.attitude.quat_wxyz[0], scalar_first=True).apply([1, 0, 0])
    np.testing.assert_allclose(fwd, [0, math.cos(math.radians(30)), -0.5], atol=1e-6)
    # by hand: q = qz(90) * qy(30) = (c45 c15, -s45 s15, c45 s15, s45 c15)
    c45, s45, c15, s15 = math.cos(math.pi / 4), math.sin(math.pi / 4), math.cos(math.pi / 12), math.sin(math.pi / 12)
    np.testing.assert_allclose(log.attitude.quat_wxyz[0], [c45 * c15, -s45 * s15, c45 * s15, s45 * c15], atol=1e-6)
    # gimbal: pitch 0.5 rad quaternion; flag 32 (vehicle frame) on even samples, 64 (earth) on odd
    np.testing.assert_allclose(log.gimbal.quat_wxyz[0], [math.cos(0.25), 0, math.sin(0.25), 0], atol=1e-7)
    assert log.gimbal.yaw_in_vehicle_frame[:4].tolist() == [True, False, True, False]
    # default range carrier CAMERA_TRACKING_GEO_STATUS.dist (float m)
    assert log.range.source.endswith("CAMERA_TRACKING_GEO_STATUS")
    np.testing.assert_allclose(log.range.range_m[:4], [2500.5, np.nan, -1.0, 812.25])
    assert log.range.valid[:4].tolist() == [True, False, False, True]
    assert log.missing_for_localization() == ["frames"]


def test_distance_sensor_cm_and_validity(tmp_path):
    p = tmp_path / "f.tlog"
    _write_flight(p, 8)
    log = read_flight([p], mapping={"tlog": {"range": {"messages": ["DISTANCE_SENSOR"]}}})
    np.testing.assert_allclose(log.range.range_m[:3], [12.34, 50.0, 0.10])
    assert np.isnan(log.range.range_m[3])
    # 12.34 m inside [0.2, 40] m; 50 m above max; 0.1 m below min; 65535 = no reading
    assert log.range.valid[:4].tolist() == [True, False, False, False]


def test_boot_time_through_system_time(tmp_path):
    p = tmp_path / "f.tlog"
    _write_flight(p)
    log = read_flight([p], mapping={"tlog": {"time": "boot"}})
    # SYSTEM_TIME: unix = T0 - 4 s - 250 us + (boot - 5000 ms)
    assert log.position.t_ns[0] == (T0_US - 4_000_000 - 250) * 1000
    assert log.clock_links[0].a == "boot" and log.clock_links[0].b == "unix"
    # CAMERA_TRACKING_GEO_STATUS has no time_boot_ms: record time, said in a warning
    assert log.range.t_ns[0] == (T0_US + 6) * 1000
    assert any("CAMERA_TRACKING_GEO_STATUS: record time used (no time_boot_ms" in w for w in log.warnings)
    with pytest.raises(ConfigError, match="time must be 'record' or 'boot'"):
        read_flight([p], mapping={"tlog": {"time": "gps"}})


def test_unknown_mapping_key_rejected(tmp_path):
    p = tmp_path / "f.tlog"
    _write_flight(p, 2)
    with pytest.raises(ConfigError, match="unknown key 'postion'"):
        read_flight([p], mapping={"tlog": {"postion": {"messages": ["GPS_RAW_INT"]}}})
    with pytest.raises(ConfigError, match="cannot supply"):
        read_flight([p], mapping={"tlog": {"range": {"messages": ["HEARTBEAT"]}}})


def test_truncated_tlog_warns_with_amount_read(tmp_path):
    p = tmp_path / "f.tlog"
    _write_flight(p, 20)
    data = p.read_bytes()
    cut = tmp_path / "cut.tlog"
    cut.write_bytes(data[: len(data) // 2 + 7])
    log = read_flight([cut])
    assert any("truncated" in w and "messages" in w for w in log.warnings)
    assert 5 <= log.position.t_ns.size < 20


def test_garbage_in_the_middle_is_skipped(tmp_path):
    p = tmp_path / "f.tlog"
    _write_flight(p, 10)
    data = p.read_bytes()
    rng = np.random.default_rng(1)
    bad = tmp_path / "bad.tlog"
    bad.write_bytes(data[:500] + rng.integers(0, 256, 333, dtype=np.uint8).tobytes() + data[500:])
    log = read_flight([bad])
    assert any("skipped" in w for w in log.warnings)
    assert log.position.t_ns.size >= 9


def test_garbage_file_and_empty_file_fail_clearly(tmp_path):
    g = tmp_path / "g.tlog"
    g.write_bytes(np.random.default_rng(2).integers(0, 256, 4000, dtype=np.uint8).tobytes())
    with pytest.raises(LogReadError, match=r"g\.tlog: no MAVLink records"):
        read_flight([g])
    e = tmp_path / "e.tlog"
    e.write_bytes(b"")
    with pytest.raises(LogReadError, match=r"e\.tlog: empty file"):
        read_flight([e])


def test_no_gps_fix_reported_missing(tmp_path):
    p = tmp_path / "nofix.tlog"
    with TlogWriter(p) as w:
        for i in range(5):
            w.write(T0_US + i * 1000, ml.MAVLink_global_position_int_message(i, 0, 0, 0, 0, 0, 0, 0, 0))
            w.write(T0_US + i * 1000 + 1, ml.MAVLink_attitude_message(i, 0, 0, 0, 0, 0, 0))
    log = read_flight([p])
    assert log.position is None
    assert "position" in log.missing_for_localization()
    assert any("no GPS fix in 5 position messages" in w for w in log.warnings)


def test_real_ardupilot_tlog_against_raw_pymavlink():
    path = LOGS / "ardupilot_uavlogviewer_vtol.tlog"
    raw = mavutil.mavlink_connection(str(path))
    first_pos = raw.recv_match(type="GLOBAL_POSITION_INT")
    t_pos_us = round(first_pos._timestamp * 1e6)
    raw = mavutil.mavlink_connection(str(path))
    first_att = raw.recv_match(type="ATTITUDE")
    log = read_flight([path])
    assert log.position.t_ns.size == 807 and log.attitude.t_ns.size == 888
    assert log.position.t_ns[0] == t_pos_us * 1000
    assert log.position.lat_deg[0] == pytest.approx(first_pos.lat / 1e7, abs=1e-12)
    assert log.position.lon_deg[0] == pytest.approx(first_pos.lon / 1e7, abs=1e-12)
    assert log.position.alt_m[0] == pytest.approx(first_pos.alt / 1000)
    # hand-converted: yaw 2.45 rad, roll -0.0247, pitch 0.0025: heading 140.4 deg, nearly level
    r, p_, y = first_att.roll, first_att.pitch, first_att.yaw
    fwd = Rotation.from_quat(log.attitude.quat_wxyz[0], scalar_first=True).apply([1, 0, 0])
    np.testing.assert_allclose(fwd, [math.cos(y) * math.cos(p_), math.sin(y) * math.cos(p_), -math.sin(p_)],
                               atol=1e-7)
    down = Rotation.from_quat(log.attitude.quat_wxyz[0], scalar_first=True).apply([0, 0, 1])
    assert down[2] == pytest.approx(math.cos(r) * math.cos(p_), abs=1e-7)
    assert log.gimbal is None and log.range is None
    assert sum(s.count for s in log.streams) == 23894


def test_mount_status_rangefinder_camera_feedback_and_system_choice(tmp_path):
    p = tmp_path / "m.tlog"
    with TlogWriter(p) as w:
        for i in range(6):
            t = T0_US + i * 200_000
            w.write(t, ml.MAVLink_mount_status_message(0, 0, -4500, 150, 9000, 2))  # pitch -45, roll 1.5, yaw 90
            w.write(t + 1, ml.MAVLink_rangefinder_message(812.5 if i else float("nan"), 0.0))
            w.write(t + 2, ml.MAVLink_camera_feedback_message(t, 1, 0, i, 0, 0, 0.0, 0.0, 0, 0, 0, 0, 0, 0))
            w.write(t + 3, ml.MAVLink_global_position_int_message(i, 100000000, 200000000, 1000, 0, 0, 0, 0, 0))
            if i < 2:  # a second vehicle (or a GCS echo) on system 7
                w.write(t + 4, ml.MAVLink_global_position_int_message(i, 1, 1, 1, 0, 0, 0, 0, 0), src_system=7)
                w.mav.srcSystem = 1
    mapping = {"tlog": {"range": {"messages": ["RANGEFINDER"]}}}
    log = read_flight([p], mapping=mapping)
    ypr = Rotation.from_quat(log.gimbal.quat_wxyz[0], scalar_first=True).as_euler("ZYX", degrees=True)
    np.testing.assert_allclose(ypr, [90, -45, 1.5], atol=1e-9)
    assert log.gimbal.yaw_in_vehicle_frame.all()  # ArduPilot MOUNT_STATUS yaw is relative to the vehicle
    assert log.range.valid.tolist() == [False, True, True, True, True, True] and log.range.range_m[1] == 812.5
    assert log.camera_events.index.tolist() == list(range(6))
    assert log.position.t_ns.size == 6 and (log.position.lat_deg == 10.0).all()
    assert any("systems [1, 7]; using system 1" in w for w in log.warnings)
    log7 = read_flight([p], mapping={"tlog": {"system_id": 7}})
    assert log7.position.t_ns.size == 2


def test_distance_sensor_orientation_and_signal_quality(tmp_path):
    """Two DISTANCE_SENSORs: id 1 down-facing (orientation 25, the altimeter), id 2 forward (0, the laser).
    Only the forward one is the range; signal_quality 1 = invalid signal (0 = unknown is fine)."""
    p = tmp_path / "two.tlog"
    with TlogWriter(p) as w:
        for i in range(4):
            t, boot = T0_US + i * 100_000, 1000 + i * 100
            w.write(t, ml.MAVLink_distance_sensor_message(boot, 10, 4000, 250, 0, 1, 25, 0))
            w.write(t + 1, ml.MAVLink_distance_sensor_message(boot, 10, 60000, 45678 + i, 0, 2, 0, 0,
                                                              signal_quality=[0, 100, 1, 50][i]))
    log = read_flight([p], mapping={"tlog": {"range": {"messages": ["DISTANCE_SENSOR"]}}})
    np.testing.assert_allclose(log.range.range_m, [456.78, 456.79, 456.80, 456.81])
    assert log.range.valid.tolist() == [True, True, False, True]
    assert any("4 of 8 DISTANCE_SENSOR samples with orientation 25 ignored" in w for w in log.warnings)
    log = read_flight([p], mapping={"tlog": {"range": {"messages": ["DISTANCE_SENSOR"], "orientations": None,
                                                       "instance": 1}}})
    np.testing.assert_allclose(log.range.range_m, [2.5] * 4)
    with pytest.warns(FutureWarning, match=r"tlog.range.distance_sensor_\w+ is deprecated: use tlog.range.\w+$"):
        log = read_flight([p], mapping={"tlog": {"range": {"messages": ["DISTANCE_SENSOR"],
                                                           "distance_sensor_orientations": None,
                                                           "distance_sensor_id": 1}}})
    np.testing.assert_allclose(log.range.range_m, [2.5] * 4)  # the old key names still work
    # both forward-facing: never interleaved; the lowest sensor by default, or the one with most samples
    with TlogWriter(p) as w:
        for i in range(5):
            t, boot = T0_US + i * 100_000, 1000 + i * 100
            if i < 2:
                w.write(t, ml.MAVLink_distance_sensor_message(boot, 10, 4000, 250, 0, 1, 0, 0))
            w.write(t + 1, ml.MAVLink_distance_sensor_message(boot, 10, 60000, 45678, 0, 2, 0, 0))
    log = read_flight([p], mapping={"tlog": {"range": {"messages": ["DISTANCE_SENSOR"]}}})
    np.testing.assert_allclose(log.range.range_m, [2.5] * 2)
    assert any("range from component 1 sensor id 1 (set tlog.range.instance" in w for w in log.warnings)
    log = read_flight([p], mapping={"tlog": {"range": {"messages": ["DISTANCE_SENSOR"], "instance": "most_samples"}}})
    np.testing.assert_allclose(log.range.range_m, [456.78] * 5)
    assert any("range from component 1 sensor id 2" in w for w in log.warnings)


def test_two_gimbals_are_not_interleaved(tmp_path):
    """GIMBAL_DEVICE_ATTITUDE_STATUS from two gimbal components: one is used (most samples, or the chosen one)."""
    p = tmp_path / "g.tlog"
    with TlogWriter(p) as w:
        for i in range(4):
            q = [math.cos(0.25), 0.0, math.sin(0.25), 0.0]
            w.write(T0_US + i * 1000, ml.MAVLink_gimbal_device_attitude_status_message(0, 0, i, 64, q, 0, 0, 0, 0),
                    src_component=154)
            if i < 2:
                w.write(T0_US + i * 1000 + 1, ml.MAVLink_gimbal_device_attitude_status_message(
                    0, 0, i, 64, [1.0, 0.0, 0.0, 0.0], 0, 0, 0, 0), src_component=171)
    log = read_flight([p])
    assert log.gimbal.t_ns.size == 4 and any("component 154 for gimbal" in w for w in log.warnings)
    log = read_flight([p], mapping={"tlog": {"gimbal": {"component_id": 171}}})
    np.testing.assert_allclose(log.gimbal.quat_wxyz, [[1, 0, 0, 0]] * 2)


def test_mount_orientation_and_mount_status(tmp_path):
    """MOUNT_ORIENTATION: roll/pitch deg earth frame, yaw deg relative to the vehicle, yaw_absolute deg earth
    (used when set); MOUNT_STATUS: pointing_a pitch, b roll, c yaw in cdeg (ArduPilot: yaw relative to vehicle)."""
    p = tmp_path / "mount.tlog"
    with TlogWriter(p) as w:
        w.write(T0_US, ml.MAVLink_mount_orientation_message(1000, 1.0, -30.0, 15.0, 250.0))
        w.write(T0_US + 1, ml.MAVLink_mount_orientation_message(1100, 0.0, -45.0, 20.0, 0.0))
        w.write(T0_US + 2, ml.MAVLink_mount_status_message(0, 0, -2500, 100, 9000))
    log = read_flight([p], mapping={"tlog": {"gimbal": {"messages": ["MOUNT_ORIENTATION"]}}})
    ypr = Rotation.from_quat(log.gimbal.quat_wxyz, scalar_first=True).as_euler("ZYX", degrees=True)
    np.testing.assert_allclose(ypr, [[250.0 - 360, -30.0, 1.0], [20.0, -45.0, 0.0]], atol=1e-9)
    assert log.gimbal.yaw_in_vehicle_frame.tolist() == [False, True]
    log = read_flight([p], mapping={"tlog": {"gimbal": {"messages": ["MOUNT_STATUS"]}}})
    ypr = Rotation.from_quat(log.gimbal.quat_wxyz, scalar_first=True).as_euler("ZYX", degrees=True)
    np.testing.assert_allclose(ypr, [[90.0, -25.0, 1.0]], atol=1e-9)
    assert log.gimbal.yaw_in_vehicle_frame.tolist() == [True]


def test_rangefinder_float_metres(tmp_path):
    """ArduPilot RANGEFINDER: float metres (beyond DISTANCE_SENSOR's 655.35 m); <= 0 and NaN invalid."""
    p = tmp_path / "rf.tlog"
    with TlogWriter(p) as w:
        for i, d in enumerate([1234.5, 0.0, float("nan"), 2000.25]):
            w.write(T0_US + i * 100_000, ml.MAVLink_rangefinder_message(d, 12.0))
    log = read_flight([p], mapping={"tlog": {"range": {"messages": ["RANGEFINDER"]}}})
    np.testing.assert_allclose(log.range.range_m, [1234.5, 0.0, np.nan, 2000.25])
    assert log.range.valid.tolist() == [True, False, False, True]
