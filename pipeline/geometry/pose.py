"""Camera and rangefinder poses of each frame in the common ENU frame, from what the vehicle logs.

Rotation chain (each a scipy Rotation, vectorised over n frames; `R_a_from_b` maps b-vectors into a):
  R_enu0_from_optical = R_enu0_from_ned(vehicle lat, lon) * R_ned_from_gimbal * R_gimbal_from_optical
where R_ned_from_gimbal is the gimbal quaternion itself when its yaw is earth-referenced, and
Rz(vehicle yaw) * quaternion when its yaw is relative to the vehicle's heading (MAVLink YAW_IN_VEHICLE_FRAME:
the quaternion is given in the vehicle-heading frame, whose yaw is the vehicle's). Lever arms (body FRD metres,
from the GNSS antenna) move the antenna position to the camera and the rangefinder:
  r_camera = r_antenna + R_enu0_from_ned * R_ned_from_body * lever_camera.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from pipeline.errors import GeometryError
from pipeline.geometry.camera import projection_matrix
from pipeline.geometry.frames import R_enu0_from_ned_at, enu_from_lla

# Gimbal FRD (x forward along the optical axis, y right, z down) -> camera optical (x right, y down, z forward).
R_OPTICAL_FROM_GIMBAL_DEFAULT = np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [1.0, 0.0, 0.0]])


def rotation_from_wxyz(quat_wxyz) -> Rotation:
    """scipy Rotation of n rotations from (n, 4) (or one (4,)) quaternions ordered w, x, y, z (normalised by
    scipy): the one conversion from the model's quaternion order."""
    return Rotation.from_quat(np.atleast_2d(np.asarray(quat_wxyz, dtype=np.float64))[..., [1, 2, 3, 0]])


def _valid_quaternions(quat_wxyz) -> np.ndarray:
    q = np.asarray(quat_wxyz, dtype=np.float64)
    if q.shape[-1] != 4 or not np.isfinite(q).all() or (np.linalg.norm(q, axis=-1) < 1e-9).any():
        raise GeometryError(f"quaternions must be finite non-zero (..., 4) arrays, got shape {q.shape}")
    return q


def vehicle_yaw_rad(R_ned_from_body: Rotation) -> np.ndarray:
    """(n,) heading (yaw of the ZYX yaw-pitch-roll sequence) of the vehicle, radians."""
    return R_ned_from_body.as_euler("ZYX")[..., 0]


def gimbal_in_ned(R_ned_from_body: Rotation, R_gimbal: Rotation, yaw_in_vehicle_frame) -> Rotation:
    """R_ned_from_gimbal for each frame: the gimbal rotation itself where its yaw is earth-referenced, composed
    with the vehicle's heading (Rz(yaw_vehicle) * R_gimbal) where `yaw_in_vehicle_frame` is True."""
    flag = np.broadcast_to(np.asarray(yaw_in_vehicle_frame, dtype=bool), (len(R_gimbal),))
    yaw = np.where(flag, vehicle_yaw_rad(R_ned_from_body), 0.0)
    return Rotation.from_euler("z", yaw[:, None]) * R_gimbal


@dataclass(frozen=True)
class FramePoses:
    """Per-frame poses in the ENU frame at `origin_lla` (metres):
    R_enu0_from_optical (n, 3, 3), camera_m (n, 3) camera centres, laser_m (n, 3) rangefinder origins,
    antenna_m (n, 3) GNSS antenna positions."""

    origin_lla: tuple[float, float, float]
    R_enu0_from_optical: np.ndarray
    camera_m: np.ndarray
    laser_m: np.ndarray
    antenna_m: np.ndarray

    @property
    def R_optical_from_enu0(self) -> np.ndarray:
        return np.swapaxes(self.R_enu0_from_optical, -1, -2)

    def projection_matrices(self, K: np.ndarray) -> np.ndarray:
        """(n, 3, 4) pinhole projection matrices P = K [R | -R c] (world = ENU at the origin)."""
        return projection_matrix(np.asarray(K, dtype=np.float64), self.R_optical_from_enu0, self.camera_m)

    def subset(self, keep: np.ndarray) -> FramePoses:
        """The poses of the frames selected by `keep` (a boolean mask or indices)."""
        return FramePoses(self.origin_lla, self.R_enu0_from_optical[keep], self.camera_m[keep], self.laser_m[keep],
                          self.antenna_m[keep])

    def optical_axis_enu(self) -> np.ndarray:
        """(n, 3) unit viewing directions (camera +z) in ENU."""
        return self.R_enu0_from_optical[..., :, 2]


def frame_poses(lat_deg, lon_deg, alt_m, body_quat_wxyz, gimbal_quat_wxyz, yaw_in_vehicle_frame,
                origin_lla: tuple[float, float, float], R_optical_from_gimbal=R_OPTICAL_FROM_GIMBAL_DEFAULT,
                lever_camera_m=(0.0, 0.0, 0.0), lever_rangefinder_m=(0.0, 0.0, 0.0)) -> FramePoses:
    """Poses of n frames from the vehicle state at the frame times.

    Args:
        lat_deg, lon_deg, alt_m: (n,) GNSS antenna position, WGS84, ellipsoid heights.
        body_quat_wxyz: (n, 4) body FRD -> local NED.  gimbal_quat_wxyz: (n, 4) gimbal FRD -> local NED (yaw
            earth-referenced, or vehicle-relative where yaw_in_vehicle_frame (n,) is True).
        R_optical_from_gimbal: (3, 3) camera mounting in the gimbal.  lever_*_m: (3,) body FRD metres.
    """
    lat = np.asarray(lat_deg, dtype=np.float64)
    lon = np.asarray(lon_deg, dtype=np.float64)
    R_body = rotation_from_wxyz(_valid_quaternions(body_quat_wxyz))
    R_gimbal = rotation_from_wxyz(_valid_quaternions(gimbal_quat_wxyz))
    n = lat.shape[0]
    if len(R_body) != n or len(R_gimbal) != n:
        raise GeometryError(f"pose inputs disagree in length: {n} positions, {len(R_body)} attitudes, "
                            f"{len(R_gimbal)} gimbal samples")
    M = np.asarray(R_optical_from_gimbal, dtype=np.float64)
    if M.shape != (3, 3) or not np.allclose(M @ M.T, np.eye(3), atol=1e-6) or np.linalg.det(M) < 0:
        raise GeometryError("R_optical_from_gimbal must be a proper 3x3 rotation matrix")
    R_enu0_from_ned = R_enu0_from_ned_at(lat, lon, origin_lla)  # (n, 3, 3)
    R_ned_from_gimbal = gimbal_in_ned(R_body, R_gimbal, yaw_in_vehicle_frame).as_matrix()
    R_enu0_from_optical = R_enu0_from_ned @ R_ned_from_gimbal @ M.T
    antenna = enu_from_lla(lat, lon, alt_m, origin_lla)
    R_enu0_from_body = R_enu0_from_ned @ R_body.as_matrix()
    camera = antenna + R_enu0_from_body @ np.asarray(lever_camera_m, dtype=np.float64)
    laser = antenna + R_enu0_from_body @ np.asarray(lever_rangefinder_m, dtype=np.float64)
    return FramePoses(origin_lla=tuple(origin_lla), R_enu0_from_optical=R_enu0_from_optical, camera_m=camera,
                      laser_m=laser, antenna_m=antenna)
