"""Which video frames are observations, and the laser range that goes with each.

Mode `range_times` (default): every laser shot, valid or not, is an observation at the video frame nearest its
time (within `frame_tolerance_s`); an invalid or out-of-range shot leaves the range NaN but keeps the frame.
Mode `frames`: the listed frame indices are the observations; the nearest valid range within
`max_range_gap_s` is attached, else NaN. Mode `bursts`: for a camera triggered in bursts (frames separated by
more than `burst_gap_s` start a new burst), one observation per burst, at the frame of the burst's laser shot
when there is one within `frame_tolerance_s`, else the burst's middle frame, with the nearest valid range within
`max_range_gap_s`; a burst whose shot was never logged still counts. All times are put on the telemetry clock
first (config `clock`).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from pipeline.errors import InputError
from pipeline.ingest.model import FrameSeries, RangeSeries
from pipeline.sync.interpolate import nearest_within

NS_PER_S = 10**9


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

    @property
    def n(self) -> int:
        return int(self.frame_pos.size)


def usable_ranges(ranges: RangeSeries) -> np.ndarray:
    """(n,) bool: the samples a solver may use (flagged valid, finite, positive)."""
    r = np.asarray(ranges.range_m, dtype=np.float64)
    return np.asarray(ranges.valid, dtype=bool) & np.isfinite(r) & (r > 0)


def plan_observations(frames: FrameSeries, ranges: RangeSeries | None, *, mode: str = "range_times",
                      video_offset_ns: int = 0, range_offset_ns: int = 0, frame_tolerance_s: float = 0.1,
                      max_range_gap_s: float = 0.1, frame_indices=(), burst_gap_s: float = 0.5) -> ObservationPlan:
    """Choose the observation frames and attach ranges (see the module docstring)."""
    t_frames = np.asarray(frames.t_ns, dtype=np.int64) + int(video_offset_ns)
    notes: list[str] = []
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
    else:
        raise InputError(f"unknown observation mode {mode!r}")
    if frame_pos.size == 0:
        raise InputError("no observation frames: no laser shot falls within the video's time span "
                         "(check clock.video_to_telemetry_offset_ns and clock.range_offset_ns)")
    return ObservationPlan(frame_pos=frame_pos.astype(np.int64),
                           frame_index=np.asarray(frames.index, dtype=np.int64)[frame_pos],
                           t_ns=t_frames[frame_pos], range_m=range_m.astype(np.float64),
                           range_t_ns=range_t.astype(np.int64), notes=notes)


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
