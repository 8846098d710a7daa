"""The per-target stages of a flight: track -> on-axis ranges -> synchronize -> solve -> result, for each target.

`pipeline.run.process_group` opens the `Flight` once (logs, frame index, camera, plan, origin), acquires the first
target's marks and estimates the clock once, into a `FlightPass`; `locate_target` then tracks one target from its
mark(s) through the planned frames (decoded frames and their SIFT features come from the pass's `ViewCache`: each
frame is decoded and described once whatever the number of targets), drops the ranges not on it, assembles its
observations and solves them with every method. `locate_targets` runs every named target of a flight: each is
tracked and synchronised, then all are solved together (`pipeline.solve.methods.solve_problems`: the same answers
as one at a time, each estimator's kernel run once for the targets with the same number of frames); one that
cannot be located becomes a `TargetFailure` (status and reason) and the others go on.
"""

from __future__ import annotations

import contextlib
import dataclasses
import functools
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from pipeline.answer import choose_answer, unsolved_reasons
from pipeline.check.flight import outside_telemetry, run_checks
from pipeline.clock_estimate import ClockEstimate
from pipeline.errors import ConfigError, InputError, RidgelocError, none_located
from pipeline.flight import Flight, TargetMark, acquire_mark
from pipeline.flight_config import FMV_SUFFIXES, FlightConfig
from pipeline.geometry.frames import enu_from_lla
from pipeline.geometry.rays import intersection_angle_deg
from pipeline.ingest.clocks import find_link, map_clock
from pipeline.intrinsics import frame_K
from pipeline.progress import report_stage
from pipeline.results import FlightResult, GroupResult, TargetFailure
from pipeline.solve import mle_outputs
from pipeline.solve.estimate import Estimate
from pipeline.solve.observations import Observations, Sigma
from pipeline.sync.assemble import assemble_observations
from pipeline.sync.select import ObservationPlan
from pipeline.targets import Mark, NamedTarget, read_truth_file
from pipeline.terrain.flight import add_dem_estimate, dem_answer_inputs, terrain_solve_options
from pipeline.track.sift import SiftTracker, TrackResult, ViewCache


class StageTimes:
    """Wall and process-CPU seconds (all threads: the wall times' counterpart under load) of each stage; a stage
    is entered with `with times("track", decoder):` (the decoder's time is booked as "decode"). Entering a stage
    again adds to it."""

    def __init__(self):
        self.wall: dict[str, float] = {}
        self.cpu: dict[str, float] = {}

    def _add(self, stage: str, wall: float, cpu: float) -> None:
        self.wall[stage] = self.wall.get(stage, 0.0) + wall
        self.cpu[stage] = self.cpu.get(stage, 0.0) + cpu

    @contextlib.contextmanager
    def __call__(self, stage: str, decoder=None):
        report_stage(stage)
        t, c = time.perf_counter(), time.process_time()
        d, dc = (decoder.seconds, decoder.cpu_seconds) if decoder is not None else (0.0, 0.0)
        yield
        if decoder is not None:
            d, dc = decoder.seconds - d, decoder.cpu_seconds - dc
            self._add("decode", d, dc)
        self._add(stage, time.perf_counter() - t - d, time.process_time() - c - dc)

    def plus(self, other: StageTimes) -> StageTimes:
        """These times and `other`'s summed stage by stage (this one's stages first)."""
        out = StageTimes()
        for s in (self, other):
            for k in s.wall:
                out._add(k, s.wall[k], s.cpu[k])
        return out


@dataclass
class FlightPass:
    """What every target of one flight shares: the open flight, the observation plan (final: after a clock
    estimate), the ENU origin, the tracker and its cache of decoded frames' features, the DEM (terrain, or None),
    and the flight-level notes, stage times and clock estimate."""

    flight: Flight
    plan: ObservationPlan
    origin: tuple[float, float, float]
    tracker: SiftTracker
    cache: ViewCache | None
    dem: object = None
    notes: list[str] = field(default_factory=list)
    times: StageTimes = field(default_factory=StageTimes)
    clock_estimate: ClockEstimate | None = None

    @functools.cached_property
    def available_frames(self) -> list[int]:
        """The frame index's frame numbers (the tracker's stepping stones), one list for every target."""
        return np.asarray(self.flight.frames.index).tolist()

    @functools.cached_property
    def truth_targets(self) -> dict[str, tuple[float, float, float]]:
        """The truth_file's targets (`truth_file_targets`), read once for every target of the flight."""
        return truth_file_targets(self.flight.config)

    def acquire(self, mark: Mark | None, notes: list[str]) -> TargetMark:
        """A mark as a frame and pixel (`pipeline.flight.acquire_mark`), its note added to `notes`."""
        f = self.flight
        m = acquire_mark(mark, frames=f.frames, plan_frame_index=self.plan.frame_index, camera=f.camera,
                         decoder=f.decoder, tracker=self.tracker, config_path=f.config.path)
        notes += [m.note] if m.note else []
        return m


