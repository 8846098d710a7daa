"""`ridgeloc run`: one flight group through every stage, ingest -> track -> sync (geometry) -> solve -> compare.

`process_group(config)` is a pure top-level function of a `FlightConfig` (picklable both ways), so a batch can
run groups in worker processes. It returns a `GroupResult` with the wall time of each stage:
  ingest  reading telemetry and the frame index (no pixels decoded): the `pipeline.flight.Flight`,
  decode  decoding the frames the tracker asked for,
  track   the target mark, the clock estimate (clock.estimate), SIFT, matching, homographies and refinement,
  sync    interpolation of the vehicle state, poses, projection matrices, undistortion, the geometry check,
  solve   every estimator.
"""

from __future__ import annotations

import contextlib
import dataclasses
import time
from collections.abc import Sequence

import numpy as np

from pipeline.check.flight import outside_telemetry, refusal_reason
from pipeline.check.frame_centre import frame_centre_checks
from pipeline.clock_estimate import ClockEstimate, estimate_clock
from pipeline.errors import ConfigError, InputError, RidgelocError
from pipeline.flight import Flight, TargetMark, acquire_mark
from pipeline.flight_config import FlightConfig
from pipeline.geometry.frames import enu_from_lla
from pipeline.geometry.rays import intersection_angle_deg
from pipeline.intrinsics import frame_K
from pipeline.locate import process_photo_group
from pipeline.progress import report_stage
from pipeline.results import GroupResult
from pipeline.solve import mle_outputs
from pipeline.solve.estimate import Estimate
from pipeline.solve.observations import Observations, Sigma
from pipeline.sync.assemble import assemble_observations
from pipeline.sync.select import ObservationPlan
from pipeline.terrain.flight import add_dem_estimate, open_flight_dem, terrain_solve_options
from pipeline.track.sift import SiftTracker, TrackResult


class _StageTimes:
    """Wall and process-CPU seconds (all threads: the wall times' counterpart under load) of each stage; a stage
    is entered with `with times("track", decoder):` (the decoder's time is booked as "decode")."""

    def __init__(self):
        self.wall: dict[str, float] = {}
        self.cpu: dict[str, float] = {}

    @contextlib.contextmanager
    def __call__(self, stage: str, decoder=None):
        report_stage(stage)
        t, c = time.perf_counter(), time.process_time()
        d, dc = (decoder.seconds, decoder.cpu_seconds) if decoder is not None else (0.0, 0.0)
        yield
        if decoder is not None:
            d, dc = decoder.seconds - d, decoder.cpu_seconds - dc
            self.wall["decode"], self.cpu["decode"] = d, dc
        self.wall[stage] = time.perf_counter() - t - d
        self.cpu[stage] = time.process_time() - c - dc


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


def _estimate_clock(flight: Flight, tracker: SiftTracker, mark: TargetMark,
                    notes: list[str]) -> tuple[ClockEstimate, ObservationPlan]:
    """clock.estimate: the video offset from the flight (`pipeline.clock_estimate`); returns (the estimate, the
    observation plan at the estimated video offset, or the configured plan when not determined)."""
    est = estimate_clock(flight, tracker, mark)
    v = est.video
    if v is not None and v.determined:
        notes.append(f"clock estimated: {v.describe()}; the estimate is used")
        return est, flight.plan_at(round(v.offset_s * 1e9))
    notes.append(f"clock estimate: {v.describe() if v is not None else 'too few tracked frames'}; the "
                 "configured offset is used")
    return est, flight.plan


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
                 notes: list[str]) -> tuple[Observations, np.ndarray, np.ndarray]:
    """(observations, useful (m,), inside (m,)): the observations of the planned frames the telemetry covers with a
    tracked pixel or a range, after the geometry check (`pipeline.check.flight.refusal_reason`)."""
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
    refusal = refusal_reason(flight, plan.t_ns[useful], track.pixel_px[useful], range_m[useful])
    if refusal is not None:
        raise InputError(refusal, config.path)
    K = frame_K(flight.camera, flight.camera_source, flight.log, plan.t_ns)  # per frame when a zoom reports its FOV
    obs = assemble_observations(poses.subset(useful[inside]), plan.t_ns[useful], track.pixel_px[useful],
                                range_m[useful], K=K[useful], dist=flight.camera.dist,
                                sigma=sigma, truth_m=truth_m)
    return obs, useful, inside


