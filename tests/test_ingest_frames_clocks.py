"""Frame conversions and clock mapping against hand-computed values."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from pipeline.ingest.clocks import GPS_UTC_LEAP_S, map_clock, series_to_clock, unix_ns_from_gps
from pipeline.ingest.frames import gimbal_to_earth, quat_ned_frd_from_enu_flu, quat_ned_from_frd_euler
from pipeline.ingest.model import AttitudeSeries, ClockLink, GimbalSeries, PositionSeries


def test_euler_zyx_hand_values():
    # yaw 90 deg only: q = (cos 45, 0, 0, sin 45)
    s = math.sqrt(0.5)
    np.testing.assert_allclose(quat_ned_from_frd_euler(0, 0, math.pi / 2)[0], [s, 0, 0, s], atol=1e-12)
    # roll 0.2 rad only: q = (cos 0.1, sin 0.1, 0, 0)
    np.testing.assert_allclose(quat_ned_from_frd_euler(0.2, 0, 0)[0], [math.cos(0.1), math.sin(0.1), 0, 0],
                               atol=1e-12)
    # yaw 180: nose south; with the sign convention w >= 0
    np.testing.assert_allclose(quat_ned_from_frd_euler(0, 0, math.pi)[0], [0, 0, 0, 1], atol=1e-12)


def test_enu_flu_to_ned_frd_hand_values():
    s = math.sqrt(0.5)
    # ROS heading north, level: ENU yaw +90 deg -> NED identity
    np.testing.assert_allclose(quat_ned_frd_from_enu_flu(np.array([[s, 0, 0, s]]))[0], [1, 0, 0, 0], atol=1e-12)
    # ROS identity (facing east) -> NED yaw +90 deg
    np.testing.assert_allclose(quat_ned_frd_from_enu_flu(np.array([[1, 0, 0, 0]]))[0], [s, 0, 0, s], atol=1e-12)
    # heading north, right wing 10 deg down: intrinsic yaw 90 then +10 about the forward axis in FLU (left wing
    # up); x is shared by FLU and FRD, so it is +10 deg roll in NED/FRD too
    q_ros = Rotation.from_euler("ZX", [90, 10], degrees=True).as_quat(scalar_first=True)
    q = quat_ned_frd_from_enu_flu(q_ros[None])[0]
    np.testing.assert_allclose(Rotation.from_quat(q, scalar_first=True).as_euler("ZYX", degrees=True),
                               [0, 0, 10], atol=1e-9)


def test_gimbal_yaw_relative_to_vehicle():
    t = np.array([0, 10**9], np.int64)
    att = AttitudeSeries(t, quat_ned_from_frd_euler([0, 0], [0, 0], np.radians([80, 100])), clock="unix")
    g = GimbalSeries(np.array([5 * 10**8], np.int64), quat_ned_from_frd_euler(0, math.radians(-20), math.radians(10)),
                     np.array([True]), clock="unix")
    e = gimbal_to_earth(g, att)
    ypr = Rotation.from_quat(e.quat_wxyz[0], scalar_first=True).as_euler("ZYX", degrees=True)
    np.testing.assert_allclose(ypr, [100, -20, 0], atol=1e-9)  # vehicle yaw 90 (interpolated) + 10
    assert not e.yaw_in_vehicle_frame.any()


def test_gps_time_and_clock_map():
    assert GPS_UTC_LEAP_S == 18
    assert unix_ns_from_gps(0, 0)[()] == (315964800 - 18) * 10**9
    assert unix_ns_from_gps(2300, 123456)[()] == (315964800 + 2300 * 604800 - 18) * 10**9 + 123456 * 10**6
    # boot -> unix with 50 ppm drift and an outlier pair (time_unix_usec before the fix)
    a = np.arange(0, 100 * 10**9, 10**9, dtype=np.int64)
    b = 1_600_000_000 * 10**9 + a + (a * 50e-6).astype(np.int64)
    b[3] = 0
    link = ClockLink("boot", "unix", a, b)
    got = map_clock(np.array([20 * 10**9 + 123], np.int64), link)[0]
    assert abs(got - (1_600_000_000 * 10**9 + 20 * 10**9 + 123 + 1_000_000)) <= 2
    pos = PositionSeries(np.array([10**9, 2 * 10**9], np.int64), np.zeros(2), np.zeros(2), np.zeros(2), "amsl",
                         clock="boot")
    out = series_to_clock(pos, [link], "unix")
    assert out.clock == "unix" and out.t_ns[0] == pytest.approx(1_600_000_001 * 10**9 + 50_000, abs=2)
