"""DataFlash units and frames on small logs written with the firmware's format characters (FMT records)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from pipeline.ingest import read_flight
from support.writers import DataFlashWriter

WEEK, MS0 = 2300, 100_000_000  # GPS week 2300, 100000 s into the week


def _write(path, n=10, with_mnt=True, with_rfnd=True, orient=0):
    with DataFlashWriter(path) as w:
        w.fmt("GPS", "QBIHLLe", "TimeUS,Status,GMS,GWk,Lat,Lng,Alt")
        w.fmt("ATT", "QccC", "TimeUS,Roll,Pitch,Yaw")
        if with_mnt:
            w.fmt("MNT", "Qfffff", "TimeUS,Roll,Pitch,YawB,YawE,Dist")
        if with_rfnd:
            w.fmt("RFND", "QBCBB", "TimeUS,Instance,Dist,Stat,Orient")
        for i in range(n):
            t_us = 60_000_000 + i * 200_000
            w.write("GPS", t_us, 1 if i == 0 else 3, MS0 + i * 200, WEEK, 473977419, 85455939, 48812)
            w.write("ATT", t_us + 10, 500, -250, 27000)  # roll 5, pitch -2.5, yaw 270 deg
            if with_mnt:
                w.write("MNT", t_us + 20, 0.0, -30.0, 15.0, 285.0, 1234.5 if i % 2 else 0.0)
            if with_rfnd:
                w.write("RFND", t_us + 30, 0, 1234 + i, 4 if i % 3 else 2, orient)


def test_dataflash_units_frames_clock(tmp_path):
    p = tmp_path / "f.bin"
    _write(p)
    log = read_flight([p])
    pos = log.position
    assert pos.t_ns.size == 9  # Status 1 (no fix) dropped
    assert pos.lat_deg[0] == pytest.approx(47.3977419) and pos.lon_deg[0] == pytest.approx(8.5455939)
    assert pos.alt_m[0] == pytest.approx(488.12) and pos.alt_datum == "amsl"  # 'e': int32 * 0.01 m
    # GPS time -> UNIX: 315964800 + 2300 weeks + 100000.2 s - 18 s; the GPS record is logged at that instant
    assert pos.clock == "unix"
    assert pos.t_ns[0] == (315964800 + WEEK * 604800 - 18) * 10**9 + (MS0 + 200) * 10**6
    # ATT: roll 5, pitch -2.5, yaw 270 deg (west)
    fwd = Rotation.from_quat(log.attitude.quat_wxyz[0], scalar_first=True).apply([1, 0, 0])
    p_ = math.radians(-2.5)
    np.testing.assert_allclose(fwd, [0, -math.cos(p_), -math.sin(p_)], atol=1e-9)
    # MNT: earth yaw YawE = 285 deg preferred over YawB, pitch -30 deg
    g = Rotation.from_quat(log.gimbal.quat_wxyz[0], scalar_first=True).as_euler("ZYX", degrees=True)
    np.testing.assert_allclose(g, [285 - 360, -30, 0], atol=1e-9)
    assert not log.gimbal.yaw_in_vehicle_frame.any()
    # RFND: C = uint16 cm * 0.01 -> m; Stat 4 = Good only
    np.testing.assert_allclose(log.range.range_m[:3], [12.34, 12.35, 12.36])
    assert log.range.valid[:4].tolist() == [False, True, True, False]


def test_dataflash_mnt_dist_and_body_yaw(tmp_path):
    p = tmp_path / "m.bin"
    _write(p, with_rfnd=False)
    mapping = {"dataflash": {"range": {"message": "MNT"},
                             "gimbal": {"fields": {"yaw_earth_deg": ["NoSuchField"]}}}}
    log = read_flight([p], mapping=mapping)
    np.testing.assert_allclose(log.range.range_m[:2], [0.0, 1234.5])
    assert log.range.valid[:2].tolist() == [False, True]  # MNT.Dist 0: no reading
    assert log.gimbal.yaw_in_vehicle_frame.all()  # YawB: relative to the vehicle
    g = Rotation.from_quat(log.gimbal.quat_wxyz[0], scalar_first=True).as_euler("ZYX", degrees=True)
    assert g[0] == pytest.approx(15.0)


def test_dataflash_cut_mid_record(tmp_path):
    p = tmp_path / "f.bin"
    _write(p, n=50)
    data = p.read_bytes()
    cut = tmp_path / "cut.bin"
    cut.write_bytes(data[: len(data) // 2 + 5])
    log = read_flight([cut])
    assert any("truncated" in w and "records" in w for w in log.warnings)
    assert 15 < log.attitude.t_ns.size < 50


def test_dataflash_old_firmware_fields(tmp_path):
    """Older logs: GPS without week/ms (no UNIX link), `Lon` instead of `Lng`, MNT without Dist or YawE."""
    p = tmp_path / "old.bin"
    with DataFlashWriter(p) as w:
        w.fmt("GPS", "QBLLe", "TimeUS,Status,Lat,Lon,Alt")
        w.fmt("MNT", "Qfff", "TimeUS,Roll,Pitch,Yaw")
        for i in range(4):
            w.write("GPS", 1_000_000 + i * 200_000, 3, 473977419, 85455939, 48812)
            w.write("MNT", 1_000_010 + i * 200_000, 0.0, -10.0, 5.0)
    log = read_flight([p], mapping={"dataflash": {"range": {"message": "MNT"}}})
    assert log.position.clock == "boot" and log.position.t_ns[0] == 1_000_000_000
    assert log.position.lon_deg[0] == pytest.approx(8.5455939)
    assert any("no GPS week/time in the log; series stay on the boot clock" in w for w in log.warnings)
    assert log.range is None  # MNT has no Dist in this firmware
    assert log.gimbal.yaw_in_vehicle_frame.all()  # old MNT Yaw: relative to the vehicle


def test_dataflash_rfnd_orientation_and_instance(tmp_path):
    """RFND Orient 25 (down) is a terrain altimeter, not the laser at the target: ignored unless configured."""
    p = tmp_path / "down.bin"
    _write(p, with_mnt=False, orient=25)
    log = read_flight([p])
    assert log.range is None
    assert any("10 of 10 RFND samples with orientation 25 ignored" in w and "down-facing" in w for w in log.warnings)
    log = read_flight([p], mapping={"dataflash": {"range": {"orientations": [25]}}})
    np.testing.assert_allclose(log.range.range_m[:3], [12.34, 12.35, 12.36])
    p = tmp_path / "two.bin"
    with DataFlashWriter(p) as w:
        w.fmt("RFND", "QBCBB", "TimeUS,Instance,Dist,Stat,Orient")
        for i in range(6):
            w.write("RFND", 1_000_000 + i * 100_000, i % 2, 50_000 + i, 4, 0)  # instance 1 at 500.01 m, ...
    log = read_flight([p], mapping={"dataflash": {"range": {"instance": 1}}})
    np.testing.assert_allclose(log.range.range_m, [500.01, 500.03, 500.05])
    log = read_flight([p])  # default: the lowest instance, with a warning naming the key
    np.testing.assert_allclose(log.range.range_m, [500.00, 500.02, 500.04])
    assert any("range from instance 0 (set dataflash.range.instance" in w for w in log.warnings)


def test_dataflash_instances_are_never_interleaved(tmp_path):
    """Two GPS receivers and two mounts (field I, ArduPilot 4.x): one instance each, never both in one series."""
    p = tmp_path / "dual.bin"
    with DataFlashWriter(p) as w:
        w.fmt("GPS", "QBBIHLLe", "TimeUS,I,Status,GMS,GWk,Lat,Lng,Alt")
        w.fmt("MNT", "QBfffff", "TimeUS,I,Roll,Pitch,YawB,YawE,Dist")
        for i in range(6):
            t_us = 1_000_000 + i * 100_000
            w.write("GPS", t_us, i % 2, 3, MS0 + i * 100, WEEK, 473977419 + 1000 * (i % 2), 85455939, 48812)
            w.write("MNT", t_us + 1, i % 2, 0.0, -30.0 - 10 * (i % 2), 0.0, 90.0, 0.0)
    log = read_flight([p])
    np.testing.assert_allclose(log.position.lat_deg, [47.3977419] * 3)  # instance 0
    assert any("GPS records of instances [0, 1]; position from instance 0" in w for w in log.warnings)
    pitch = Rotation.from_quat(log.gimbal.quat_wxyz, scalar_first=True).as_euler("ZYX", degrees=True)[:, 1]
    np.testing.assert_allclose(pitch, [-30.0] * 3, atol=1e-9)
    log = read_flight([p], mapping={"dataflash": {"position": {"instance": 1}, "gimbal": {"instance": 1}}})
    np.testing.assert_allclose(log.position.lat_deg, [47.3978419] * 3)
    pitch = Rotation.from_quat(log.gimbal.quat_wxyz, scalar_first=True).as_euler("ZYX", degrees=True)[:, 1]
    np.testing.assert_allclose(pitch, [-40.0] * 3, atol=1e-9)
