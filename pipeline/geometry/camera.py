"""Pinhole camera: intrinsics, projection matrices, and pointing a camera at a target.

Camera frame convention (OpenCV / ROS `_optical`): x right, y down, z forward along the optical axis.
`R_cam_from_world` rotates world vectors into the camera frame; the camera centre is in world metres.
"""

from __future__ import annotations

import numpy as np

from pipeline.errors import GeometryError


def intrinsics_matrix(fx_px: float, fy_px: float, cx_px: float, cy_px: float) -> np.ndarray:
    """(3, 3) camera matrix K."""
    return np.array([[fx_px, 0.0, cx_px], [0.0, fy_px, cy_px], [0.0, 0.0, 1.0]])


def projection_matrix(K: np.ndarray, R_cam_from_world: np.ndarray, centre_m: np.ndarray) -> np.ndarray:
    """P = K [R | -R c], shape (..., 3, 4) for broadcastable (..., 3, 3) R and (..., 3) centres; K (3, 3) or
    (..., 3, 3) per camera (a zoom lens)."""
    R = np.asarray(R_cam_from_world, dtype=np.float64)
    c = np.asarray(centre_m, dtype=np.float64)
    t = -np.einsum("...ij,...j->...i", R, c)
    Rt = np.concatenate([R, t[..., None]], axis=-1)
    return np.einsum("...ij,...jk->...ik", np.asarray(K, dtype=np.float64), Rt)


def project(P: np.ndarray, X_m: np.ndarray) -> np.ndarray:
    """Pixels (..., 2) of world points X_m (..., 3) through P (..., 3, 4)."""
    Xh = np.concatenate([X_m, np.ones((*X_m.shape[:-1], 1))], axis=-1)
    x = np.einsum("...ij,...j->...i", P, Xh)
    return x[..., :2] / x[..., 2:3]


def look_at_rotation(centre_m: np.ndarray, target_m: np.ndarray, up_world=(0.0, 0.0, 1.0)) -> np.ndarray:
    """R_cam_from_world (..., 3, 3) of a camera at centre_m whose optical axis points at target_m, with
    image 'down' (camera +y) as close as possible to world -up (no roll). Broadcasts over leading axes."""
    centre = np.asarray(centre_m, dtype=np.float64)
    target = np.asarray(target_m, dtype=np.float64)
    z = target - centre
    norm = np.linalg.norm(z, axis=-1, keepdims=True)
    if (norm == 0).any():
        raise GeometryError("camera centre coincides with the target")
    z = z / norm
    up = np.broadcast_to(np.asarray(up_world, dtype=np.float64), z.shape)
    x = np.cross(z, up)  # right = forward x up
    xn = np.linalg.norm(x, axis=-1, keepdims=True)
    if (xn < 1e-12).any():
        raise GeometryError("look-at direction is parallel to 'up'; roll is undefined")
    x = x / xn
    y = np.cross(z, x)  # down
    return np.stack([x, y, z], axis=-2)
