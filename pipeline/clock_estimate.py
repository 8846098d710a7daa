"""The video-to-telemetry clock offset estimated from the flight itself.

A gimbal that tracks a target keeps pointing at it whatever the time, so poses taken at a wrong time still point
roughly at the target: the offset shows only in what the gimbal does not follow, its lag and jitter, against
the tracked pixel. For each candidate offset delta (added to the configured one) the target's meeting point X is
projected through the poses at the shifted frame times and compared with the tracked pixels, frame to frame
within groups of nearby frames (a burst, or a window around each observation):

    e_i(delta) = u_i - proj_i(delta),    cost(delta) = sum over successive frames i, i+1 of a group ||e_{i+1} - e_i||^2.

Differencing removes what varies slowly (the attitude errors' bias, the error of X) and whitens an attitude error
that wanders like a random walk over a burst, which would otherwise mimic the gimbal's jitter and bias the offset.

The estimate is the minimum over a grid (10 ms steps over +-search_s, then 1 ms steps near the best). Its 95 %
interval is the wider of the profile-likelihood set {delta: cost(delta) - cost_min <= 3.84 s^2} (s^2 = cost_min /
dof, the frame-to-frame steps independent) the 2.5-97.5 % range of a bootstrap over the groups (groups drawn
with replacement, the argmin of each resampled total) and a jackknife over the groups (Student's t), which hold
where the steps are not independent but the groups are (with few groups each alone under-covers). When the
interval reaches the window's edge the offset is not determined by the data (a gimbal with no jitter, too few
groups), and the estimate is not used.

The range source's offset is not estimated: the ranges would show it only through the platform's motion
towards or away from the target, which an orbit around it hardly has, and there the meeting point's error of
tens of metres (a range-rate error of a fraction of a metre per second) decides the answer: tried on the sample
flights, it gave offsets of -0.5 and -1.1 s with intervals excluding the true 0.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np
from scipy.special import stdtrit  # Student's t.ppf bit for bit, without importing scipy.stats

from pipeline.flight import Flight, TargetMark
from pipeline.geometry.lens import undistort_pixels
from pipeline.geometry.rays import meeting_point

CHI2_95_1DOF = 3.841
GROUP_HALF_WINDOW_S = 0.4  # frames within this of an observation form its group (continuous video)
MAX_FRAMES_PER_GROUP = 11
BOOTSTRAP = 400


@dataclass(frozen=True)
class OffsetEstimate:
    """delta_s: the estimated correction to the configured offset (seconds; the estimated offset is the configured
    one plus delta_s); low_s / high_s its 95 % interval; determined: the interval is inside the search window;
    n: frames used; rms: the misfit at the estimate (px); window_s the search half-width."""

    source: str
    configured_s: float
    delta_s: float
    low_s: float
    high_s: float
    determined: bool
    n: int
    rms: float
    window_s: float

    @property
    def offset_s(self) -> float:
        return self.configured_s + self.delta_s

    def to_dict(self) -> dict:
        return {"source": self.source, "configured_s": self.configured_s, "estimated_s": self.offset_s,
                "delta_s": self.delta_s, "ci95_s": [self.configured_s + self.low_s, self.configured_s + self.high_s],
                "ci95_delta_s": [self.low_s, self.high_s], "determined": self.determined, "n": self.n,
                "rms": self.rms, "search_s": self.window_s}

    def describe(self) -> str:
        what = "video-to-telemetry offset" if self.source == "video" else f"{self.source} offset"
        if not self.determined:
            return (f"{what}: not determined by the data within +-{self.window_s:g} s of the configured "
                    f"{self.configured_s:.3f} s ({self.n} samples)")
        return (f"{what}: {self.offset_s:.3f} s = configured {self.delta_s * 1000:+.0f} ms, 95 % "
                f"[{self.low_s * 1000:+.0f}, {self.high_s * 1000:+.0f}] ms ({self.n} samples, misfit "
                f"{self.rms:.2f} px rms)")


@dataclass(frozen=True)
class ClockEstimate:
    """The video offset's estimate (None: too few tracked frames). The range source's offset is not estimated
    (see the module docstring)."""

    video: OffsetEstimate | None

    def to_dict(self) -> dict:
        return {"video": None if self.video is None else self.video.to_dict(), "range": None}

    def describe(self) -> str:
        return self.video.describe() if self.video is not None else "video offset: too few tracked frames"


def estimation_frames(r: Flight) -> tuple[np.ndarray, np.ndarray]:
    """(frame positions in r.frames, group id of each): every frame within GROUP_HALF_WINDOW_S of an observation
    frame (at most MAX_FRAMES_PER_GROUP, the nearest), grouped by observation."""
    t = np.asarray(r.frames.t_ns, dtype=np.int64)
    pos, gid = [], []
    for g, p in enumerate(np.asarray(r.plan.frame_pos)):
        near = np.flatnonzero(np.abs(t - t[p]) <= GROUP_HALF_WINDOW_S * 1e9)
        near = near[np.argsort(np.abs(t[near] - t[p]), kind="stable")][:MAX_FRAMES_PER_GROUP]
        pos.extend(sorted(near.tolist()))
        gid.extend([g] * len(near))
    pos, gid = np.asarray(pos, dtype=np.int64), np.asarray(gid, dtype=np.int64)
    _, first = np.unique(pos, return_index=True)  # a frame near two observations belongs to the first
    keep = np.sort(first)
    return pos[keep], gid[keep]


def _profile(deltas: np.ndarray, cost: np.ndarray, dof: int, inflation: float) -> tuple[float, float, float, float]:
    """(best delta, low, high, s2) of a sampled cost profile."""
    k = int(np.nanargmin(cost))
    s2 = float(cost[k]) / max(dof, 1)
    inside = cost - cost[k] <= CHI2_95_1DOF * s2 * inflation
    lo = hi = k
    while lo > 0 and inside[lo - 1]:
        lo -= 1
    while hi < len(cost) - 1 and inside[hi + 1]:
        hi += 1
    return float(deltas[k]), float(deltas[lo]), float(deltas[hi]), s2


def _savgol(t_ns: np.ndarray, values: np.ndarray, span_s: float) -> np.ndarray:
    """values (n, k) smoothed along time by a cubic Savitzky-Golay filter about span_s wide (unchanged when the
    series is too short or too sparse for one)."""
    from scipy.signal import savgol_filter  # imported here: scipy.signal imports scipy.stats (~0.5 s)

    t = np.asarray(t_ns, dtype=np.int64)
    if t.size < 9:
        return values
    dt = float(np.median(np.diff(t))) / 1e9
    n = int(span_s / dt) | 1
    if n < 5 or n > t.size:
        return values
    return savgol_filter(values, n, 3, axis=0, mode="interp")


def smoothed_log(log):
    """The log with position, attitude and gimbal smoothed over ~0.3 s (gimbal, attitude) and ~1 s (position): the
    noise of a sensor sampled at a few tens of Hz, linearly interpolated, would otherwise depend on where a frame
    falls between two samples, and the misfit would favour offsets that put frames half-way between samples."""
    pos, att, gim = log.position, log.attitude, log.gimbal
    xyz = _savgol(pos.t_ns, np.c_[pos.lat_deg, pos.lon_deg, pos.alt_m], 1.0)
    pos = dataclasses.replace(pos, lat_deg=xyz[:, 0], lon_deg=xyz[:, 1], alt_m=xyz[:, 2])

    def quats(series):
        q = np.asarray(series.quat_wxyz, dtype=float)
        flip = np.r_[False, np.sum(q[1:] * q[:-1], axis=1) < 0]  # one hemisphere along the series
        q = _savgol(series.t_ns, q * np.where(np.logical_xor.accumulate(flip), -1.0, 1.0)[:, None], 0.3)
        return dataclasses.replace(series, quat_wxyz=q / np.linalg.norm(q, axis=1, keepdims=True))
    return dataclasses.replace(log, position=pos, attitude=quats(att), gimbal=quats(gim))


def estimate_video_offset(r: Flight, t_video_ns: np.ndarray, pixel_px: np.ndarray, groups: np.ndarray,
                          search_s: float) -> OffsetEstimate | None:
    """The video offset correction from tracked pixels pixel_px (m, 2) (distorted, NaN = lost) at frames whose
    video-clock times are t_video_ns (m,), grouped by `groups` (m,). None with too few tracked frames."""
    cam = r.camera
    configured_ns = r.config.clock.offset_ns("video")
    ok = np.isfinite(pixel_px).all(1)
    # only groups with at least 2 tracked frames carry within-group information
    counts = np.bincount(groups[ok], minlength=int(groups.max()) + 1) if ok.any() else np.zeros(1, int)
    ok &= counts[groups] >= 2
    if ok.sum() < 6:
        return None
    t0, px, g = np.asarray(t_video_ns)[ok], np.asarray(pixel_px, float)[ok], np.asarray(groups)[ok]
    _, g = np.unique(g, return_inverse=True)
    px_u = undistort_pixels(px, cam.K, cam.dist)
    # the target: where the lines of sight through the tracked pixels meet (at the configured offset)
    o, d, inside = r.rays(t0 + configured_ns, px)
    if inside.sum() < 3:
        return None
    X, _, _ = meeting_point(o[inside], d[inside])
    if not np.isfinite(X).all():
        return None
    n_groups = int(g.max()) + 1
    log = smoothed_log(r.log)

    def costs(deltas_ns: np.ndarray) -> np.ndarray:
        """(K, n_groups) within-group misfit of each group at each candidate offset (NaN outside the telemetry)."""
        K_, m = len(deltas_ns), len(t0)
        t = (t0[None, :] + configured_ns + deltas_ns[:, None]).ravel()
        poses, k = r.poses(t, log=log)
        resid = np.full((K_ * m, 2), np.nan)
        if poses is not None:
            v = np.einsum("nij,nj->ni", poses.R_optical_from_enu0, X - poses.camera_m)
            proj = (v[:, :2] / v[:, 2:3]) * [cam.fx_px, cam.fy_px] + [cam.cx_px, cam.cy_px]
            resid[k] = np.tile(px_u, (K_, 1))[k] - proj
        resid = resid.reshape(K_, m, 2)
        step = resid[:, pair + 1] - resid[:, pair]  # successive frames of a group (time order)
        per_group = np.zeros((K_, n_groups))
        np.add.at(per_group, (slice(None), g[pair]), np.sum(step ** 2, axis=2))
        return per_group

    order_t = np.lexsort((t0, g))
    t0, px_u, g = t0[order_t], px_u[order_t], g[order_t]
    pair = np.flatnonzero(g[1:] == g[:-1])
    window = round(search_s * 1e9)
    coarse = np.arange(-window, window + 1, 10_000_000, dtype=np.int64)
    cg = costs(coarse)
    total = cg.sum(axis=1)
    if not np.isfinite(total).any():
        return None
    best = int(coarse[int(np.nanargmin(total))])
    fine = np.arange(best - 20_000_000, best + 20_000_001, 1_000_000, dtype=np.int64)
    deltas = np.r_[coarse, fine]
    cg = np.r_[cg, costs(fine)]
    order = np.argsort(deltas, kind="stable")
    deltas, cg = deltas[order] / 1e9, cg[order]
    valid = np.isfinite(cg).all(axis=1)  # offsets that keep every frame inside the telemetry
    deltas, cg = deltas[valid], cg[valid]
    total = cg.sum(axis=1)
    dof = 2 * len(pair) - 1
    d_best, lo, hi, s2 = _profile(deltas, total, dof, 1.0)
    # The pixel errors are correlated along a group (a gimbal's attitude error wanders), so the likelihood
    # interval above, which counts every step as independent, can be far too narrow; the groups are seconds apart
    # and nearly independent: a bootstrap over groups (resampled with replacement, the argmin of each resampled
    # total) gives the spread the data support.
    # The bootstrap of an argmin under-covers with few groups; a jackknife (leave one group out, Student's t) is
    # added, and the widest of the three kept.
    if n_groups >= 3:
        rng = np.random.default_rng(0)  # fixed: the same data give the same interval
        counts = rng.multinomial(n_groups, np.full(n_groups, 1.0 / n_groups), size=BOOTSTRAP)
        boot = deltas[np.argmin(counts @ cg.T, axis=1)]
        loo = deltas[np.argmin(total[None, :] - cg.T, axis=1)]
        sd = math.sqrt((n_groups - 1) / n_groups * float(np.sum((loo - loo.mean()) ** 2)))
        half = float(stdtrit(n_groups - 1, 0.975)) * sd
        lo = min(lo, float(np.quantile(boot, 0.025)), d_best - half)
        hi = max(hi, float(np.quantile(boot, 0.975)), d_best + half)
    else:
        lo, hi = -search_s, search_s
    determined = lo > -search_s + 0.015 and hi < search_s - 0.015
    return OffsetEstimate("video", configured_ns / 1e9, d_best, max(lo, -search_s), min(hi, search_s), determined,
                          len(t0), math.sqrt(s2), search_s)


def estimate_clock(r: Flight, tracker, mark: TargetMark, cache=None) -> ClockEstimate:
    """Track the target from `mark` through the frames around each observation (decoded by the flight's
    frames) and estimate the video offset (see the module docstring); `tracker` a SiftTracker, `cache` the
    flight's ViewCache (frames the targets' tracks decode later are then decoded once)."""
    if r.plan is None:
        return ClockEstimate(None)
    search_s = r.config.clock.search_s
    pos, groups = estimation_frames(r)
    idx = np.asarray(r.frames.index)[pos]
    track = tracker.track(r.decoder, mark.frame_index, mark.pixel_px, idx.tolist(),
                          available=np.asarray(r.frames.index).tolist(), cache=cache)
    return ClockEstimate(estimate_video_offset(r, np.asarray(r.frames.t_ns)[pos], track.pixel_px, groups, search_s))
