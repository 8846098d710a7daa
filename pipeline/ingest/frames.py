"""Attitude conventions -> the model's quaternions (w, x, y, z) rotating body/gimbal FRD into local level NED.

- MAVLink ATTITUDE, DataFlash ATT/MNT, MOUNT_STATUS, DJI: ZYX (yaw, pitch, roll) Euler angles of FRD vs NED:
  R_ned_from_frd = Rz(yaw) @ Ry(pitch) @ Rx(roll) = Rotation.from_euler("ZYX", [yaw, pitch, roll]).
- ROS (REP-103): orientation rotates body FLU into local ENU; q_ned_from_frd = R_ned_from_enu * q_enu_from_flu *
  R_flu_from_frd, both fixed rotations.
- Any orientation named `<body>_<world>` (ORIENTATION_FRAMES: body frd, flu or optical = REP-103 `_optical`, x right,
  y down, z forward; world ned or enu) is converted the same way: q_ned_from_frd = R_ned_from_world * q *
  R_body_from_frd (`quat_ned_frd_from_frame`; `frame_quat_from_ned_frd` is its inverse).
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation, Slerp

from pipeline.geometry.frames import R_ENU_FROM_NED
from pipeline.geometry.pose import R_OPTICAL_FROM_GIMBAL_DEFAULT, gimbal_in_ned
from pipeline.geometry.pose import rotation_from_wxyz as rotation_from_quat_wxyz

R_NED_FROM_ENU = Rotation.from_matrix(R_ENU_FROM_NED.T)
R_FLU_FROM_FRD = Rotation.from_matrix([[1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, -1.0]])
# Camera optical (REP-103 `_optical`: x right, y down, z forward) from gimbal FRD (x forward, y right, z down).
R_OPTICAL_FROM_FRD = Rotation.from_matrix(R_OPTICAL_FROM_GIMBAL_DEFAULT)
_BODY = {"frd": Rotation.identity(), "flu": R_FLU_FROM_FRD, "optical": R_OPTICAL_FROM_FRD}
_WORLD = {"ned": Rotation.identity(), "enu": R_NED_FROM_ENU}
ORIENTATION_FRAMES = tuple(f"{b}_{w}" for b in _BODY for w in _WORLD)  # frd_ned, frd_enu, flu_ned, flu_enu, ...
QUAT_ORDERS = ("wxyz", "xyzw")


def quat_wxyz_from_rotation(rot: Rotation) -> np.ndarray:
    """(n, 4) w, x, y, z with w >= 0 (one sign per rotation, so series stay comparable)."""
    q = np.atleast_2d(rot.as_quat(scalar_first=True))
    return np.where(q[:, :1] < 0, -q, q)


def quat_ned_from_frd_euler(roll_rad, pitch_rad, yaw_rad) -> np.ndarray:
    """ZYX Euler angles (rad) of FRD vs NED -> (n, 4) quaternion w, x, y, z (FRD -> NED)."""
    angles = np.column_stack([np.asarray(yaw_rad, float).ravel(), np.asarray(pitch_rad, float).ravel(),
                              np.asarray(roll_rad, float).ravel()])
    return quat_wxyz_from_rotation(Rotation.from_euler("ZYX", angles))


def quat_ned_frd_from_enu_flu(q_enu_from_flu_wxyz: np.ndarray) -> np.ndarray:
    """ROS orientation (FLU -> ENU, w, x, y, z) -> (n, 4) FRD -> NED, w, x, y, z."""
    rot = R_NED_FROM_ENU * rotation_from_quat_wxyz(q_enu_from_flu_wxyz) * R_FLU_FROM_FRD
    return quat_wxyz_from_rotation(rot)


def _frame_parts(frame: str) -> tuple[Rotation, Rotation]:
    body, _, world = frame.partition("_")
    if body not in _BODY or world not in _WORLD:
        raise ValueError(f"unknown orientation frame {frame!r} (known: {', '.join(ORIENTATION_FRAMES)})")
    return _WORLD[world], _BODY[body]


def quat_ned_frd_from_frame(q_wxyz: np.ndarray, frame: str) -> np.ndarray:
    """(n, 4) quaternions (w, x, y, z) rotating `frame`'s body axes into its world axes (e.g. "optical_enu": a
    camera optical frame -> ENU) -> (n, 4) FRD -> NED, w, x, y, z. ValueError for an unknown frame name."""
    A, B = _frame_parts(frame)
    return quat_wxyz_from_rotation(A * rotation_from_quat_wxyz(q_wxyz) * B)


def frame_quat_from_ned_frd(q_wxyz: np.ndarray, frame: str) -> np.ndarray:
    """Inverse of quat_ned_frd_from_frame: FRD -> NED quaternions expressed in `frame` (w, x, y, z)."""
    A, B = _frame_parts(frame)
    return quat_wxyz_from_rotation(A.inv() * rotation_from_quat_wxyz(q_wxyz) * B.inv())


def quat_wxyz_from_order(q: np.ndarray, order: str) -> np.ndarray:
    """(n, 4) quaternions stored in `order` ("wxyz" scalar first, "xyzw" scalar last) -> w, x, y, z."""
    if order not in QUAT_ORDERS:
        raise ValueError(f"unknown quaternion order {order!r} (known: {', '.join(QUAT_ORDERS)})")
    q = np.asarray(q, dtype=np.float64)
    return q if order == "wxyz" else q[..., [3, 0, 1, 2]]


def euler_zyx_from_quat_wxyz(q_wxyz: np.ndarray) -> np.ndarray:
    """(n, 4) FRD -> NED quaternions -> (n, 3) roll, pitch, yaw in rad (ZYX)."""
    ypr = rotation_from_quat_wxyz(q_wxyz).as_euler("ZYX")
    return ypr[:, ::-1]


def gimbal_to_earth(gimbal, attitude):
    """GimbalSeries with yaw relative to the vehicle heading (per-sample flag) -> all earth-referenced.

    For flagged samples the quaternion is expressed in the vehicle's heading frame (NED turned by the vehicle
    yaw): q_ned_from_gimbal = Rz(vehicle_yaw(t)) * q. Vehicle yaw is interpolated (Slerp) at the gimbal times;
    samples outside the attitude span are clamped to its ends. Both series must be on the same clock.
    """
    from pipeline.ingest.model import GimbalSeries

    flag = np.asarray(gimbal.yaw_in_vehicle_frame, bool)
    if not flag.any():
        return gimbal
    if attitude is None or attitude.t_ns.size == 0:
        from pipeline.errors import InputError
        raise InputError(f"gimbal series {gimbal.source!r}: yaw is relative to the vehicle, but there is no "
                         "vehicle attitude to refer it to the earth")
    t_att = attitude.t_ns
    t = np.clip(gimbal.t_ns[flag], t_att[0], t_att[-1])
    rots = rotation_from_quat_wxyz(attitude.quat_wxyz)
    if t_att.size == 1:
        body = rots[np.zeros(t.size, dtype=int)]
    else:
        body = Slerp((t_att - t_att[0]).astype(float), rots)((t - t_att[0]).astype(float))
    q = gimbal.quat_wxyz.copy()
    q[flag] = quat_wxyz_from_rotation(gimbal_in_ned(body, rotation_from_quat_wxyz(q[flag]), True))
    return GimbalSeries(gimbal.t_ns, q, np.zeros_like(flag), source=gimbal.source, clock=gimbal.clock)