def methods_of(config: FlightConfig) -> list[str]:
    from pipeline.solve import METHODS

    if config.solve.methods == "all":
        return list(METHODS)
    methods = [config.solve.methods] if isinstance(config.solve.methods, str) else list(config.solve.methods)
    unknown = [m for m in methods if m not in METHODS]
    if unknown:
        raise ConfigError(f"solve.methods: unknown method(s) {unknown} (known: {', '.join(METHODS)})", config.path)
    return methods


def solve_all(problems: Sequence[Observations], methods: Sequence[str], options: dict
              ) -> list[tuple[dict[str, Estimate], dict]]:
    """Every method on each problem (a flight's targets, together: `pipeline.solve.methods.solve_problems`): per
    problem (estimates, {method: {"status", "reason"}} for those that could not run)."""
    from pipeline.solve import unsolved_status
    from pipeline.solve.methods import solve_problems

    out = []
    for answers in solve_problems(problems, methods, options):
        estimates = {m: a for m, a in answers.items() if not isinstance(a, Exception)}
        failures = {m: {"status": unsolved_status(a), "reason": str(a)} for m, a in answers.items()
                    if isinstance(a, Exception)}
        out.append((estimates, failures))
    return out


def _frame_reason(lost: bool, via: str, inside: bool, used: bool) -> str | None:
    """Why a planned observation frame lacks its pixel or is not used (None when it is whole)."""
    why = []
    if lost:
        why.append(f"target lost: {via}")
    if not inside:
        why.append("outside the telemetry span: dropped")
    elif not used:
        why.append("neither a tracked pixel nor a valid range: dropped")
    return "; ".join(why) or None


def _combine(tracks: list[tuple[int, TrackResult]]) -> TrackResult:
    """Per frame, the track from the nearest mark frame that holds the target there (the first mark's when none
    does): several marks of one point re-acquire it where one mark's track loses it."""
    if len(tracks) == 1:
        return tracks[0][1]
    out = []
    for k in range(len(tracks[0][1].frames)):
        options = sorted(tracks, key=lambda mt: abs(mt[1].frames[k].frame_index - mt[0]))
        found = [t.frames[k] for _, t in options if not t.frames[k].lost]
        out.append(found[0] if found else tracks[0][1].frames[k])
    return TrackResult(out)


def _on_axis_ranges(flight: Flight, plan: ObservationPlan, track: TrackResult, notes: list[str]) -> np.ndarray:
    """The planned ranges (m,), NaN where the target was more than observations.max_laser_offset_px from the
    principal point: the laser is boresighted, so the shot was not on the target."""
    range_m, limit, cam = plan.range_m.copy(), flight.config.observations.max_laser_offset_px, flight.camera
    if limit is None:
        return range_m
    where = np.where(np.isnan(track.pixel_px), track.predicted_px, track.pixel_px)
    off_target = (np.hypot(where[:, 0] - cam.cx_px, where[:, 1] - cam.cy_px) > limit) & ~np.isnan(range_m)
    if off_target.any():
        range_m[off_target] = np.nan
        notes.append(f"{int(off_target.sum())} range(s) not used: the target was more than {limit:g} px from the "
                     "image centre, off the laser's axis")
    return range_m


def _synchronize(flight: Flight, plan: ObservationPlan, track: TrackResult, range_m: np.ndarray, truth_m,
                 notes: list[str]) -> tuple[Observations, np.ndarray, np.ndarray, list[str]]:
    """(observations, useful (m,), inside (m,), geometry warnings): the observations of the planned frames the
    telemetry covers with a tracked pixel or a range, after the geometry checks (`pipeline.check.flight.run_checks`;
    its warnings are also added to notes)."""
    config = flight.config
    poses, inside = flight.poses(plan.t_ns)
    if not inside.any():
        raise InputError(outside_telemetry(flight), config.path)
    if not inside.all():
        notes.append(f"{int((~inside).sum())} observation(s) outside the telemetry span were dropped")
    sigma = Sigma.from_dict(dataclasses.asdict(config.sigma), "sigma")
    useful = inside & (~track.lost | ~np.isnan(range_m))
    if (inside & ~useful).any():
        notes.append(f"{int((inside & ~useful).sum())} observation(s) with neither pixel nor range dropped")
    if not useful.any():
        raise InputError("no usable observation: the target was never tracked and no laser range is valid",
                         config.path)
    # A wrong convention gives an answer kilometres off with nothing else to show for it: refuse the flight.
    refusal, geometry_warnings = run_checks(flight, plan.t_ns[useful], track.pixel_px[useful], range_m[useful])
    if refusal is not None:
        raise InputError(refusal, config.path)
    geometry_warnings = plan.warnings + geometry_warnings  # ranges lost to a clock offset: every answer says so
    notes += geometry_warnings
    K = frame_K(flight.camera, flight.camera_source, flight.log, plan.t_ns)  # per frame when a zoom reports its FOV
    obs = assemble_observations(poses.subset(useful[inside]), plan.t_ns[useful], track.pixel_px[useful],
                                range_m[useful], K=K[useful], dist=flight.camera.dist,
                                sigma=sigma, truth_m=truth_m)
    return obs, useful, inside, geometry_warnings


