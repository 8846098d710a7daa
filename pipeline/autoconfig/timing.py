"""When the video's frames were taken on the telemetry's clock, and which frames are observations, from what the
files state (`video_clock`, `observation_choice`).

The video clock, in order:
1. frames stamped on the telemetry's own clock (a bag's images, a full-motion video's KLV, a DJI SRT beside its
   video): no offset;
2. a clock link the readers found between the two clocks (an SRT's date and time read as UTC);
3. the video's creation time (`ingest.video_time`: the recording start, to the whole second) and, where the
   camera was triggered in bursts by the laser, the shots: a burst's frame and its shot were taken together, so
   the offset that puts a shot on a frame of nearly every burst, within the second the creation time leaves
   open, is the offset to the nanosecond (the laser fires once a second, so the shots alone leave whole seconds
   open); without bursts the creation time is written and `clock.estimate` left to refine it at the run
   (`pipeline/clock_estimate.py`, where the intrinsics are known `ridgeloc init` runs it itself);
4. otherwise nothing: the offset is a fact for the user.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from pipeline.ingest.clocks import find_link, map_clock
from pipeline.ingest.model import FlightLog, FrameSeries
from pipeline.ingest.video_time import creation_time_ns

BURST_GAP_S = 0.5  # as observations.burst_gap_s: a longer gap between frames starts a new burst
COINCIDENCE_NS = 5_000_000  # a shot and its frame, triggered together, within 5 ms
MIN_BURSTS_MATCHED = 0.8  # of the bursts must hold a shot at the chosen offset (a shot may be lost)
MAX_FRAMES_LISTED = 20  # observation frames listed for a continuous video without laser ranges


@dataclass(frozen=True)
class VideoClock:
    """How the frames are put on the telemetry clock. shared: they are on it already; start_ns: the video
    clock's zero on the telemetry clock (None when shared or unknown); estimate_s: the window (s) `clock.estimate`
    should search around it at the run (None: no estimate needed); how: one line saying where it came from."""

    shared: bool
    start_ns: int | None
    how: str
    estimate_s: float | None = None

    @property
    def known(self) -> bool:
        return self.shared or self.start_ns is not None


def bursts(t_ns: np.ndarray, gap_s: float = BURST_GAP_S) -> list[np.ndarray]:
    """Positions of the frames (times t_ns (n,), sorted) in each burst: runs separated by more than gap_s."""
    t = np.asarray(t_ns, dtype=np.int64)
    if t.size == 0:
        return []
    cuts = np.flatnonzero(np.diff(t) > round(gap_s * 1e9)) + 1
    return np.split(np.arange(t.size), cuts)


def align_bursts(frames_t_ns: np.ndarray, shots_t_ns: np.ndarray, low_ns: int, high_ns: int) -> int | None:
    """The offset (ns, telemetry = video + offset) in [low_ns, high_ns) that puts a laser shot on a frame of the
    most bursts (at least MIN_BURSTS_MATCHED of them); where several do (a shot fits any frame of a burst), the
    one that puts the shots nearest the bursts' middles, as a camera triggered around its shot records them.
    None when there are fewer than 2 bursts or no single such offset."""
    t_v = np.asarray(frames_t_ns, dtype=np.int64)
    groups = bursts(t_v)
    shots = np.sort(np.asarray(shots_t_ns, dtype=np.int64))
    if len(groups) < 2 or shots.size == 0:
        return None
    burst_of = np.empty(t_v.size, dtype=np.int64)
    for b, pos in enumerate(groups):
        burst_of[pos] = b
    # every (frame, shot) pair whose offset falls in the window
    lo = np.searchsorted(shots, t_v + low_ns - COINCIDENCE_NS)
    hi = np.searchsorted(shots, t_v + high_ns + COINCIDENCE_NS)
    if not (hi > lo).any():
        return None
    frame_idx = np.repeat(np.arange(t_v.size), hi - lo)
    shot_idx = np.concatenate([np.arange(a, b) for a, b in zip(lo, hi, strict=True)])
    d = shots[shot_idx] - t_v[frame_idx]
    order = np.argsort(d, kind="stable")
    d, owner = d[order], burst_of[frame_idx[order]]
    # offsets within COINCIDENCE_NS of each other are one alignment
    starts = np.flatnonzero(np.r_[True, np.diff(d) > COINCIDENCE_NS])
    ends = np.r_[starts[1:], d.size]
    matched = np.array([np.unique(owner[a:b]).size for a, b in zip(starts, ends, strict=True)])
    if matched.max() < max(2, MIN_BURSTS_MATCHED * len(groups)):
        return None
    middles = np.array([(t_v[pos[0]] + t_v[pos[-1]]) // 2 for pos in groups])
    best = []
    for k in np.flatnonzero(matched == matched.max()):
        run = d[starts[k]:ends[k]]  # sorted
        offset = int(run[run.size // 2])  # an integer median: float64 would lose ~100 ns at UNIX-ns magnitudes
        j = np.clip(np.searchsorted(shots, middles + offset), 1, shots.size - 1) if shots.size > 1 else \
            np.zeros(middles.size, dtype=np.int64)
        miss = np.minimum(np.abs(shots[j] - middles - offset), np.abs(shots[j - 1] - middles - offset)) \
            if shots.size > 1 else np.abs(shots[0] - middles - offset)
        best.append((float(np.median(miss)), offset))
    best.sort()
    if len(best) > 1 and best[1][0] - best[0][0] <= COINCIDENCE_NS:
        return None
    offset = best[0][1]
    return offset if low_ns <= offset < high_ns else None


def _telemetry_span(log: FlightLog) -> tuple[int, int]:
    spans = [(int(s.t_ns[0]), int(s.t_ns[-1])) for s in (log.position, log.attitude, log.gimbal)]
    return max(a for a, _ in spans), min(b for _, b in spans)


def video_clock(log: FlightLog, video_path) -> VideoClock:
    """How the flight's frames (log.frames) are put on its telemetry's clock (see the module docstring);
    `video_path` the video file (None: the frames come from a bag or a full-motion video)."""
    frames: FrameSeries = log.frames
    clock = log.position.clock
    if frames.clock == clock:
        return VideoClock(True, None, f"the frames ({_short(frames.source)}) and the telemetry "
                          f"({_short(log.position.source)}) are stamped on one clock ({clock})")
    link, reverse = find_link(log.clock_links, frames.clock, clock)
    if link is not None:
        start = int(map_clock(np.zeros(1, dtype=np.int64), link, reverse=reverse)[0])  # the video clock's zero
        return VideoClock(False, start, f"the video clock linked to the telemetry's by the files' own times "
                          f"({link.a} -> {link.b})")
    if video_path is None or clock != "unix":
        return VideoClock(False, None, f"the frames' clock ({frames.clock}) and the telemetry's ({clock}) are "
                          "linked by nothing in the files")
    created = creation_time_ns(video_path)
    if created is None:
        return VideoClock(False, None, f"{_short(video_path)} states no creation time and the telemetry no video "
                          "start")
    lo, hi = _telemetry_span(log)
    t = np.asarray(frames.t_ns, dtype=np.int64)
    if created + int(t[0]) > hi or created + int(t[-1]) < lo:
        return VideoClock(False, None, f"{_short(video_path)}'s creation time puts it outside the telemetry "
                          "(a camera clock not set, or local time)")
    if log.range is not None:
        aligned = align_bursts(t, np.asarray(log.range.t_ns), created, created + 10**9)
        if aligned is not None:
            return VideoClock(False, aligned, f"{_short(video_path)}'s creation time (to the second) and the laser "
                              "shots its bursts were triggered by (to the frame)")
    return VideoClock(False, created + 500_000_000, f"{_short(video_path)}'s creation time, to the second (its "
                      "middle taken); the run estimates the rest from the flight", estimate_s=1.0)


def _short(path) -> str:
    return Path(str(path).split(":", 1)[0]).name + (":" + str(path).split(":", 1)[1] if ":" in str(path) else "")


@dataclass(frozen=True)
class ObservationChoice:
    """The `observations:` section to write (None: the default, every laser shot) and why, in one line."""

    section: dict | None
    how: str


def observation_choice(log: FlightLog, video_offset_ns: int | None) -> ObservationChoice:
    """Bursts of video (a triggered camera): one observation per burst. Continuous video with laser ranges:
    every shot (the default). Without ranges: up to MAX_FRAMES_LISTED frames spread evenly over the video, over
    the part the telemetry covers where the video's offset (telemetry = video + video_offset_ns) is known."""
    t = np.asarray(log.frames.t_ns, dtype=np.int64)
    groups = bursts(t)
    ranged = log.range is not None and bool(np.asarray(log.range.valid).any())
    if len(groups) >= 2:
        return ObservationChoice({"mode": "bursts"}, f"the video comes in {len(groups)} bursts (gaps over "
                                 f"{BURST_GAP_S:g} s): one observation per burst, at its laser shot")
    if ranged:
        return ObservationChoice(None, "continuous video with laser ranges: every shot is an observation")
    inside = np.arange(t.size)
    if video_offset_ns is not None:
        lo, hi = _telemetry_span(log)
        inside = np.flatnonzero((t + video_offset_ns >= lo) & (t + video_offset_ns <= hi))
        inside = inside if inside.size else np.arange(t.size)
    span_s = (int(t[inside[-1]]) - int(t[inside[0]])) / 1e9
    n = int(min(MAX_FRAMES_LISTED, inside.size, max(3, span_s)))
    pos = inside[np.unique(np.round(np.linspace(0, inside.size - 1, n)).astype(int))]
    index = np.asarray(log.frames.index)[pos]
    return ObservationChoice({"mode": "frames", "frame_indices": [int(i) for i in index]},
                             f"no laser ranges: {len(index)} frames spread over the {span_s:.1f} s of video the "
                             "telemetry covers are the observations (keep those that show the target)")
