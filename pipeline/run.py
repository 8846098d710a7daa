"""`ridgeloc run`: one flight group through every stage, ingest -> track -> sync (geometry) -> solve -> compare.

`process_group(config)` is a pure top-level function of a `FlightConfig` (picklable both ways), so a batch can
run groups in worker processes. It returns a `GroupResult` with the wall time of each stage:
  ingest  reading telemetry and the frame index (no pixels decoded),
  decode  decoding the frames the tracker asked for,
  track   SIFT, matching, homographies and refinement (and the marks resolved, the clock estimated),
  sync    interpolation of the vehicle state, poses, projection matrices, undistortion,
  solve   every estimator.
"""

from __future__ import annotations

import dataclasses
import json
import math
import time
from collections.abc import Sequence
from os import PathLike
from pathlib import Path

import cv2
import numpy as np

from pipeline.batch import report_stage
from pipeline.check.conventions import current_reading
from pipeline.check.flight import ResolvedFlight, outside_telemetry
from pipeline.errors import ConfigError, InputError, RidgelocError
from pipeline.flight_config import FlightConfig
from pipeline.geometry.frames import ellipsoid_from_amsl_m
from pipeline.ingest.model import FlightLog, FrameSeries
from pipeline.intrinsics import resolve_camera
from pipeline.results import FlightResult, GroupResult  # FlightResult: issue 21
from pipeline.solve.estimate import Estimate
from pipeline.solve.observations import Observations
from pipeline.sync.assemble import frame_states
from pipeline.sync.select import plan_observations
from pipeline.track.sift import SiftTracker


class _TimedDecoder:
    """Decodes chosen frame numbers to grayscale and accumulates the time spent."""

    def __init__(self, read):
        self._read = read
        self.seconds = 0.0
        self.cpu_seconds = 0.0
        self.decoded = 0
        self.failed: list[int] = []

    def __call__(self, indices: Sequence[int]) -> dict[int, np.ndarray]:
        t, c = time.perf_counter(), time.process_time()
        wanted = sorted(set(int(i) for i in indices))
        try:
            images = self._read(wanted)
        except RidgelocError:  # a truncated or damaged stream: keep the frames that decode, the others are lost
            images = {}
            for i in wanted:
                try:
                    images.update(self._read([i]))
                except RidgelocError:
                    self.failed.append(i)
        out = {i: (img if img.ndim == 2 else cv2.cvtColor(img, cv2.COLOR_BGR2GRAY)) for i, img in images.items()}
        self.seconds += time.perf_counter() - t
        self.cpu_seconds += time.process_time() - c
        self.decoded += len(out)
        return out


def read_flight_logs(config: FlightConfig) -> FlightLog:
    """The flight's telemetry files read into one FlightLog; InputError when it lacks position, attitude or gimbal."""
    from pipeline.ingest import read_flight

    log = read_flight(list(config.files.telemetry), mapping=config.mapping)
    missing = [q for q in ("position", "attitude", "gimbal") if getattr(log, q) is None]
    if missing:
        raise InputError(f"the flight's logs supply no {', '.join(missing)}: check `mapping:` "
                         "(see `ridgeloc inspect`)", config.path)
    return log


def open_frames(config: FlightConfig, log: FlightLog) -> tuple[FrameSeries, _TimedDecoder, object]:
    """The flight's frame index and a decoder of chosen frames: the video file when the config names one,
    else the image topic of a bag the telemetry came from. Returns (frames, decoder, closable)."""
    from pipeline import ingest

    if config.files.video is not None:
        video = ingest.VideoFrames(config.files.video)  # demuxes the file once: its index serves both
        try:
            frames = ingest.read_video(config.files.video, frames_csv=config.files.frames_csv or "auto",
                                       index=video.index)
        except BaseException:
            video.close()
            raise
        return frames, _TimedDecoder(video.read), video
    if log.frames is not None and "fmv" in log.formats:  # full-motion video: the frames of the telemetry file
        video = ingest.VideoFrames(log.frames.source)
        return log.frames, _TimedDecoder(video.read), video
    if log.frames is None:
        raise ConfigError("the flight has no video (files.video) and its logs carry no images", config.path)
    for path in config.files.telemetry:
        try:
            images = ingest.BagImages(path, None, mapping=config.mapping, frames=log.frames)
        except (RidgelocError, ValueError, KeyError):
            continue
        return images.frames, _TimedDecoder(images.read), None
    raise ConfigError(f"cannot open the image stream {log.frames.source!r} of the flight's logs", config.path)


def plan_flight_observations(config: FlightConfig, frames: FrameSeries, log: FlightLog,
                             video_offset_ns: int | None = None):
    """Which frames are observations, with their laser shots, as the flight config's `observations:` and
    `clock:` say, or with `video_offset_ns` when given (`pipeline.sync.select.plan_observations`; needs only
    timestamps)."""
    c, sel = config.clock, config.observations
    video_offset_ns = c.offset_ns("video") if video_offset_ns is None else video_offset_ns
    return plan_observations(frames, log.range, mode=sel.mode, video_offset_ns=video_offset_ns,
                             range_offset_ns=c.offset_ns("range"), frame_tolerance_s=sel.frame_tolerance_s,
                             max_range_gap_s=sel.max_range_gap_s, frame_indices=sel.frame_indices,
                             burst_gap_s=sel.burst_gap_s)


