import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from pipeline.errors import GeometryError
from pipeline.geometry.camera import intrinsics_matrix, project
from pipeline.geometry.pose import frame_poses

ORIGIN = (30.0, 114.0, 0.0)
K = intrinsics_matrix(1000.0, 1000.0, 300.0, 200.0)


def _wxyz(yaw_deg, pitch_deg, roll_deg):
    q = Rotation.from_euler("ZYX", [yaw_deg, pitch_deg, roll_deg], degrees=True).as_quat()
    return np.r_[q[3], q[:3]][None, :]


def _poses(body, gimbal, yaw_in_vehicle=False, **kw):
    return frame_poses([ORIGIN[0]], [ORIGIN[1]], [ORIGIN[2]], body, gimbal, [yaw_in_vehicle], ORIGIN, **kw)


def test_level_vehicle_north_gimbal_down_30_looks_north_and_below():
    p = _poses(_wxyz(0, 0, 0), _wxyz(0, -30, 0))
    c, s = math.cos(math.radians(30)), math.sin(math.radians(30))
    np.testing.assert_allclose(p.optical_axis_enu()[0], [0.0, c, -s], atol=1e-12)
    # image x (right) points east, image y (down) is below the axis, towards the ground ahead
    np.testing.assert_allclose(p.R_enu0_from_optical[0][:, 0], [1.0, 0.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(p.R_enu0_from_optical[0][:, 1], [0.0, -s, -c], atol=1e-12)
    P = p.projection_matrices(K)[0]
    on_axis = 1000.0 * np.array([0.0, c, -s])
    np.testing.assert_allclose(project(P, on_axis), [300.0, 200.0], atol=1e-9)
    # 10 m east of a point 1000 m down the axis: u = cx + fx * 10 / 1000
    np.testing.assert_allclose(project(P, on_axis + np.array([10.0, 0, 0])), [310.0, 200.0], atol=1e-9)
    # 10 m along image-down (i.e. towards the ground ahead): v = cy + fy * 10 / 1000
    np.testing.assert_allclose(project(P, on_axis + 10.0 * np.array([0.0, -s, -c])), [300.0, 210.0], atol=1e-9)


def test_gimbal_yaw_relative_to_vehicle_heading_is_added_to_it():
    body = _wxyz(90, 0, 0)  # heading east
    gimbal = _wxyz(0, -30, 0)
    c, s = math.cos(math.radians(30)), math.sin(math.radians(30))
    earth = _poses(body, gimbal, yaw_in_vehicle=False)
    np.testing.assert_allclose(earth.optical_axis_enu()[0], [0.0, c, -s], atol=1e-12)  # still north
    rel = _poses(body, gimbal, yaw_in_vehicle=True)
    np.testing.assert_allclose(rel.optical_axis_enu()[0], [c, 0.0, -s], atol=1e-12)  # east, like the vehicle
    rel2 = _poses(_wxyz(90, 5, 3), _wxyz(-90, -30, 0), yaw_in_vehicle=True)  # 90 - 90: north again
    np.testing.assert_allclose(rel2.optical_axis_enu()[0], [0.0, c, -s], atol=1e-12)


def test_lever_arms_rotate_with_the_body():
    body = _wxyz(90, 0, 0)  # heading east: body forward = east, right = south, down = down
    p = _poses(body, _wxyz(0, -30, 0), lever_camera_m=[1.0, 0.0, 0.0], lever_rangefinder_m=[0.0, 2.0, 0.5])
    np.testing.assert_allclose(p.antenna_m[0], [0, 0, 0], atol=1e-6)
    np.testing.assert_allclose(p.camera_m[0], [1.0, 0.0, 0.0], atol=1e-6)
    np.testing.assert_allclose(p.laser_m[0], [0.0, -2.0, -0.5], atol=1e-6)


def test_camera_mounting_rotation_is_applied():
    # A mount rolled 90 deg about the optical axis swaps image right/down.
    mount = np.array([[0.0, 0.0, 1.0], [0.0, -1.0, 0.0], [1.0, 0.0, 0.0]])  # x_opt = gimbal down, y_opt = left
    p = _poses(_wxyz(0, 0, 0), _wxyz(0, 0, 0), R_optical_from_gimbal=mount)
    np.testing.assert_allclose(p.R_enu0_from_optical[0][:, 0], [0.0, 0.0, -1.0], atol=1e-12)  # image right = down
    np.testing.assert_allclose(p.optical_axis_enu()[0], [0.0, 1.0, 0.0], atol=1e-12)


def test_vectorised_over_frames_and_rejects_bad_input():
    n = 5
    lat = np.full(n, ORIGIN[0])
    lon = ORIGIN[1] + np.linspace(0, 0.05, n)
    q = np.tile(_wxyz(0, 0, 0), (n, 1))
    g = np.tile(_wxyz(0, -45, 0), (n, 1))
    p = frame_poses(lat, lon, np.full(n, 1000.0), q, g, np.zeros(n, bool), ORIGIN)
    assert p.projection_matrices(K).shape == (n, 3, 4)
    # farther east the local down tilts west-wards in ENU0: axis east component grows negative
    assert (np.diff(p.optical_axis_enu()[:, 0]) < 0).all()
    with pytest.raises(GeometryError):
        frame_poses(lat, lon, np.full(n, 1000.0), q[:3], g, np.zeros(n, bool), ORIGIN)
    with pytest.raises(GeometryError):
        frame_poses(lat, lon, np.full(n, 1000.0), q, g, np.zeros(n, bool), ORIGIN, R_optical_from_gimbal=2 * np.eye(3))
