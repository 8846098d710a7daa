"""Interpolation of time series at query times (int64 ns on one clock): linear for positions, Slerp for
attitudes, nearest-within-tolerance for discrete samples. Times are taken relative to the first sample before
conversion to float, so nanosecond UNIX stamps keep their precision."""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation, Slerp

from pipeline.errors import InputError


def _inside(t_src: np.ndarray, t_ns: np.ndarray) -> np.ndarray:
    return (t_ns >= t_src[0]) & (t_ns <= t_src[-1])


def interpolate_linear(t_src_ns: np.ndarray, values: np.ndarray, t_ns: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Values (m, k) at times t_ns (m,) from samples (n,) / (n, k), linearly; returns (values, inside) where
    inside (m,) is False for queries outside the sampled span (those rows are NaN, never extrapolated)."""
    t_src = np.asarray(t_src_ns, dtype=np.int64)
    t = np.asarray(t_ns, dtype=np.int64)
    v = np.asarray(values, dtype=np.float64)
    v2 = v.reshape(len(t_src), -1)
    if t_src.size == 0:
        raise InputError("cannot interpolate an empty series")
    inside = _inside(t_src, t)
    x_src = (t_src - t_src[0]).astype(np.float64)
    x = (t - t_src[0]).astype(np.float64)
    out = np.stack([np.interp(x, x_src, col) for col in v2.T], axis=-1)
    out[~inside] = np.nan
    return out.reshape((len(t), *v.shape[1:])), inside


def interpolate_rotations(t_src_ns: np.ndarray, quat_wxyz: np.ndarray,
                          t_ns: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Quaternions (m, 4) w, x, y, z at t_ns (m,) by Slerp between samples (n, 4); returns (quat, inside) with
    NaN rows for queries outside the sampled span."""
    t_src = np.asarray(t_src_ns, dtype=np.int64)
    t = np.asarray(t_ns, dtype=np.int64)
    q = np.asarray(quat_wxyz, dtype=np.float64)
    if t_src.size == 0:
        raise InputError("cannot interpolate an empty attitude series")
    inside = _inside(t_src, t)
    out = np.full((len(t), 4), np.nan)
    if inside.any():
        if t_src.size == 1:
            out[inside] = q[0]
        else:
            keep = np.r_[True, np.diff(t_src) > 0]  # Slerp needs strictly increasing times
            rots = Rotation.from_quat(q[keep][:, [1, 2, 3, 0]])
            slerp = Slerp((t_src[keep] - t_src[0]).astype(np.float64), rots)
            xyzw = slerp((t[inside] - t_src[0]).astype(np.float64)).as_quat()
            out[inside] = xyzw[:, [3, 0, 1, 2]]
    return out, inside


def nearest_within(t_src_ns: np.ndarray, t_ns: np.ndarray, tolerance_ns: int) -> np.ndarray:
    """(m,) index of the source sample nearest each query time, or -1 where none lies within tolerance_ns."""
    t_src = np.asarray(t_src_ns, dtype=np.int64)
    t = np.asarray(t_ns, dtype=np.int64)
    if t_src.size == 0:
        return np.full(t.shape, -1, dtype=np.int64)
    j = np.clip(np.searchsorted(t_src, t), 1, max(t_src.size - 1, 1))
    left = np.clip(j - 1, 0, t_src.size - 1)
    right = np.clip(j, 0, t_src.size - 1)
    pick = np.where(np.abs(t - t_src[left]) <= np.abs(t_src[right] - t), left, right)
    return np.where(np.abs(t_src[pick] - t) <= tolerance_ns, pick, -1).astype(np.int64)
