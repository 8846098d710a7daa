"""The whole check of one flight (`check_flight`) and its one-screen text (`format_check`)."""

from __future__ import annotations

from dataclasses import dataclass, field

from pipeline.check.flight import GeometryResult, ResolvedFlight, geometry_checks, mapping_lines, resolve_flight
from pipeline.check.geometry import _fmt_m
from pipeline.errors import InputError, RidgelocError
from pipeline.flight_config import FlightConfig


@dataclass
class CheckResult:
    resolved: ResolvedFlight
    mapping: list[str]
    geometry: GeometryResult
    clock: object | None = None  # pipeline.sync.clock_estimate.ClockEstimate
    problems: list[str] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)

    def to_dict(self) -> dict:
        g = self.geometry
        c = g.cluster
        return {
            "flight": self.resolved.config.name, "mapping": self.mapping, "problems": self.problems,
            "warnings": self.warnings,
            "geometry": None if c is None else {
                "rays": g.what, "metric": c.metric, "spread_m": c.spread_m, "distance_m": c.distance_m,
                "ahead": c.ahead, "range_bias_m": c.range_bias_m, "range_bias_sigma_m": c.range_bias_sigma_m,
                "alternatives": [{"lines": a.lines, "notes": a.notes, "spread_m": a.cluster.spread_m}
                                 for a in g.alternatives]},
            "clock": None if self.clock is None else self.clock.to_dict(),
        }


def check_flight(config: FlightConfig, clock: bool = True) -> CheckResult:
    """Resolve `config` against its data and run every check; with `clock`, also estimate the clock offsets
    (whether or not clock.estimate is set; this tracks the target through the frames around each observation)."""
    r = resolve_flight(config)
    geo = geometry_checks(r)
    result = CheckResult(r, mapping_lines(r), geo, problems=list(geo.problems), warnings=list(geo.warnings))
    result.warnings[:0] = r.notes
    if clock and r.plan is not None and not geo.problems:
        try:
            result.clock = _estimate_clock(r)
        except RidgelocError as exc:
            result.warnings.append(f"clock offsets not estimated: {exc}")
        v = getattr(result.clock, "video", None)
        if v is not None and v.determined and not (v.low_s <= 0 <= v.high_s) and abs(v.delta_s) > 0.05:
            result.problems.append(f"the video clock looks {v.delta_s:+.3f} s off (95 % [{v.low_s:+.3f}, "
                                   f"{v.high_s:+.3f}] s): set clock.video_offset_s to {v.offset_s:.3f} (or the "
                                   "equivalent video_start), or clock: {estimate: true}")
    return result


def _estimate_clock(r: ResolvedFlight):
    from pipeline.run import open_frames
    from pipeline.sync.clock_estimate import estimate_clock
    from pipeline.track.sift import SiftTracker

    cfg = r.config
    _, decoder, closable = open_frames(cfg, r.log)
    try:
        tracker = SiftTracker(cfg.tracking)
        from pipeline.targets import flight_targets  # issue 21: the first target's first mark, as `run` takes it

        targets = flight_targets(cfg)
        mark = targets[0].marks[0] if targets else None
        if mark is None:  # the crosshair of the first observation frame, as `run` takes it
            mark_index, mark_px = int(r.plan.frame_index[0]), (float(r.camera.cx_px), float(r.camera.cy_px))
        elif mark.template is not None:
            import cv2

            template = cv2.imread(mark.template, cv2.IMREAD_GRAYSCALE)
            if template is None:
                raise InputError("target.template: not a readable image", mark.template)
            mark_index, mark_px = tracker.acquire(template, mark.template_pixel, decoder,
                                                  r.plan.frame_index.tolist())
        else:
            mark_index, mark_px = mark.frame_index, mark.pixel
        return estimate_clock(r, decoder, tracker, mark_index, mark_px)
    finally:
        close = getattr(closable, "close", None)
        if close is not None:
            close()


def format_check(result: CheckResult) -> str:
    lines = list(result.mapping)
    g = result.geometry
    c = g.cluster
    lines.append("geometry")
    if c is not None:
        lines.append(f"  {g.what} at {c.n} observations ({c.n_ranged} with a range): {c.describe()}"
                     + ("" if c.consistent else "  << not converging"))
        if c.consistent and c.range_bias_m == c.range_bias_m:  # not NaN
            lines.append(f"  laser range - distance to where the lines of sight meet: {c.range_bias_m:+.1f} m "
                         f"(+-{c.range_bias_sigma_m:.1f} m)")
    for a in g.alternatives:
        lines.append(f"  alternative clustering within {_fmt_m(a.cluster.spread_m)} ({a.cluster.metric}):")
        lines += [f"      {line}" for line in a.lines]
        lines += [f"      ({note})" for note in a.notes]
    if result.clock is not None:
        lines.append("clock")
        lines.append("  " + result.clock.describe())
    lines += [f"warning: {w}" for w in result.warnings]
    lines += [f"problem: {p}" for p in result.problems]
    lines.append("consistent" if not result.problems else f"{len(result.problems)} problem(s)")
    return "\n".join(lines)