def process_group(config: FlightConfig) -> GroupResult:
    """One flight group through its stages: open the flight (logs, frame index, camera, plan, origin); acquire
    the target mark; estimate the clock when clock.estimate asks; track the target; drop the ranges off the
    laser's axis; synchronize (poses, geometry check, observations); solve with every method; collect the
    result. A photo flight (files.photos) is located as `ridgeloc locate` does."""
    if config.files.photos:
        return process_photo_group(config)
    times, notes = _StageTimes(), []
    with times("ingest"):
        flight = Flight.open(config)
    with flight:
        plan = flight.require_plan()
        notes += flight.notes + plan.notes
        notes += [r.line() for _, r in frame_centre_checks(config, flight.log.formats)]  # the payload's own fix
        with times("track", flight.decoder):
            tracker = SiftTracker(config.tracking)
            mark = acquire_mark(config.target, frames=flight.frames, plan_frame_index=plan.frame_index,
                                camera=flight.camera, decoder=flight.decoder, tracker=tracker, config_path=config.path)
            notes += [mark.note] if mark.note else []
            origin = flight.require_origin()
            if config.altitude.geoid_separation_m == "auto" and flight.log.position.alt_datum == "amsl":
                notes.append(f"geoid separation {flight.separation_m:.2f} m (altitude.geoid_separation_m: auto, "
                             "EGM2008 at the first position)")
            clock_estimate = None
            if config.clock.estimate:
                clock_estimate, plan = _estimate_clock(flight, tracker, mark, notes)
            track = tracker.track(flight.decoder, mark.frame_index, mark.pixel_px, plan.frame_index.tolist(),
                                  available=np.asarray(flight.frames.index).tolist())
    if flight.decoder.failed:
        notes.append(f"{len(flight.decoder.failed)} frame(s) could not be decoded (damaged or truncated stream)")
    if track.lost.any():
        notes.append(f"target lost in {int(track.lost.sum())} of {plan.n} observation frames (pixel not used)")
    range_m = _on_axis_ranges(flight, plan, track, notes)
    truth_lla = config.truth_lla()
    truth_m = None if truth_lla is None else enu_from_lla(*truth_lla, origin)
    with times("sync"):
        obs, useful, inside = _synchronize(flight, plan, track, range_m, truth_m, notes)
    with times("solve"):  # with terrain: the `dem` method and the MLE's terrain prior
        dem = open_flight_dem(config.terrain)
        estimates, failures = solve_all(obs, _methods(config),
                                        terrain_solve_options(dem, config.terrain, origin, config.solve.options))
        add_dem_estimate(dem, obs, origin, estimates, failures, [f"frame {i}" for i in plan.frame_index[useful]])
    if not estimates:
        reasons = "; ".join(f"{m}: {f['reason']}" for m, f in failures.items())
        raise InputError(f"no estimator could solve the flight: {reasons}", config.path)
    if "mle" in estimates:  # its fit message, boresight bias and rejected observations
        notes.extend(mle_outputs.notes(estimates["mle"].extras, obs.t_ns, plan.frame_index[useful]))

    reference = truth_m
    if reference is None:
        best = estimates.get("mle") or next(iter(estimates.values()))
        reference = best.position_m
    gamma = intersection_angle_deg(obs.platform_m, reference) if obs.n >= 2 and np.isfinite(reference).all() else \
        float("nan")
    tracking = track.to_dict()  # every planned observation frame, the dropped ones included
    tracking["used"] = [bool(u) for u in useful]  # True: a row of observations.json, in the same order
    tracking["reason"] = [_frame_reason(lost, via, ins, use) for lost, via, ins, use in
                          zip(track.lost, tracking["via"], inside, useful, strict=True)]
    tracking["t_ns"] = [int(t) for t in plan.t_ns]
    tracking["range_t_ns"] = [int(t) for t in plan.range_t_ns]
    tracking["mark"] = mark.to_dict()
    cam = flight.camera
    settings = config.to_dict()
    settings["camera_resolved"] = {"source": flight.camera_source, **{k: getattr(cam, k) for k in (
        "width_px", "height_px", "fx_px", "fy_px", "cx_px", "cy_px", "dist")}}
    settings["notes"] = notes
    if clock_estimate is not None:
        settings["clock_estimate"] = clock_estimate.to_dict()
    settings["solve_failures"] = failures
    settings["frames_decoded"] = flight.decoder.decoded
    settings["cpu_s"] = times.cpu
    return GroupResult(name=config.name, origin_lla=origin, observations=obs, estimates=estimates, truth_m=truth_m,
                       intersection_angle_deg=gamma, timings_s=times.wall, settings=settings, tracking=tracking)