def geoid_separation_m(config: FlightConfig, log: FlightLog) -> float | None:
    """altitude.geoid_separation_m as a number: `auto` -> the EGM2008 undulation at the first finite position."""
    value = config.altitude.geoid_separation_m
    if value != "auto":
        return value
    from pipeline.geometry.geoid import patch_around

    pos = log.position
    ok = np.zeros(0, bool) if pos is None else np.isfinite(pos.lat_deg) & np.isfinite(pos.lon_deg)
    if not ok.any():
        raise InputError("altitude.geoid_separation_m: auto needs a position in the logs", config.path)
    i = int(np.flatnonzero(ok)[0])
    lat, lon = float(pos.lat_deg[i]), float(pos.lon_deg[i])
    return float(patch_around(lat, lon)(lat, lon))  # cached per flight: check and the clock estimate ask again


def _origin(config: FlightConfig, log: FlightLog, separation_m: float | None) -> tuple[float, float, float]:
    if config.origin != "auto":
        return config.origin.as_tuple()
    pos = log.position
    alt = float(pos.alt_m[0])
    if pos.alt_datum == "amsl":
        if separation_m is None:
            raise ConfigError("altitudes are AMSL: set altitude.geoid_separation_m (a number, or auto)", config.path)
        alt = float(ellipsoid_from_amsl_m(alt, separation_m))
    return float(pos.lat_deg[0]), float(pos.lon_deg[0]), alt


def intersection_angle_deg(platform_m: np.ndarray, target_m: np.ndarray) -> float:
    """Angle between the first and last lines of sight to target_m (the paper's gamma), degrees."""
    u = np.asarray(target_m, dtype=np.float64) - np.asarray(platform_m, dtype=np.float64)[[0, -1]]
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    return math.degrees(math.acos(float(np.clip(u[0] @ u[1], -1.0, 1.0))))


def _methods(config: FlightConfig) -> list[str]:
    from pipeline.solve import METHODS

    if config.solve.methods == "all":
        return list(METHODS)
    methods = [config.solve.methods] if isinstance(config.solve.methods, str) else list(config.solve.methods)
    unknown = [m for m in methods if m not in METHODS]
    if unknown:
        raise ConfigError(f"solve.methods: unknown method(s) {unknown} (known: {', '.join(METHODS)})", config.path)
    return methods


def solve_all(obs: Observations, methods: Sequence[str], options: dict) -> tuple[dict[str, Estimate], dict]:
    """Every method on one problem: (estimates, {method: {"status", "reason"}} for those that could not run)."""
    from pipeline.solve import solve, unsolved_status

    estimates, failures = {}, {}
    for m in methods:
        try:
            estimates[m] = solve(m, obs, **dict(options.get(m) or {}))
        except (RidgelocError, ValueError, np.linalg.LinAlgError) as exc:
            failures[m] = {"status": unsolved_status(exc), "reason": str(exc)}
    return estimates, failures


def _estimate_clock(config, log, frames, cam, cam_source, plan, origin, decoder, tracker, mark_index, mark_px, notes):
    """clock.estimate: the video offset from the flight (`pipeline.sync.clock_estimate`); returns
    (the estimate, the observation plan at the estimated video offset, or the given plan when not determined)."""
    from pipeline.sync.clock_estimate import estimate_clock

    resolved = ResolvedFlight(config, log, frames, cam, cam_source, current_reading(config, log), plan, None, origin)
    est = estimate_clock(resolved, decoder, tracker, mark_index, mark_px)
    v = est.video
    if v is not None and v.determined:
        plan = plan_flight_observations(config, frames, log, round(v.offset_s * 1e9))
        notes.append(f"clock estimated: {v.describe()}; the estimate is used")
    else:
        notes.append(f"clock estimate: {v.describe() if v is not None else 'too few tracked frames'}; the "
                     "configured offset is used")
    return est, plan