def payload_frame_centre_deg(flight: Flight, t_ns: np.ndarray) -> list | None:
    """The payload's frame centre (KLV tags 23/24, EG 0104) at telemetry times t_ns (m,): [lat_deg, lon_deg]
    interpolated in time, None outside its span; None when the logs give none. It comes with the positions, so
    their clock offset applies."""
    fc = flight.log.frame_centre
    if fc is None or fc.t_ns.size == 0:
        return None
    t = np.asarray(t_ns, dtype=np.int64) - flight.config.clock.offset_ns("position")
    inside = (t >= fc.t_ns[0]) & (t <= fc.t_ns[-1])
    lat = np.interp(t, fc.t_ns, fc.lat_deg)
    lon = np.interp(t, fc.t_ns, fc.lon_deg)
    return [[round(float(a), 8), round(float(b), 8)] if ok and np.isfinite(a) and np.isfinite(b) else None
            for a, b, ok in zip(lat, lon, inside, strict=True)]


def truth_file_targets(config: FlightConfig) -> dict[str, tuple[float, float, float]]:
    """{name: (lat_deg, lon_deg, alt_m)} of the config's truth_file's named targets (synthetic flights with several
    targets); {} without a truth_file or when the config states its truth."""
    if config.truth is not None or config.truth_file is None:
        return {}
    return read_truth_file(config.truth_file).named()


def _truth_lla(fp: FlightPass, target: NamedTarget | None):
    config = fp.flight.config
    if target is not None and target.truth_lla is not None:
        return target.truth_lla
    if target is None or target.name is None:
        return config.truth_lla()
    return fp.truth_targets.get(target.name)


@dataclass
class _Tracked:
    """One target tracked and synchronised (`_track_and_sync`), waiting for its solve."""

    target: NamedTarget | None
    marks: list[TargetMark]
    track: TrackResult
    obs: Observations
    useful: np.ndarray
    inside: np.ndarray
    truth_m: np.ndarray | None
    notes: list[str]
    times: StageTimes
    geometry_warnings: list[str]


def _track_and_sync(fp: FlightPass, target: NamedTarget | None, marks: list[TargetMark] | None) -> _Tracked:
    """Track one target from its mark(s), drop the ranges off its axis, synchronise. Raises a RidgelocError when
    it has no usable observation."""
    flight, plan = fp.flight, fp.plan
    times, notes = StageTimes(), []
    with times("track", flight.decoder):
        if marks is None:
            marks = [fp.acquire(m, notes) for m in (target.marks if target is not None else [None])]
        tracks = [(m.frame_index, fp.tracker.track(flight.decoder, m.frame_index, m.pixel_px,
                                                   plan.frame_index.tolist(),
                                                   available=fp.available_frames,
                                                   cache=fp.cache)) for m in marks]
        track = _combine(tracks)
    if flight.decoder.failed:
        notes.append(f"{len(flight.decoder.failed)} frame(s) could not be decoded (damaged or truncated stream)")
    if track.lost.any():
        notes.append(f"target lost in {int(track.lost.sum())} of {plan.n} observation frames (pixel not used)")
    range_m = _on_axis_ranges(flight, plan, track, notes)
    truth_lla = _truth_lla(fp, target)
    truth_m = None if truth_lla is None else enu_from_lla(*truth_lla, fp.origin)
    with times("sync"):
        obs, useful, inside, geometry_warnings = _synchronize(flight, plan, track, range_m, truth_m, notes)
    return _Tracked(target, marks, track, obs, useful, inside, truth_m, notes, times, geometry_warnings)


