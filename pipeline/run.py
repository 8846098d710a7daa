"""`ridgeloc run`: one flight group through every stage, ingest -> track -> sync (geometry) -> solve -> compare.

`process_group(config)` is a pure top-level function of a `FlightConfig` (picklable both ways), so a batch can
run groups in worker processes. It returns a `GroupResult` (a `FlightResult` of one per target for a flight with
named targets, issue 21) with the wall time of each stage:
  ingest  reading telemetry and the frame index (no pixels decoded): the `pipeline.flight.Flight`,
  decode  waiting for the frames the tracker asked for (a video's are decoded ahead on worker threads while
          the tracker works: their decoding overlaps track, and its CPU counts there),
  track   the target mark, the clock estimate (clock.estimate), SIFT, matching, homographies and refinement,
  sync    interpolation of the vehicle state, poses, projection matrices, undistortion, the geometry check,
  solve   every estimator.
"""

from __future__ import annotations

from pipeline.clock_estimate import ClockEstimate, estimate_clock
from pipeline.flight import Flight, TargetMark
from pipeline.flight_config import FlightConfig
from pipeline.ingest.frame_centre import frame_centre_checks
from pipeline.locate import process_photo_group
from pipeline.results import FlightResult, GroupResult
from pipeline.sync.select import ObservationPlan
from pipeline.target_stage import FlightPass, StageTimes, locate_target, locate_targets
from pipeline.targets import check_marks_in_video, flight_targets
from pipeline.terrain.flight import open_flight_dem
from pipeline.track.sift import SiftTracker, ViewCache


def _estimate_clock(flight: Flight, tracker: SiftTracker, mark: TargetMark, notes: list[str],
                    cache: ViewCache | None = None) -> tuple[ClockEstimate, ObservationPlan]:
    """clock.estimate: the video offset from the flight (`pipeline.clock_estimate`); returns (the estimate, the
    observation plan at the estimated video offset, or the configured plan when not determined)."""
    est = estimate_clock(flight, tracker, mark, cache)
    v = est.video
    if v is not None and v.determined:
        notes.append(f"clock estimated: {v.describe()}; the estimate is used")
        return est, flight.plan_at(round(v.offset_s * 1e9))
    notes.append(f"clock estimate: {v.describe() if v is not None else 'too few tracked frames'}; the "
                 "configured offset is used")
    return est, flight.plan


def process_group(config: FlightConfig) -> GroupResult | FlightResult:
    """One flight group through its stages: open the flight once (logs, frame index, camera, plan, origin); check
    the named targets' marks against the video; acquire the first target's marks and estimate the clock when
    clock.estimate asks (once per flight); then each target (`pipeline.target_stage.locate_target`): track, drop
    the ranges off the laser's axis, synchronize, solve, collect. A GroupResult for the single `target:` (or the
    crosshair), a FlightResult (one GroupResult per named target) for `targets:` / `marks_file:`. A photo flight
    (files.photos) is located as `ridgeloc locate` does."""
    if config.files.photos:
        return process_photo_group(config)
    times, notes = StageTimes(), []
    with times("ingest"):
        flight = Flight.open(config)
    targets = flight_targets(config)  # [] (crosshair), [one unnamed target], or named targets
    named = bool(targets) and targets[0].name is not None
    with flight:
        plan = flight.require_plan()
        if named:  # every mark checked against the video before anything runs
            check_marks_in_video(targets, flight.frames.index, flight.camera.width_px, flight.camera.height_px,
                                 config.path)
        notes += flight.notes + plan.notes
        notes += [r.line() for _, r in frame_centre_checks(flight.log)]  # the payload's own fix
        with times("track", flight.decoder):
            # the cache serves frames decoded for one track to another: named targets, the clock estimate's
            cache = ViewCache(share_matches=named) if named or config.clock.estimate else None
            fp = FlightPass(flight, plan, None, SiftTracker(config.tracking), cache, notes=notes, times=times)
            first = [fp.acquire(m, notes) for m in (targets[0].marks if targets else [None])]
            fp.origin = flight.require_origin()
            if config.altitude.geoid_separation_m == "auto" and flight.log.position.alt_datum == "amsl":
                notes.append(f"geoid separation {flight.separation_m:.2f} m (altitude.geoid_separation_m: auto, "
                             "EGM2008 at the first position)")
            if config.clock.estimate:  # the flight's clock, from the first target's first mark
                fp.clock_estimate, fp.plan = _estimate_clock(flight, fp.tracker, first[0], notes, fp.cache)
        fp.dem = open_flight_dem(config.terrain)
        if named:
            result = locate_targets(fp, targets, first)
        else:
            result = locate_target(fp, targets[0] if targets else None, first)[0]
    return result
