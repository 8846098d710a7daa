"""Lens distortion (OpenCV model k1, k2, p1, p2, k3): image pixels <-> ideal pinhole pixels of the same K."""

from __future__ import annotations

import cv2
import numpy as np


def undistort_pixels(pixel_px, K: np.ndarray, dist) -> np.ndarray:
    """(n, 2) pinhole pixels of (n, 2) distorted image pixels (NaN rows stay NaN), so P = K [R | t] applies.
    K: (3, 3), or (n, 3, 3) per frame."""
    px = np.asarray(pixel_px, dtype=np.float64).reshape(-1, 2)
    out = np.full_like(px, np.nan)
    ok = np.isfinite(px).all(axis=1)
    d = np.asarray(dist, dtype=np.float64).ravel()
    K = np.asarray(K, dtype=np.float64)
    if K.ndim == 3 and d.any():  # one K per frame: OpenCV takes one camera per call
        for i in np.flatnonzero(ok):
            out[i] = undistort_pixels(px[i:i + 1], K[i], d)[0]
        return out
    if ok.any():
        if not d.any():
            out[ok] = px[ok]
        else:
            und = cv2.undistortPoints(px[ok].reshape(-1, 1, 2), K, d, None, None, K,
                                          (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 50, 1e-10))
            out[ok] = und.reshape(-1, 2)
    return out


def distort_pixels(pixel_px, K: np.ndarray, dist) -> np.ndarray:
    """(n, 2) image pixels that the lens makes of (n, 2) ideal pinhole pixels (the inverse of undistort_pixels)."""
    px = np.asarray(pixel_px, dtype=np.float64).reshape(-1, 2)
    Kinv = np.linalg.inv(K)
    rays = (np.c_[px, np.ones(len(px))] @ Kinv.T)  # normalised camera rays, z = 1
    img, _ = cv2.projectPoints(rays.reshape(-1, 1, 3), np.zeros(3), np.zeros(3), K,
                               np.asarray(dist, dtype=np.float64).ravel())
    return img.reshape(-1, 2)
