"""Lines of sight: where n rays meet (least squares) and the angle between the first and last of them."""

from __future__ import annotations

import math

import numpy as np


def camera_rays_m(P: np.ndarray, pixel: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Camera centres C = -M^-1 p4 (n, 3) and unit directions (n, 3) through the pixels (n, 2) of 3x4 cameras
    P (n, 3, 4), in P's world frame (NaN rows where a pixel is NaN). The direction sign(det M) M^-1 [u, v, 1]
    points in front of the camera."""
    M, p4 = P[:, :, :3], P[:, :, 3]
    C = -np.linalg.solve(M, p4[..., None])[..., 0]
    xh = np.concatenate([pixel, np.ones((pixel.shape[0], 1))], axis=1)
    a = np.linalg.solve(M, xh[..., None])[..., 0] * np.where(np.linalg.det(M) < 0, -1.0, 1.0)[:, None]
    return C, a / np.linalg.norm(a, axis=1, keepdims=True)


def meeting_point(origins: np.ndarray, dirs: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(X (3,), miss distances (n,), covariance scale N^-1 (3, 3)) of the rays' least-squares meeting point,
    with one Cauchy-like reweighting pass so that a few stray rays do not drag it. NaN when the rays are parallel.
    origins, dirs: (n, 3), dirs unit vectors."""
    o, d = np.asarray(origins, float), np.asarray(dirs, float)
    proj = np.eye(3) - d[:, :, None] * d[:, None, :]  # (n, 3, 3) projectors orthogonal to each ray
    w = np.ones(len(o))
    X = np.full(3, np.nan)
    Ninv = np.full((3, 3), np.nan)
    for _ in range(3):
        N = np.einsum("i,ijk->jk", w, proj)
        b = np.einsum("i,ijk,ik->j", w, proj, o)
        if np.linalg.cond(N) > 1e12:
            return X, np.full(len(o), np.nan), Ninv
        X = np.linalg.solve(N, b)
        miss = np.linalg.norm(np.einsum("ijk,ik->ij", proj, X - o), axis=1)
        scale = max(float(np.median(miss)), 1e-6) * 3.0
        w = 1.0 / (1.0 + (miss / scale) ** 2)
        Ninv = np.linalg.inv(N)
    return X, miss, Ninv


def intersection_angle_deg(platform_m: np.ndarray, target_m: np.ndarray) -> float:
    """Angle between the first and last lines of sight from platform_m (n, 3) to target_m (3,) (the paper's
    gamma), degrees."""
    u = np.asarray(target_m, dtype=np.float64) - np.asarray(platform_m, dtype=np.float64)[[0, -1]]
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    return math.degrees(math.acos(float(np.clip(u[0] @ u[1], -1.0, 1.0))))