def _solve_tracked(fp: FlightPass, tracked: list[_Tracked]) -> list[tuple[dict[str, Estimate], dict]]:
    """Every method on every tracked target of the flight at once (`solve_all`), with terrain the `dem` method
    and the MLE's terrain prior; the solve's time is booked to each target's times in equal shares (they are
    solved together)."""
    config = fp.flight.config
    times = StageTimes()
    with times("solve"):
        solved = solve_all([t.obs for t in tracked], methods_of(config),
                           terrain_solve_options(fp.dem, config.terrain, fp.origin, config.solve.options))
        for t, (estimates, failures) in zip(tracked, solved, strict=True):
            add_dem_estimate(fp.dem, t.obs, fp.origin, estimates, failures,
                             [f"frame {i}" for i in fp.plan.frame_index[t.useful]])
    for t in tracked:
        t.times._add("solve", times.wall["solve"] / len(tracked), times.cpu["solve"] / len(tracked))
    return solved


def unstated_accuracies(config: FlightConfig, method: str | None = None) -> list[str]:
    """The position and pointing accuracies a video flight's config leaves unstated (`sigma:` position_m,
    attitude_deg), which the answer's uncertainty then takes from defaults and the flight's own misfit; those the
    answer's `method` states in its own `sigma` option (`solve.options.mle.sigma`) count as stated."""
    own = ((config.solve.options or {}).get(method) or {}).get("sigma") or {} if method else {}
    return [k for k in ("position_m", "attitude_deg") if getattr(config.sigma, k) is None and own.get(k) is None]


def unix_times_ns(log, t_ns: np.ndarray) -> list[int] | None:
    """Times on the telemetry clock (the position's) mapped onto UNIX time through the log's clock link, where the
    clock is another (a KLV video's "video" clock, linked by its packets' time stamps); None where it is UNIX
    time already or no link exists."""
    clock = getattr(log.position, "clock", "unix")
    if clock == "unix":
        return None
    link, reverse = find_link(log.clock_links, clock, "unix")
    return None if link is None else [int(x) for x in map_clock(np.asarray(t_ns, np.int64), link, reverse)]


def _result(fp: FlightPass, t: _Tracked, estimates: dict[str, Estimate], failures: dict) -> GroupResult:
    """One target's result with the flight's settings, notes and times added; where no estimator could solve it,
    its answer says why (`not_located`)."""
    flight, plan, config = fp.flight, fp.plan, fp.flight.config
    obs, useful, inside, track, marks, notes = t.obs, t.useful, t.inside, t.track, t.marks, t.notes
    if "mle" in estimates:  # its fit message, boresight bias and rejected observations
        notes.extend(mle_outputs.notes(estimates["mle"].extras, obs.t_ns, plan.frame_index[useful]))
    with t.times("answer"):
        answer = choose_answer(obs, estimates, unsolved_reasons(failures), fp.origin, options=config.solve.options,
                               **dem_answer_inputs(fp.dem, None if config.terrain is None else
                                                   config.terrain.vertical_sigma_m, obs, fp.origin,
                                                   estimates.get("dem")))
    unstated = unstated_accuracies(config, answer.method)
    answer_warnings = []
    if unstated and answer.located:
        where = (f"in a flight config for the clip (`ridgeloc init {config.path} -o flight.yaml`, then `sigma:`)"
                 if Path(config.path or "").suffix.lower() in FMV_SUFFIXES else "(docs/flight_config.md)")
        answer_warnings.append(
            f"sensor accuracies not stated ({', '.join('sigma.' + k for k in unstated)}): the uncertainty rests on "
            "defaults and on this flight's own misfit, which a short or smooth flight measures poorly; state your "
            f"sensors' specifications {where}")
        notes += answer_warnings

    reference = t.truth_m
    if reference is None:
        reference = answer.position_m if answer.located else np.full(3, np.nan)
    gamma = intersection_angle_deg(obs.platform_m, reference) if obs.n >= 2 and np.isfinite(reference).all() else \
        float("nan")
    tracking = track.to_dict()  # every planned observation frame, the dropped ones included
    tracking["used"] = [bool(u) for u in useful]  # True: a row of observations.json, in the same order
    tracking["reason"] = [_frame_reason(lost, via, ins, use) for lost, via, ins, use in
                          zip(track.lost, tracking["via"], inside, useful, strict=True)]
    tracking["t_ns"] = [int(x) for x in plan.t_ns]
    unix = unix_times_ns(flight.log, plan.t_ns)
    if unix is not None:  # the frames' UNIX times (a KLV video: its packets' time stamps), for the overlay's UTC
        tracking["unix_t_ns"] = unix
    payload = payload_frame_centre_deg(flight, plan.t_ns)
    if payload is not None:  # the KLV's own frame centre, for the report's map beside ridgeloc's
        tracking["payload_frame_centre_deg"] = payload
    tracking["range_t_ns"] = [int(x) for x in plan.range_t_ns]
    if plan.range_error_m is not None:  # observations at key frames: the ranges' estimated interpolation error
        tracking["range_error_m"] = [None if not np.isfinite(e) else round(float(e), 4) for e in plan.range_error_m]
    tracking["mark"] = marks[0].to_dict()
    if len(marks) > 1:
        tracking["marks"] = [m.to_dict() for m in marks]
    total = fp.times.plus(t.times)  # the flight's ingest and track (marks, clock) count in each target's
    cam = flight.camera
    settings = config.to_dict()
    settings["camera_resolved"] = {"source": flight.camera_source, **{k: getattr(cam, k) for k in (
        "width_px", "height_px", "fx_px", "fy_px", "cx_px", "cy_px", "dist")}}
    settings["notes"] = [*fp.notes, *notes]
    if answer_warnings:  # what limits the answer's uncertainty itself: the console and the TAK marker say it too
        settings["answer_warnings"] = answer_warnings
    if flight.notes:  # the logs' own warnings (also in notes): damage read past, shown on the console too
        settings["input_warnings"] = list(flight.notes)
    if t.geometry_warnings:  # also in notes; every estimate's reason in the exports carries them
        settings["geometry_warnings"] = list(t.geometry_warnings)
    if fp.clock_estimate is not None:
        settings["clock_estimate"] = fp.clock_estimate.to_dict()
    settings["solve_failures"] = failures
    settings["frames_decoded"] = flight.decoder.decoded
    settings["cpu_s"] = total.cpu
    return GroupResult(name=config.name, origin_lla=fp.origin, observations=obs, estimates=estimates,
                       truth_m=t.truth_m, intersection_angle_deg=gamma, timings_s=total.wall, settings=settings,
                       tracking=tracking, target=None if t.target is None else t.target.name, answer=answer)


