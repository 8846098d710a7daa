"""Text DataFlash logs (.log): Mission Planner's conversion of a .bin, and old firmware's own text logs."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from pipeline.errors import LogReadError
from pipeline.ingest import read_flight
from pipeline.ingest.dispatch import detect_format
from support.writers import dataflash_text_from_binary

REAL_BIN = "../shared/logs/ardupilot_pymavlink_test.BIN"
GPS_EPOCH_S, LEAP_S = 315964800, 18


def gps_unix_ns(week: int, ms: int) -> int:
    return (GPS_EPOCH_S + week * 604800 - LEAP_S) * 10**9 + ms * 10**6


@pytest.mark.parametrize("newline", ["\n", "\r\n"])
def test_text_conversion_of_a_real_bin_reads_like_the_bin(tmp_path, newline):
    txt = tmp_path / "converted.log"
    n = dataflash_text_from_binary(REAL_BIN, txt, newline=newline)
    assert n > 1000
    assert detect_format(txt) == "dataflash"
    a, b = read_flight(REAL_BIN), read_flight(txt)
    assert b.formats == ["dataflash"] and b.position.clock == "unix"
    for q in ("position", "attitude"):
        sa, sb = getattr(a, q), getattr(b, q)
        np.testing.assert_array_equal(sa.t_ns, sb.t_ns)
        assert sb.source.endswith(f"converted.log:{sa.source.split(':')[1]}")
    np.testing.assert_array_equal(a.position.lat_deg, b.position.lat_deg)
    np.testing.assert_array_equal(a.position.lon_deg, b.position.lon_deg)
    np.testing.assert_allclose(a.position.alt_m, b.position.alt_m, atol=1e-9)
    np.testing.assert_allclose(a.attitude.quat_wxyz, b.attitude.quat_wxyz, atol=1e-12)
    assert {s.name: s.count for s in a.streams}["ATT"] == {s.name: s.count for s in b.streams}["ATT"]


AC31 = """ArduCopter V3.1\r
\r
FMT, 128, 89, FMT, BBnNZ, Type,Length,Name,Format\r
FMT, 130, 45, GPS, BIHBcLLeeEefI, Status,TimeMS,Week,NSats,HDop,Lat,Lng,RelAlt,Alt,Spd,GCrs,VZ,T\r
FMT, 1, 19, ATT, IccccCC, TimeMS,DesRoll,Roll,DesPitch,Pitch,DesYaw,Yaw\r
FMT, 10, 3, STRT, , \r
PARM, RTL_ALT, 1500\r
MSG, ArduCopter V3.1.1 (681dafcf)\r
"""


def _ac31(n=5):
    lines = [AC31]
    for i in range(n):
        lines.append(f"ATT, {95891 + 200 * i}, 0.00, 5.00, 0.00, -2.50, 189.54, 270.00\r\n")
        lines.append(f"GPS, 3, {56674000 + 200 * i}, 1777, 12, 1.32, 14.1105766, 100.6191906, -0.06, 12.50, "
                     f"2.48, 287.33, -1.2, {95901 + 200 * i}\r\n")
    return "".join(lines)


def test_old_text_log_with_week_and_boot_ms(tmp_path):
    """ArduCopter 3.1: TimeMS is boot time in ATT but GPS time of week in GPS (whose boot time is T), CRLF."""
    p = tmp_path / "ac31.log"
    p.write_text(_ac31(), newline="")
    log = read_flight(p)
    assert log.position.clock == "unix" and log.attitude.clock == "unix"
    np.testing.assert_array_equal(log.position.t_ns, [gps_unix_ns(1777, 56674000 + 200 * i) for i in range(5)])
    # ATT logged 10 ms of boot time before each GPS record
    np.testing.assert_array_equal(log.attitude.t_ns, log.position.t_ns - 10 * 10**6)
    assert log.position.lat_deg[0] == 14.1105766 and log.position.alt_m[0] == 12.5
    ypr = Rotation.from_quat(log.attitude.quat_wxyz[0], scalar_first=True).as_euler("ZYX", degrees=True)
    np.testing.assert_allclose(ypr, [-90, -2.5, 5.0], atol=1e-9)  # text values are already in degrees


AC30_HEAD = """58

ArduCopter V3.0.1
Free RAM: 1273
FMT, 128, 89, FMT, BBnNZ, Type,Length,Name,Format
FMT, 130, 35, GPS, BIBcLLeeEe, Status,Time,NSats,HDop,Lat,Lng,RelAlt,Alt,Spd,GCrs
FMT, 1, 17, ATT, cccccCC, RollIn,Roll,PitchIn,Pitch,YawIn,Yaw,NavYaw
PARM, SYSID_SW_MREV, 120.000000
"""
ATT30 = "ATT, 0.00, 0.23, 0.00, 0.75, 0.00, 215.88, 215.88\n"


def _gps30(tow_ms):
    return f"GPS, 3, {tow_ms}, 10, 1.49, 24.2398205, 54.5793101, 0.19, 9.48, 0.01, 347.24\n"


def test_old_text_log_without_week_or_record_times(tmp_path):
    """ArduCopter 3.0: only GPS has a time (ms of the GPS week, no week); ATT records are timed between the
    GPS records by file position, the ATT before the first GPS record is dropped."""
    tows = [308900200, 308900400, 308900600]
    body = ATT30 + "".join(_gps30(t) + ATT30 + ATT30 for t in tows)
    p = tmp_path / "ac30.log"
    p.write_text(AC30_HEAD + body)
    log = read_flight(p)
    assert log.position.clock == "unknown"
    np.testing.assert_array_equal(log.position.t_ns, np.array(tows) * 10**6)
    assert any("no GPS week" in w and "dataflash.gps_week" in w for w in log.warnings)
    # byte lengths: each GPS line ends a period of len(gps) + 2 len(att); the ATT lines end at len(gps)+len(att)
    # and len(gps)+2 len(att) after the previous GPS line's start: fractions of the 200 ms step
    lg, la = len(_gps30(tows[0])), len(ATT30)
    frac = np.array([la, 2 * la]) / (lg + 2 * la)
    expect = [t + f * 200e6 for t in np.array(tows[:2]) * 10**6 for f in frac]
    np.testing.assert_allclose(log.attitude.t_ns, expect, atol=1)
    assert log.attitude.t_ns.size == 4  # before the first and after the last GPS record: dropped

    log = read_flight(p, mapping={"dataflash": {"gps_week": 1777}})
    assert log.position.clock == log.attitude.clock == "unix"
    assert log.position.t_ns[0] == gps_unix_ns(1777, tows[0])


def test_text_log_cut_mid_line_and_bad_text(tmp_path):
    p = tmp_path / "cut.log"
    text = _ac31()
    p.write_text(text[: len(text) - 30], newline="")
    log = read_flight(p)
    assert log.position.t_ns.size == 4
    assert any("truncated" in w for w in log.warnings)

    bad = tmp_path / "notes.log"
    bad.write_text("this is a ground station's chat log\nnothing else\n")
    with pytest.raises(LogReadError) as e:
        read_flight(bad)
    assert "notes.log" in str(e.value) and "\n" not in str(e.value) and "text DataFlash" in str(e.value)
