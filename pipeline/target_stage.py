"""The per-target stages of a flight: track -> sync -> solve for each of its targets, sharing what the flight holds.

`pipeline.run.process_group` reads the logs, opens the video, plans the observation frames, estimates the clock
and interpolates the vehicle state ONCE per flight into a `SharedFlight`; `locate_target` then tracks one target
from its mark(s) through the planned frames (the decoded frames and their SIFT features come from the flight's
`ViewCache`: each frame is decoded and described once whatever the number of targets), drops the ranges that are
not on it, assembles its observations and solves them with every method. `locate_targets` runs every target of a
flight: a target that cannot be located becomes a `TargetFailure` (status and reason) and the others go on.
"""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass, field

import cv2
import numpy as np

from pipeline.check.conventions import current_reading
from pipeline.check.flight import ResolvedFlight, refusal_reason
from pipeline.errors import ConfigError, InputError, RidgelocError
from pipeline.geometry.frames import enu_from_lla
from pipeline.intrinsics import frame_K
from pipeline.results import FlightResult, GroupResult, TargetFailure
from pipeline.solve import mle_outputs
from pipeline.solve.observations import Sigma
from pipeline.sync.assemble import assemble_observations
from pipeline.targets import Mark, NamedTarget
from pipeline.track.sift import SiftTracker, TrackResult, ViewCache


@dataclass
class SharedFlight:
    """What every target of a flight shares: the config, logs, frame index and decoder, camera, the observation
    plan (final: after a clock estimate), the vehicle states at the planned frames, the ENU origin, the tracker
    and its cache of decoded frames' features, and the flight-level notes and timings."""

    config: object
    log: object
    frames: object
    decoder: object
    cam: object
    cam_source: str
    plan: object
    states: object
    origin: tuple[float, float, float]
    separation_m: float | None
    tracker: SiftTracker
    cache: ViewCache = field(default_factory=ViewCache)
    notes: list[str] = field(default_factory=list)
    timings: dict[str, float] = field(default_factory=dict)
    cpu: dict[str, float] = field(default_factory=dict)
    clock_estimate: object = None


def resolve_mark(flight: SharedFlight, mark: Mark | None, notes: list[str]) -> tuple[int, tuple[float, float]]:
    """(frame index, pixel) of a mark: a template is searched for in the observation frames; None is the
    boresighted laser's crosshair (the principal point) of the first observation frame."""
    config, plan, cam = flight.config, flight.plan, flight.cam
    if mark is None:
        if plan.n == 0:
            raise InputError("no observation frame to take the target from", config.path)
        idx = int(plan.frame_index[0])
        notes.append(f"target: the image centre of frame {idx}, where the laser points (no mark given)")
        return idx, (float(cam.cx_px), float(cam.cy_px))
    if mark.template is not None:
        template = cv2.imread(mark.template, cv2.IMREAD_GRAYSCALE)
        if template is None:
            raise ConfigError("target.template: not a readable image", mark.template)
        return flight.tracker.acquire(template, mark.template_pixel, flight.decoder, plan.frame_index.tolist())
    if mark.frame_index not in set(np.asarray(flight.frames.index).tolist()):
        where = f"{mark.source}: " if mark.source and mark.source != "target" else "target."
        raise ConfigError(f"{where}frame_index {mark.frame_index} is not a frame of the video", config.path)
    return int(mark.frame_index), (float(mark.pixel[0]), float(mark.pixel[1]))


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