def locate_target(fp: FlightPass, target: NamedTarget | None, marks: list[TargetMark] | None = None
                  ) -> tuple[GroupResult, StageTimes]:
    """Track, synchronise and solve one target of the flight (None: the crosshair): (its result with the flight's
    settings, notes and times added, its own stage times). `marks`: the target's marks already acquired (the
    first target's are, for the clock estimate). Raises a RidgelocError when the target cannot be located."""
    t = _track_and_sync(fp, target, marks)
    (estimates, failures), = _solve_tracked(fp, [t])
    return _result(fp, t, estimates, failures), t.times


def locate_targets(fp: FlightPass, targets: list[NamedTarget], first_marks: list[TargetMark]) -> FlightResult:
    """Every named target of the flight; those that cannot be located become TargetFailures. Raises InputError
    when none can."""
    outcome: list[GroupResult | TargetFailure] = [None] * len(targets)
    tracked: dict[int, _Tracked] = {}
    methods = tuple(methods_of(fp.flight.config))
    for i, t in enumerate(targets):  # each tracked and synchronised; then all solved at once
        try:
            tracked[i] = _track_and_sync(fp, t, first_marks if i == 0 else None)
        except RidgelocError as exc:
            outcome[i] = TargetFailure(t.name, str(exc), methods)
    total = fp.times
    if tracked:
        for (i, t), (estimates, failures) in zip(tracked.items(), _solve_tracked(fp, list(tracked.values())),
                                                 strict=True):
            try:
                outcome[i] = _result(fp, t, estimates, failures)
            except RidgelocError as exc:
                outcome[i] = TargetFailure(t.target.name, str(exc), methods)
            total = total.plus(t.times)  # the flight's stages once, each target's own added
    results = [o for o in outcome if isinstance(o, GroupResult)]
    failed = [o for o in outcome if isinstance(o, TargetFailure)]
    if not results:
        raise none_located(failed, fp.flight.config.path)
    for r in results:
        r.settings["frames_decoded"] = fp.flight.decoder.decoded  # the flight's frames, decoded once for all
    # the flight's own settings: a target's without its solve failures, geometry warnings and CPU times, with the
    # flight's notes
    flight_settings = {k: v for k, v in results[0].settings.items()
                       if k not in ("solve_failures", "geometry_warnings", "cpu_s")}
    flight_settings["notes"] = list(fp.notes)
    flight_settings["frames_decoded"] = fp.flight.decoder.decoded
    return FlightResult(name=fp.flight.config.name, targets=results, failed=failed, timings_s=total.wall,
                        settings=flight_settings)
