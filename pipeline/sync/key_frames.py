"""Observations at key frames: each laser shot's observation moved to the nearest key frame, with the range
interpolated at that frame's time.

A key frame decodes on its own; any other frame of a compressed video costs the frames of its group of pictures
before it (half a group on average). Where key frames come about as often as the laser fires, observing at them
decodes one frame per observation instead of half a group, and the pose is interpolated at the frame's own time
as for any frame (`pipeline.sync.assemble.frame_states`). The laser's range is not measured at that time: it is
interpolated linearly between the valid shots just before and just after it, which costs

    e = |r''| (t - t1) (t2 - t) / 2      (at most |r''| h^2 / 8 for shots h apart)

where r'' is the range's second derivative, here estimated from the range's own shots (a quadratic fitted to
the nearest CURVATURE_SHOTS valid shots), and t1 < t < t2 the shots' times. The same fits give the range's scatter
about a smooth curve (its noise); `pipeline.sync.select` uses both to decide whether to observe at key frames.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

NS_PER_S = 10**9
CURVATURE_SHOTS = 7  # valid shots per local quadratic fit (3 each side): the curvature's noise 0.22 sigma / h^2


@dataclass(frozen=True)
class KeyFramePlan:
    """m observations at key frames: frame_pos (m,) positions in the frame arrays, shot (m,) the laser shot each
    stands for (index into the range series), range_m (m,) interpolated at the frame's time (NaN: no valid shots
    around it within the gap), range_error_m (m,) the interpolation's estimated error (NaN where no range or no
    curvature estimate), noise_m the range's scatter about its local quadratic fits (median; NaN when too few
    shots)."""

    frame_pos: np.ndarray
    shot: np.ndarray
    range_m: np.ndarray
    range_error_m: np.ndarray
    noise_m: float


def interpolate_ranges(t_shots_ns: np.ndarray, range_m: np.ndarray, t_ns: np.ndarray, max_gap_ns: int
                       ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Ranges at times t_ns (m,) by linear interpolation between the samples (n,) just before and just after each
    (a sample at the time itself is taken as it is), NaN where either is missing or they are more than max_gap_ns
    apart. Returns (range (m,), time to the sample before (m,) s, time to the sample after (m,) s)."""
    t_src = np.asarray(t_shots_ns, dtype=np.int64)
    r = np.asarray(range_m, dtype=np.float64)
    t = np.asarray(t_ns, dtype=np.int64)
    out = np.full(t.shape, np.nan)
    before = np.full(t.shape, np.nan)
    after = np.full(t.shape, np.nan)
    if t_src.size == 0:
        return out, before, after
    j = np.searchsorted(t_src, t, side="right")  # t_src[j-1] <= t < t_src[j]
    exact = (j > 0) & (t_src[np.maximum(j - 1, 0)] == t)
    out[exact] = r[j[exact] - 1]
    before[exact] = after[exact] = 0.0
    k = ~exact & (j > 0) & (j < t_src.size)
    t1, t2 = t_src[j[k] - 1], t_src[np.minimum(j[k], t_src.size - 1)]
    ok = (t2 - t1) <= max_gap_ns
    rows = np.flatnonzero(k)[ok]
    t1, t2 = t1[ok], t2[ok]
    w = (t[rows] - t1) / (t2 - t1)
    out[rows] = (1 - w) * r[j[rows] - 1] + w * r[j[rows]]
    before[rows] = (t[rows] - t1) / NS_PER_S
    after[rows] = (t2 - t[rows]) / NS_PER_S
    return out, before, after