def locate_target(flight: SharedFlight, target: NamedTarget | None, marks: list[tuple[int, tuple]] | None = None
                  ) -> GroupResult:
    """Track, synchronise and solve one target of the flight (None: the crosshair). `marks`: the target's marks
    already resolved to (frame index, pixel) (the first target's are, for the clock estimate). Raises a
    RidgelocError when the target cannot be located."""
    from pipeline.batch import report_stage
    from pipeline.run import _methods, intersection_angle_deg, solve_all

    config, plan, cam, states = flight.config, flight.plan, flight.cam, flight.states
    sel = config.observations
    notes: list[str] = []
    t1, c1 = time.perf_counter(), time.process_time()
    d0, dc0 = flight.decoder.seconds, flight.decoder.cpu_seconds
    if marks is None:  # (the first target's are resolved in process_group's "track" stage)
        report_stage("track")
        marks = [resolve_mark(flight, m, notes) for m in (target.marks if target is not None else [None])]
    tracks = [(idx, flight.tracker.track(flight.decoder, idx, px, plan.frame_index.tolist(),
                                         available=np.asarray(flight.frames.index).tolist(), cache=flight.cache))
              for idx, px in marks]
    track = _combine(tracks)
    decode_s = flight.decoder.seconds - d0
    timings = {"decode": decode_s, "track": time.perf_counter() - t1 - decode_s}
    cpu = {"decode": flight.decoder.cpu_seconds - dc0,
           "track": time.process_time() - c1 - (flight.decoder.cpu_seconds - dc0)}
    if track.lost.any():
        notes.append(f"target lost in {int(track.lost.sum())} of {plan.n} observation frames (pixel not used)")
    range_m = plan.range_m.copy()
    if sel.max_laser_offset_px is not None:
        # The laser is boresighted: when the target is far from the principal point the shot is not on it.
        where = np.where(np.isnan(track.pixel_px), track.predicted_px, track.pixel_px)
        offset = np.hypot(where[:, 0] - cam.cx_px, where[:, 1] - cam.cy_px)
        off_target = (offset > sel.max_laser_offset_px) & ~np.isnan(range_m)
        if off_target.any():
            range_m[off_target] = np.nan
            notes.append(f"{int(off_target.sum())} range(s) not used: the target was more than "
                         f"{sel.max_laser_offset_px:g} px from the image centre, off the laser's axis")

    report_stage("sync")
    t2, c2 = time.perf_counter(), time.process_time()
    if not states.inside.all():
        notes.append(f"{int((~states.inside).sum())} observation(s) outside the telemetry span were dropped")
    truth_lla = target.truth_lla if target is not None and target.truth_lla is not None else \
        (config.truth_lla() if target is None or target.name is None else named_truth_lla(config, target.name))
    truth_m = None if truth_lla is None else enu_from_lla(*truth_lla, flight.origin)
    sigma = Sigma.from_dict(dataclasses.asdict(config.sigma), "sigma")
    useful = states.inside & (~track.lost | ~np.isnan(range_m))
    if (states.inside & ~useful).any():
        notes.append(f"{int((states.inside & ~useful).sum())} observation(s) with neither pixel nor range dropped")
    if not useful.any():
        raise InputError("no usable observation: the target was never tracked and no laser range is valid",
                         config.path)
    resolved = ResolvedFlight(config, flight.log, flight.frames, cam, flight.cam_source,
                              current_reading(config, flight.log), plan, None, flight.origin)
    # A wrong convention gives an answer kilometres off with nothing else to show for it: refuse the flight.
    refusal = refusal_reason(resolved, plan.t_ns[useful], track.pixel_px[useful], range_m[useful])
    if refusal is not None:
        raise InputError(refusal, config.path)
    sub = dataclasses.replace(states, inside=useful)
    K_frames = frame_K(cam, flight.cam_source, flight.log, plan.t_ns)  # per frame for a zoom lens
    obs, _ = assemble_observations(sub, track.pixel_px, range_m, K=K_frames, dist=cam.dist,
                                   origin_lla=flight.origin,
                                   R_optical_from_gimbal=np.array(cam.R_optical_from_gimbal),
                                   lever_camera_m=config.lever_arms_m.camera,
                                   lever_rangefinder_m=config.lever_arms_m.rangefinder, sigma=sigma,
                                   truth_m=truth_m)
    timings["sync"] = time.perf_counter() - t2
    cpu["sync"] = time.process_time() - c2

    report_stage("solve")
    t3, c3 = time.perf_counter(), time.process_time()
    estimates, failures = solve_all(obs, _methods(config), config.solve.options)
    timings["solve"] = time.perf_counter() - t3
    cpu["solve"] = time.process_time() - c3
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
    tracking["reason"] = [_frame_reason(lost, via, inside, use) for lost, via, inside, use in
                          zip(track.lost, tracking["via"], states.inside, useful, strict=True)]
    tracking["t_ns"] = [int(t) for t in plan.t_ns]
    tracking["range_t_ns"] = [int(t) for t in plan.range_t_ns]
    mark_index, mark_px = marks[0]
    tracking["mark"] = {"frame_index": int(mark_index), "pixel_px": [float(mark_px[0]), float(mark_px[1])]}
    if len(marks) > 1:
        tracking["marks"] = [{"frame_index": int(i), "pixel_px": [float(p[0]), float(p[1])]} for i, p in marks]
    settings = {"notes": notes, "solve_failures": failures, "cpu_s": cpu}
    name = None if target is None else target.name
    return GroupResult(name=config.name, origin_lla=flight.origin, observations=obs, estimates=estimates,
                       truth_m=truth_m, intersection_angle_deg=gamma, timings_s=timings, settings=settings,
                       tracking=tracking, target=name)


