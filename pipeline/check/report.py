"""The whole check of one flight (`check_flight`) and its one-screen text (`format_check`)."""

from __future__ import annotations

from dataclasses import dataclass, field

from pipeline.check.flight import GeometryResult, geometry_checks, mapping_lines
from pipeline.check.geometry import PARALLEL_DEG, _fmt_m
from pipeline.clock_estimate import ClockEstimate, estimate_clock
from pipeline.errors import RidgelocError
from pipeline.flight import Flight, acquire_mark
from pipeline.flight_config import FlightConfig
from pipeline.ingest.frame_centre import LARGE_M, FrameCentreCheck, frame_centre_checks, frame_centre_document
from pipeline.targets import first_mark
from pipeline.track.sift import SiftTracker


def add_frame_centre(result, checks: list[tuple[str, FrameCentreCheck]]) -> None:
    """Put the checks on a check result; a convention error (median above LARGE_M) is also a problem."""
    result.frame_centre = checks
    result.problems += [f"{f}: {r.line()}" for f, r in checks if r.median_m > LARGE_M]


@dataclass
class CheckResult:
    resolved: Flight
    mapping: list[str]
    geometry: GeometryResult
    clock: ClockEstimate | None = None
    problems: list[str] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)
    frame_centre: list = field(default_factory=list)  # [(file, check.frame_centre.FrameCentreCheck)]

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
            "frame_centre": frame_centre_document(self.frame_centre),
        }


def check_flight(config: FlightConfig, clock: bool = True) -> CheckResult:
    """Resolve `config` against its data and run every check; with `clock`, also estimate the clock offsets
    (whether or not clock.estimate is set; this tracks the target through the frames around each observation)."""
    with Flight.open(config) as r:
        geo = geometry_checks(r)
        result = CheckResult(r, mapping_lines(r), geo, problems=list(geo.problems), warnings=list(geo.warnings))
        result.warnings[:0] = r.notes + (r.plan.warnings if r.plan is not None else [])
        add_frame_centre(result, frame_centre_checks(r.log))
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


def _estimate_clock(r: Flight) -> ClockEstimate:
    tracker = SiftTracker(r.config.tracking)
    mark = acquire_mark(first_mark(r.config), frames=r.frames, plan_frame_index=r.plan.frame_index,
                        camera=r.camera, decoder=r.decoder, tracker=tracker, config_path=r.config.path)
    return estimate_clock(r, tracker, mark)  # the first target's first mark, as `run` takes it


def verdict_line(result: CheckResult) -> str:
    """check's last line: the problems' count, else consistent, saying so when warnings stand above it."""
    if result.problems:
        return f"{len(result.problems)} problem(s)"
    n = len(result.warnings)
    return "consistent" if not n else f"consistent conventions, but {n} warning(s) above: read them before trusting " \
                                      "an answer"


def format_check(result: CheckResult) -> str:
    lines = list(result.mapping)
    g = result.geometry
    c = g.cluster
    lines.append("geometry")
    if c is not None:
        lines.append(f"  {g.what} at {c.n} observations ({c.n_ranged} with a range): {c.describe()}"
                     + ("  << no baseline" if c.no_baseline else "" if c.consistent else "  << not converging"))
        if c.consistent and c.range_bias_m == c.range_bias_m:  # not NaN
            along = "nearly parallel lines of sight" if c.gamma_deg < PARALLEL_DEG else \
                f"lines of sight {c.gamma_deg:.0f} deg apart"
            sigma = (f"undetermined: +-{c.meet_along_sigma_m:.0f} m along {along}"
                     if c.meet_undetermined else f"+-{c.range_bias_sigma_m:.1f} m")
            lines.append(f"  laser range - distance to where the lines of sight meet: {c.range_bias_m:+.1f} m "
                         f"({sigma})")
    for a in g.alternatives:
        lines.append(f"  alternative clustering within {_fmt_m(a.cluster.spread_m)} ({a.cluster.metric}):")
        lines += [f"      {line}" for line in a.lines]
        lines += [f"      ({note})" for note in a.notes]
    if result.clock is not None:
        lines.append("clock")
        lines.append("  " + result.clock.describe())
    lines += [f"  {r.line()}" for _, r in result.frame_centre]
    lines += [f"warning: {w}" for w in result.warnings]
    lines += [f"problem: {p}" for p in result.problems]
    lines.append(verdict_line(result))
    return "\n".join(lines)