def range_curvature(t_shots_ns: np.ndarray, range_m: np.ndarray, t_ns: np.ndarray,
                    n_shots: int = CURVATURE_SHOTS) -> tuple[np.ndarray, np.ndarray]:
    """(r'' (m,) m/s^2, residual rms (m,) m) at times t_ns from a quadratic in time fitted by least squares to
    the n_shots samples nearest each time (a window of consecutive samples around it); NaN when there are fewer
    than 5 samples."""
    t_src = np.asarray(t_shots_ns, dtype=np.int64)
    r = np.asarray(range_m, dtype=np.float64)
    t = np.asarray(t_ns, dtype=np.int64)
    m, n = t.size, t_src.size
    if n < 5:
        return np.full(m, np.nan), np.full(m, np.nan)
    k = min(n_shots, n)
    start = np.clip(np.searchsorted(t_src, t) - k // 2, 0, n - k)
    idx = start[:, None] + np.arange(k)[None, :]  # (m, k)
    dt = (t_src[idx] - t[:, None]) / NS_PER_S
    A = np.stack([np.ones_like(dt), dt, dt * dt], axis=-1)  # (m, k, 3)
    y = r[idx]
    AtA = np.einsum("mki,mkj->mij", A, A)
    Aty = np.einsum("mki,mk->mi", A, y)
    coef = np.linalg.solve(AtA, Aty[..., None])[..., 0]
    resid = y - np.einsum("mki,mi->mk", A, coef)
    rms = np.sqrt(np.sum(resid * resid, axis=1) / (k - 3))
    return 2.0 * coef[:, 2], rms


def key_frame_observations(t_frames_ns: np.ndarray, keyframe: np.ndarray, t_shots_ns: np.ndarray,
                           usable: np.ndarray, range_m: np.ndarray, *, tolerance_ns: int,
                           max_gap_ns: int) -> KeyFramePlan:
    """Each laser shot (n,) (times on the frames' clock, in time order; `usable` (n,) the valid ones) paired with
    the nearest key frame within tolerance_ns that no earlier shot took, preferring frames with a valid shot on
    each side within max_gap_ns; the range interpolated at the frame's time from the valid shots (see the module
    docstring). t_frames_ns (f,) sorted, keyframe (f,) bool."""
    t_frames = np.asarray(t_frames_ns, dtype=np.int64)
    keys = np.flatnonzero(np.asarray(keyframe, dtype=bool))
    t_keys = t_frames[keys]
    ok = np.asarray(usable, dtype=bool)
    t_ok = np.asarray(t_shots_ns, dtype=np.int64)[ok]
    r_ok = np.asarray(range_m, dtype=np.float64)[ok]
    r_key, before, after = interpolate_ranges(t_ok, r_ok, t_keys, max_gap_ns)
    ranged = np.isfinite(r_key)
    taken = np.zeros(keys.size, dtype=bool)
    pos, shot = [], []
    for s, ts in enumerate(np.asarray(t_shots_ns, dtype=np.int64).tolist()):
        lo = int(np.searchsorted(t_keys, ts - tolerance_ns, side="left"))
        hi = int(np.searchsorted(t_keys, ts + tolerance_ns, side="right"))
        best = None
        for c in range(lo, hi):
            if taken[c]:
                continue
            score = (not ranged[c], abs(int(t_keys[c]) - ts), c)  # ranged first, then nearest, then earlier
            if best is None or score < best[0]:
                best = (score, c)
        if best is not None:
            taken[best[1]] = True
            pos.append(best[1])
            shot.append(s)
    c = np.asarray(pos, dtype=np.int64)
    order = np.argsort(keys[c], kind="stable")
    c, shot = c[order], np.asarray(shot, dtype=np.int64)[order]
    curvature, rms = range_curvature(t_ok, r_ok, t_keys[c])
    error = np.abs(curvature) * before[c] * after[c] / 2.0
    noise = float(np.nanmedian(rms)) if np.isfinite(rms).any() else float("nan")
    return KeyFramePlan(frame_pos=keys[c], shot=shot, range_m=r_key[c], range_error_m=error, noise_m=noise)


def frames_to_decode(frame_pos: np.ndarray, keyframe: np.ndarray) -> int:
    """How many frames a reader decodes to get the frames at positions frame_pos: each from the key frame at or
    before it, the frames of one group of pictures decoded on in one pass."""
    keys = np.flatnonzero(np.asarray(keyframe, dtype=bool))
    if keys.size == 0 or keys[0] != 0:
        keys = np.r_[0, keys]
    p = np.unique(np.asarray(frame_pos, dtype=np.int64))
    if p.size == 0:
        return 0
    group = keys[np.searchsorted(keys, p, side="right") - 1]
    last = {}
    for g, q in zip(group.tolist(), p.tolist(), strict=True):
        last[g] = max(last.get(g, q), q)
    return int(sum(q - g + 1 for g, q in last.items()))