def named_truth_lla(config, name: str) -> tuple[float, float, float] | None:
    """A named target's truth from the config's truth_file: its `targets` list ({name, lat_deg, lon_deg, alt_m})
    when it has one (synthetic flights with several targets), else None."""
    import json
    from pathlib import Path

    if config.truth is not None or config.truth_file is None:
        return None
    try:
        doc = json.loads(Path(config.truth_file).read_text())
        for t in doc.get("targets") or []:
            if t.get("name") == name:
                return float(t["lat_deg"]), float(t["lon_deg"]), float(t["alt_m"])
    except (OSError, ValueError, KeyError, TypeError, AttributeError) as exc:
        raise ConfigError(f"cannot read the targets' truth: {exc}", config.truth_file) from None
    return None


def finish_settings(flight: SharedFlight, r: GroupResult) -> GroupResult:
    """The flight's settings, notes and timings merged into one target's result (in place; returned)."""
    config, cam = flight.config, flight.cam
    settings = config.to_dict()
    settings["camera_resolved"] = {"source": flight.cam_source, **{k: getattr(cam, k) for k in (
        "width_px", "height_px", "fx_px", "fy_px", "cx_px", "cy_px", "dist")}}
    settings["notes"] = [*flight.notes, *r.settings["notes"]]
    if flight.clock_estimate is not None:
        settings["clock_estimate"] = flight.clock_estimate.to_dict()
    settings["solve_failures"] = r.settings["solve_failures"]
    settings["frames_decoded"] = flight.decoder.decoded
    settings["cpu_s"] = _add(flight.cpu, r.settings["cpu_s"])
    r.settings = settings
    r.timings_s = _add(flight.timings, r.timings_s)  # the flight's "track" (marks, clock) counts in each target's
    return r


def _add(a: dict[str, float], b: dict[str, float]) -> dict[str, float]:
    """Stage times summed key by key (a's keys first)."""
    out = dict(a)
    for k, v in b.items():
        out[k] = out.get(k, 0.0) + v
    return out


def locate_targets(flight: SharedFlight, targets: list[NamedTarget], first_marks) -> FlightResult:
    """Every named target of the flight; those that cannot be located become TargetFailures. Raises InputError
    when none can."""
    from pipeline.run import _methods

    results, failed = [], []
    for i, t in enumerate(targets):
        try:
            results.append(locate_target(flight, t, first_marks if i == 0 else None))
        except RidgelocError as exc:
            failed.append(TargetFailure(t.name, str(exc), tuple(_methods(flight.config))))
    if not results:
        raise InputError("no target could be located: " + "; ".join(f"{f.target}: {f.message}" for f in failed),
                         flight.config.path)
    stage_sum = dict(flight.timings)  # the flight's stages once, each target's own added
    for r in results:
        stage_sum = _add(stage_sum, r.timings_s)
        finish_settings(flight, r)
    # the flight's own settings: a target's without its solve failures and CPU times, with the flight's notes
    flight_settings = {k: v for k, v in results[0].settings.items() if k not in ("solve_failures", "cpu_s")}
    flight_settings["notes"] = list(flight.notes)
    return FlightResult(name=flight.config.name, targets=results, failed=failed, timings_s=stage_sum,
                        settings=flight_settings)


def flight_files(result: FlightResult) -> dict[str, str]:
    """The per-flight files of a flight with named targets, name -> text: estimates.json keyed by target
    ({"targets": {name: the single-target document | {"status": "not_located", "reason"}}}), and per located
    target <target>/observations.json, <target>/estimates.json and <target>/tracking.json (as for one target)."""
    import json

    from pipeline.run import _json_default, estimates_document, group_files

    doc: dict = {"targets": {}}
    files: dict[str, str] = {}
    for r in result.targets:
        doc["targets"][r.target] = estimates_document(r)
        files.update({f"{r.target}/{k}": v for k, v in group_files(r).items()})
    for f in result.failed:
        doc["targets"][f.target] = {"status": "not_located", "reason": f.message}
    return {"estimates.json": json.dumps(doc, indent=1, default=_json_default) + "\n", **files}