def process_group(config: FlightConfig) -> GroupResult | FlightResult:
    """Ingest, track, synchronize and solve one flight group (see the module docstring). Logs are read, the
    observations planned and the vehicle state interpolated once; then each target goes through
    `pipeline.target_stage.locate_target` (issue 21): a GroupResult for the single `target:` (or the
    crosshair), a FlightResult (one GroupResult per named target) for `targets:` / `marks_file:`."""
    from pipeline.target_stage import SharedFlight, finish_settings, locate_target, locate_targets, resolve_mark
    from pipeline.targets import check_marks_in_video, flight_targets
    from pipeline.track.sift import ViewCache

    report_stage("ingest")
    timings: dict[str, float] = {}
    notes: list[str] = []
    cpu: dict[str, float] = {}  # process CPU seconds per stage (all threads): the wall times' counterpart under load
    t0, c0 = time.perf_counter(), time.process_time()
    log = read_flight_logs(config)
    frames, decoder, closable = open_frames(config, log)
    cam, cam_source = resolve_camera(config, log if log.frames is not None else dataclasses.replace(log, frames=frames))
    notes.extend(log.warnings)
    timings["ingest"] = time.perf_counter() - t0
    cpu["ingest"] = time.process_time() - c0
    targets = flight_targets(config)  # issue 21: [] (crosshair), [one unnamed target], or named targets
    named = bool(targets) and targets[0].name is not None
    try:
        if named:  # every mark checked against the video before anything runs
            check_marks_in_video(targets, frames.index, cam.width_px, cam.height_px, config.path)
        # Which frames are observations (needs only timestamps).
        c = config.clock
        plan = plan_flight_observations(config, frames, log)
        notes.extend(plan.notes)
        report_stage("track")
        t1, c1 = time.perf_counter(), time.process_time()
        tracker = SiftTracker(config.tracking)
        flight = SharedFlight(config, log, frames, decoder, cam, cam_source, plan, None, None, None, tracker,
                              ViewCache(share_matches=named), notes, timings, cpu)
        first = [resolve_mark(flight, m, notes) for m in (targets[0].marks if targets else [None])]
        separation_m = geoid_separation_m(config, log)
        if config.altitude.geoid_separation_m == "auto" and log.position.alt_datum == "amsl":
            notes.append(f"geoid separation {separation_m:.2f} m (altitude.geoid_separation_m: auto, EGM2008 at "
                         "the first position)")
        origin = _origin(config, log, separation_m)
        if c.estimate:  # the flight's clock, from the first target's first mark
            flight.clock_estimate, plan = _estimate_clock(config, log, frames, cam, cam_source, plan, origin,
                                                          decoder, tracker, first[0][0], first[0][1], notes)
        timings["track"] = time.perf_counter() - t1  # the marks and the clock: counted with the tracking
        cpu["track"] = time.process_time() - c1
        states = frame_states(log, plan.t_ns, position_offset_ns=c.offset_ns("position"),
                              attitude_offset_ns=c.offset_ns("attitude"), gimbal_offset_ns=c.offset_ns("gimbal"),
                              geoid_separation_m=separation_m)
        if not states.inside.any():
            resolved = ResolvedFlight(config, log, frames, cam, cam_source, current_reading(config, log), plan,
                                      None, origin)
            raise InputError(outside_telemetry(resolved), config.path)
        flight.plan, flight.states, flight.origin, flight.separation_m = plan, states, origin, separation_m
        if decoder.failed:
            notes.append(f"{len(decoder.failed)} frame(s) could not be decoded (damaged or truncated stream)")
        if named:
            result = locate_targets(flight, targets, first)
        else:
            result = finish_settings(flight, locate_target(flight, targets[0] if targets else None, first))
    finally:
        close = getattr(closable, "close", None)
        if close is not None:
            close()
    return result


# ---- outputs of one group ------------------------------------------------------------------------------------


def estimates_document(result: GroupResult) -> dict:
    """The `ridgeloc solve OBS.json --method all --json` document of the group's observations:
    {"estimates": {method: Estimate.to_dict(truth)}, "unsolved": {method: {"status", "reason"}} (only when some
    could not run)}."""
    doc: dict = {"estimates": {m: e.to_dict(result.truth_m) for m, e in result.estimates.items()}}
    failures = result.settings.get("solve_failures") or {}
    if failures:
        doc["unsolved"] = dict(failures)
    return doc


def _json_default(o):
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, (np.floating, np.integer, np.bool_)):
        return o.item()
    raise TypeError(f"not JSON-serialisable: {type(o).__name__}")


def group_files(result: GroupResult | FlightResult) -> dict[str, str]:
    """The per-group files `ridgeloc run` writes, name -> text: observations.json (the `ridgeloc solve` input,
    to re-solve without re-processing video), estimates.json (its --json output) and tracking.json (per-frame
    tracking quality). The report stage can pass them on as extra files of the group's folder. A flight with
    named targets: `pipeline.target_stage.flight_files` (issue 21)."""
    if isinstance(result, FlightResult):
        from pipeline.target_stage import flight_files

        return flight_files(result)
    return {
        "observations.json": json.dumps(result.observations.to_dict(), indent=1) + "\n",
        "estimates.json": json.dumps(estimates_document(result), indent=1, default=_json_default) + "\n",
        "tracking.json": json.dumps(result.tracking, indent=1, default=_json_default) + "\n",
    }


def write_group_outputs(outdir: str | PathLike, result: GroupResult) -> Path:
    """Write OUTDIR/<group>/ with `group_files(result)`, atomically: the folder is complete or absent."""
    from pipeline.atomic import atomic_dir

    final = Path(outdir) / result.name
    files = group_files(result)
    with atomic_dir(final) as tmp:
        for name, text in files.items():
            (tmp / name).write_text(text)
    return final
