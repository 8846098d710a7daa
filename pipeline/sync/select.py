"""Which video frames are observations, and the laser range that goes with each.

Mode `range_times` (default): every laser shot, valid or not, is an observation at the video frame nearest its
time (within `frame_tolerance_s`); an invalid or out-of-range shot leaves the range NaN but keeps the frame.
Mode `frames`: the listed frame indices are the observations; the nearest valid range within
`max_range_gap_s` is attached, else NaN. Mode `bursts`: for a camera triggered in bursts (frames separated by
more than `burst_gap_s` start a new burst), one observation per burst, at the frame of the burst's laser shot
when there is one within `frame_tolerance_s`, else the burst's middle frame, with the nearest valid range within
`max_range_gap_s`; a burst whose shot was never logged still counts. All times are put on the telemetry clock
first (config `clock`).

Observations at key frames (`at_key_frames`, mode `range_times` of a video whose key frames are known): each shot
moves to the nearest key frame within `key_frame_tolerance_s`, its range interpolated at that frame's time
(`pipeline.sync.key_frames`). `True` always does so, `False` never, `"auto"` where it decodes at most half the
frames, keeps the shots' observations and ranges (all but 2 %, at least one), and the interpolation's estimated
error is small against the range's noise (90th percentile at most KEY_FRAME_ERROR_FRACTION of it): the smaller of
`range_sigma_m` (the config's sigma.range_m, when stated) and the shots' own scatter about their local fits.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from pipeline.errors import InputError
from pipeline.ingest.model import FrameSeries, RangeSeries
from pipeline.sync.interpolate import nearest_within
from pipeline.sync.key_frames import frames_to_decode, key_frame_observations

NS_PER_S = 10**9
KEY_FRAME_ERROR_FRACTION = 0.25  # the interpolation's error beside noise sigma: sqrt(1 + 0.25^2) = 1.03 sigma


@dataclass(frozen=True)
class ObservationPlan:
    """m planned observations: frame_pos (m,) positions in the FrameSeries arrays, frame_index (m,) the frames'
    own numbers, t_ns (m,) frame times on the telemetry clock, range_m (m,) metres or NaN, range_t_ns (m,)
    telemetry time of the range used (-1 when none)."""

    frame_pos: np.ndarray
    frame_index: np.ndarray
    t_ns: np.ndarray
    range_m: np.ndarray
    range_t_ns: np.ndarray
    notes: list[str] = field(default_factory=list)
    at_key_frames: bool = False  # observations moved to key frames, ranges interpolated at their times
    range_error_m: np.ndarray | None = None  # (m,) the interpolation's estimated error (at key frames), else None
    warnings: list[str] = field(default_factory=list)  # what makes the plan suspect (`check` and `run` print them)

    @property
    def n(self) -> int:
        return int(self.frame_pos.size)


def usable_ranges(ranges: RangeSeries) -> np.ndarray:
    """(n,) bool: the samples a solver may use (flagged valid, finite, positive)."""
    r = np.asarray(ranges.range_m, dtype=np.float64)
    return np.asarray(ranges.valid, dtype=bool) & np.isfinite(r) & (r > 0)


def plan_observations(frames: FrameSeries, ranges: RangeSeries | None, *, mode: str = "range_times",
                      video_offset_ns: int = 0, range_offset_ns: int = 0, frame_tolerance_s: float = 0.1,
                      max_range_gap_s: float = 0.1, frame_indices=(), burst_gap_s: float = 0.5,
                      keyframe: np.ndarray | None = None, at_key_frames: bool | str = "auto",
                      key_frame_tolerance_s: float = 0.5, range_interpolation_gap_s: float = 1.5,
                      range_sigma_m: float | None = None) -> ObservationPlan:
    """Choose the observation frames and attach ranges (see the module docstring). keyframe (n,) bool: which of
    the frames are key frames (None: unknown, or every frame decodes alone)."""
    t_frames = np.asarray(frames.t_ns, dtype=np.int64) + int(video_offset_ns)
    notes: list[str] = []
    warnings: list[str] = []
    if ranges is not None:
        t_rng = np.asarray(ranges.t_ns, dtype=np.int64) + int(range_offset_ns)
        ok = usable_ranges(ranges)
    if mode == "range_times":
        if ranges is None or ranges.t_ns.size == 0:
            raise InputError("observation mode 'range_times' needs laser ranges, but the flight has none")
        pos = nearest_within(t_frames, t_rng, int(frame_tolerance_s * NS_PER_S))
        shots = np.flatnonzero(pos >= 0)
        if shots.size < t_rng.size:
            notes.append(f"{t_rng.size - shots.size} laser shot(s) have no video frame within "
                         f"{frame_tolerance_s} s and are not observations")
        # Two shots on one frame: keep the one closest in time.
        gap = np.abs(t_frames[pos[shots]] - t_rng[shots])
        order = np.lexsort((gap, pos[shots]))
        shots = shots[order]
        first = np.r_[True, np.diff(pos[shots]) != 0][: shots.size]
        shots = np.sort(shots[first])
        frame_pos = pos[shots]
        range_m = np.where(ok[shots], np.asarray(ranges.range_m, dtype=np.float64)[shots], np.nan)
        range_t = np.where(ok[shots], t_rng[shots], -1)
    elif mode in ("frames", "bursts"):
        if mode == "frames":
            wanted = np.asarray(frame_indices, dtype=np.int64)
            lookup = {int(k): i for i, k in enumerate(np.asarray(frames.index))}
            missing = [int(k) for k in wanted if int(k) not in lookup]
            if missing:
                raise InputError(f"observation frame(s) not in the video: {missing[:5]}")
            frame_pos = np.unique(np.array([lookup[int(k)] for k in wanted], dtype=np.int64))
        else:
            frame_pos = _burst_frames(t_frames, t_rng if ranges is not None else np.zeros(0, np.int64),
                                      int(burst_gap_s * NS_PER_S), int(frame_tolerance_s * NS_PER_S))
        range_m = np.full(frame_pos.size, np.nan)
        range_t = np.full(frame_pos.size, -1, dtype=np.int64)
        if ranges is not None and ok.any():
            good = np.flatnonzero(ok)
            j = nearest_within(t_rng[good], t_frames[frame_pos], int(max_range_gap_s * NS_PER_S))
            has = j >= 0
            range_m[has] = np.asarray(ranges.range_m, dtype=np.float64)[good[j[has]]]
            range_t[has] = t_rng[good[j[has]]]
            if mode == "bursts":
                warnings = _bursts_without_shots(t_frames[frame_pos], t_rng[good], int(has.sum()), max_range_gap_s)
    else:
        raise InputError(f"unknown observation mode {mode!r}")
    if frame_pos.size == 0:
        raise InputError("no observation frames: no laser shot falls within the video's time span "
                         "(check clock.video_to_telemetry_offset_ns and clock.range_offset_ns)")
    plan = ObservationPlan(frame_pos=frame_pos.astype(np.int64),
                           frame_index=np.asarray(frames.index, dtype=np.int64)[frame_pos],
                           t_ns=t_frames[frame_pos], range_m=range_m.astype(np.float64),
                           range_t_ns=range_t.astype(np.int64), notes=notes, warnings=warnings)
    if mode == "range_times" and keyframe is not None and at_key_frames is not False:
        plan = _at_key_frames(plan, frames, t_frames, np.asarray(keyframe, dtype=bool), ranges, t_rng, ok,
                              at_key_frames, int(key_frame_tolerance_s * NS_PER_S),
                              int(range_interpolation_gap_s * NS_PER_S), range_sigma_m)
    return plan


def _bursts_without_shots(t_obs_ns: np.ndarray, t_shots_ns: np.ndarray, n_ranged: int,
                          max_range_gap_s: float) -> list[str]:
    """A burst of video is recorded around the laser shot that triggered it: when most bursts have no valid shot
    within max_range_gap_s although valid shots fall between the first and the last burst, the ranges are lost to a
    clock offset (video or range), not to the laser. One warning line, or none."""
    n = t_obs_ns.size
    if n < 3 or 2 * n_ranged >= n:
        return []
    between = int(((t_shots_ns >= t_obs_ns.min()) & (t_shots_ns <= t_obs_ns.max())).sum())
    if between < n:
        return []
    return [f"only {n_ranged} of {n} bursts of video have a laser shot within {max_range_gap_s:g} s, although "
            f"{between} valid shots fall between the first and the last burst: the video clock (or the range's) "
            "looks off, and the observations lose their ranges; check clock.video_start (or video_offset_s, "
            "range_offset_s)"]


def _allowance(n: int) -> int:
    return max(1, int(np.ceil(0.02 * n)))


def _at_key_frames(plan: ObservationPlan, frames: FrameSeries, t_frames: np.ndarray, keyframe: np.ndarray,
                   ranges: RangeSeries, t_rng: np.ndarray, ok: np.ndarray, when: bool | str, tolerance_ns: int,
                   gap_ns: int, sigma_m: float | None) -> ObservationPlan:
    """The plan at key frames instead of the shots' own frames, when `when` is True, or "auto" and it pays (see
    the module docstring); else `plan`, with a note when key frames would have saved decoding but did not apply."""
    kp = key_frame_observations(t_frames, keyframe, t_rng, ok, ranges.range_m, tolerance_ns=tolerance_ns,
                                max_gap_ns=gap_ns)
    ranged = np.isfinite(kp.range_m)
    before, after = frames_to_decode(plan.frame_pos, keyframe), frames_to_decode(kp.frame_pos, keyframe)
    err = kp.range_error_m[ranged]
    p90 = float(np.percentile(err, 90)) if err.size and np.isfinite(err).all() else float("nan")
    n_ranged = int(np.isfinite(plan.range_m).sum())
    noise = kp.noise_m if sigma_m is None else min(sigma_m, kp.noise_m)
    if when == "auto":
        if before < 2 * after:
            return plan
        why = []
        if kp.frame_pos.size < plan.n - _allowance(plan.n):
            why.append(f"only {kp.frame_pos.size} of the {plan.n} shots have a key frame of their own within "
                       f"{tolerance_ns / NS_PER_S:g} s")
        if ranged.sum() < n_ranged - _allowance(n_ranged):
            why.append(f"only {int(ranged.sum())} of {n_ranged} ranges could be interpolated (valid shots on "
                       f"both sides within {gap_ns / NS_PER_S:g} s)")
        if not p90 <= KEY_FRAME_ERROR_FRACTION * noise:
            why.append(f"the range is not smooth enough: interpolation error p90 {p90:.3g} m against its noise "
                       f"{noise:.3g} m")
        if why:
            plan.notes.append(f"observations at the shots' own frames: key frames would decode {after} frames "
                              f"instead of {before}, but {'; '.join(why)} (observations.at_key_frames)")
            return plan
    if kp.frame_pos.size == 0:
        raise InputError(f"observations.at_key_frames: no laser shot has a key frame within "
                         f"{tolerance_ns / NS_PER_S:g} s (observations.key_frame_tolerance_s)")
    med = float(np.median(err)) if err.size else float("nan")
    notes = [f"observations at key frames ({'auto' if when == 'auto' else 'observations.at_key_frames'}): "
             f"{kp.frame_pos.size} of {t_rng.size} laser shots, each at the nearest key frame within "
             f"{tolerance_ns / NS_PER_S:g} s, {int(ranged.sum())} with a range interpolated at the frame's time "
             f"(estimated error median {med:.3g} m, p90 {p90:.3g} m; the range's scatter {kp.noise_m:.3g} m); "
             f"{after} frames to decode instead of {before}"]
    pos = kp.frame_pos
    return ObservationPlan(frame_pos=pos, frame_index=np.asarray(frames.index, dtype=np.int64)[pos],
                           t_ns=t_frames[pos], range_m=kp.range_m, range_t_ns=np.where(ranged, t_frames[pos], -1),
                           notes=notes, at_key_frames=True, range_error_m=kp.range_error_m)


def _burst_frames(t_frames: np.ndarray, t_shots: np.ndarray, gap_ns: int, tolerance_ns: int) -> np.ndarray:
    """Positions of one frame per burst: the frame of a laser shot inside the burst, else the middle frame."""
    order = np.argsort(t_frames, kind="stable")
    t = t_frames[order]
    starts = np.flatnonzero(np.r_[True, np.diff(t) > gap_ns])
    ends = np.r_[starts[1:], t.size]
    shot_frame = nearest_within(t, t_shots, tolerance_ns)
    out = []
    for a, b in zip(starts, ends, strict=True):
        inside = shot_frame[(shot_frame >= a) & (shot_frame < b)]
        out.append(int(inside[0]) if inside.size else (a + b - 1) // 2)
    return np.sort(order[np.array(out, dtype=np.int64)])
