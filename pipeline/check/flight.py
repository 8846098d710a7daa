"""The checks of one flight (a `pipeline.flight.Flight`): what each role was resolved to (`mapping_lines`), the
geometry checks (`geometry_checks`) and those of `ridgeloc run` (`run_checks`: the one-line refusal of an
inconsistent flight, the warnings it carries into its report and exports)."""

from __future__ import annotations

import dataclasses
import datetime
import math
from dataclasses import dataclass

import numpy as np

from pipeline.answer import baseline_problem, lines_of_sight_from_rays
from pipeline.check.conventions import (
    Convention,
    Reading,
    candidates,
    current_reading,
    fix,
    fix_lines,
    mount_matrix,
    reinterpret,
)
from pipeline.check.geometry import Cluster, _fmt_m, cluster, meet_undetermined_warning, range_bias_problem
from pipeline.errors import RidgelocError
from pipeline.flight import Flight
from pipeline.flight_config import CLOCK_SOURCES
from pipeline.targets import flight_targets, in_image

# ---- the resolved mapping ---------------------------------------------------------------------------------------


def _span(t_ns) -> tuple[int, int] | None:
    t = np.asarray(t_ns, dtype=np.int64)
    return (int(t[0]), int(t[-1])) if t.size else None


def _utc(t_ns: int) -> str:
    dt = datetime.datetime.fromtimestamp(t_ns / 1e9, tz=datetime.timezone.utc)
    return dt.isoformat(timespec="milliseconds").replace("+00:00", "Z")


def _when(t_ns: int) -> str:
    return _utc(t_ns) if t_ns > 10**17 else f"{t_ns / 1e9:.3f} s"  # UNIX times as UTC, others as seconds


def _rate(t_ns) -> str:
    t = np.asarray(t_ns, dtype=np.int64)
    return f"{(t.size - 1) / ((t[-1] - t[0]) / 1e9):.1f} Hz" if t.size > 1 and t[-1] > t[0] else "-"


def mapping_lines(r: Flight) -> list[str]:
    """What each role comes from, in which frame, units and time base, with spans, rates and overlaps."""
    c, log, now = r.config.clock, r.log, current_reading(r.config, r.log)
    lines = [f"flight {r.config.name} ({r.config.path or 'built in code'})"]
    yaw = {None: "per the log's flags", True: "relative to the vehicle heading", False: "earth-referenced"}
    describe = {
        "position": lambda s: f"WGS84 deg, altitude {s.alt_datum}",
        "attitude": lambda s: "quaternion body FRD -> local NED (as read)",
        "gimbal": lambda s: (f"quaternion read as {now.frame} (order {now.quat_order}), yaw "
                             f"{yaw[now.yaw_in_vehicle_frame]}; mapping format {now.fmt}"),
        "range": lambda s: f"metres, {int(np.asarray(s.valid).sum())} of {s.t_ns.size} valid",
    }
    for role in ("position", "attitude", "gimbal", "range"):
        s = getattr(log, role)
        if s is None:
            lines.append(f"  {role:<10} none")
            continue
        off = c.offset_ns(role)
        a, b = _span(s.t_ns)
        lines.append(f"  {role:<10} {s.source}: {s.t_ns.size} samples, {_rate(s.t_ns)}, {s.clock} clock"
                     + (f" + {off / 1e9:+.3f} s" if off else "") + f"; {describe[role](s)}")
        lines.append(f"  {'':<10} span {_when(a + off)} .. {_when(b + off)} ({(b - a) / 1e9:.1f} s)")
    f = r.frames
    off = c.offset_ns("video")
    first_ns = int(f.t_ns[0]) + off if f.t_ns.size else None  # the first frame on the telemetry clock
    lines.append(f"  {'frames':<10} {f.source}: {f.t_ns.size} frames, {_rate(f.t_ns)}, {f.clock} clock + "
                 f"{off / 1e9:.3f} s"
                 + (f" (first frame at {_utc(first_ns)})" if first_ns is not None and first_ns > 10**17 else "")
                 + (" (video_start " + str(c.video_start) + ")" if c.video_start is not None else ""))
    if f.t_ns.size:
        lines.append(f"  {'':<10} span {_when(int(f.t_ns[0]) + off)} .. {_when(int(f.t_ns[-1]) + off)}")
    cam = r.camera
    lines.append(f"  {'intrinsics':<10} {cam.width_px}x{cam.height_px} px, fx {cam.fx_px:.1f} fy {cam.fy_px:.1f}, "
                 f"principal point ({cam.cx_px:.1f}, {cam.cy_px:.1f}), dist {list(cam.dist)} from {r.camera_source}")
    mount = now.mount if now.mount != "frd" else "body FRD: camera.fixed_to_body" if cam.fixed_to_body else \
        "gimbal FRD"
    lines.append(f"  {'mount':<10} R_optical_from_gimbal {[list(row) for row in cam.R_optical_from_gimbal]} "
                 f"({mount})")
    arms = r.config.lever_arms_m
    lines.append(f"  {'levers':<10} camera {list(arms.camera)} m, rangefinder {list(arms.rangefinder)} m (body FRD)")
    offsets = ", ".join(f"{s} {c.offset_ns(s) / 1e9:+.3f} s" for s in CLOCK_SOURCES if s != "video" and
                        c.offset_ns(s))
    lines.append(f"  {'clock':<10} video {off / 1e9:+.6f} s" + (f", {offsets}" if offsets else "")
                 + (f"; estimate within +-{c.search_s:g} s" if c.estimate else ""))
    tel = r.telemetry_span_ns()
    if tel is None:
        lines.append("  overlap    position, attitude and gimbal do not overlap in time")
    elif f.t_ns.size:
        va, vb = int(f.t_ns[0]) + off, int(f.t_ns[-1]) + off
        ov = max(0, min(vb, tel[1]) - max(va, tel[0]))
        lines.append(f"  overlap    telemetry {(tel[1] - tel[0]) / 1e9:.1f} s, video {(vb - va) / 1e9:.1f} s, both "
                     f"{ov / 1e9:.1f} s")
    if r.plan is not None:
        n_r = int(np.isfinite(r.plan.range_m).sum())
        where = ", at key frames" if r.plan.at_key_frames else ""
        lines.append(f"  observations {r.plan.n} ({r.config.observations.mode}{where}), {n_r} with a laser range")
    else:
        lines.append(f"  observations none: {r.plan_error}")
    if r.origin is not None:
        lines.append(f"  origin     {r.origin[0]:.6f}, {r.origin[1]:.6f}, {r.origin[2]:.1f} m (ellipsoid)")
    return lines


# ---- geometry ---------------------------------------------------------------------------------------------------


def outside_telemetry(r: Flight) -> str:
    """The one-line problem when no observation time falls inside the telemetry."""
    tel = r.telemetry_span_ns()
    if tel is not None and tel[0] == tel[1]:  # e.g. a video cut short after its first metadata packet
        return (f"the telemetry covers a single instant ({_when(tel[0])}): position, attitude and gimbal together "
                "have one sample, no span to interpolate a pose at any frame in; is the file cut short?")
    span = "" if tel is None else f" ({_when(tel[0])} .. {_when(tel[1])})"
    return (f"no observation time falls inside the telemetry{span}: the video clock is off; set clock.video_start "
            "(the first frame's UNIX time or ISO 8601) or clock.video_offset_s")


def rays(r: Flight, t_ns: np.ndarray, pixel_px: np.ndarray | None = None, conv: Convention | None = None,
         now: Reading | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """`Flight.rays` under the convention `conv` (None: as configured) instead of the one the flight was read
    with (`now`, default the configured reading)."""
    if conv is None:
        return r.rays(t_ns, pixel_px)
    now = now or current_reading(r.config, r.log)
    log = dataclasses.replace(r.log, gimbal=reinterpret(r.log.gimbal, conv, now))
    return r.rays(t_ns, pixel_px, log=log, R_optical_from_gimbal=mount_matrix(conv, now))


@dataclass(frozen=True)
class Alternative:
    convention: Convention
    cluster: Cluster
    lines: list[str]
    notes: list[str]
    n_changes: int


@dataclass
class GeometryResult:
    """The cluster as configured, the better alternatives (best first; empty when the configured one is
    consistent), problems and warnings (one line each)."""

    cluster: Cluster | None
    alternatives: list[Alternative]
    problems: list[str]
    warnings: list[str]
    what: str  # which rays: "optical axes" or "tracked target"


def try_alternatives(r: Flight, now: Reading, t_ns, pixel_px, ranges_m, configured: Cluster | None,
                     limit: int = 4) -> list[Alternative]:
    """The alternative conventions whose lines of sight cluster (consistent), best first, one per distinct
    cluster size (equivalent fixes: the one with fewest changes)."""
    found: list[Alternative] = []
    for conv in candidates(now)[1:]:
        try:
            o, d, _ = rays(r, t_ns, pixel_px, conv, now)
        except RidgelocError:
            continue
        c = cluster(o, d, ranges_m)
        if c is None or not c.consistent or c.no_baseline:  # lines of sight meeting by noise fix nothing
            continue
        if configured is not None and configured.ahead and c.spread_m >= 0.5 * configured.spread_m:
            continue
        changes, notes = fix(conv, now)
        found.append(Alternative(conv, c, fix_lines(changes), notes, conv.changes(now)))
    if not found:
        return []
    # Alternatives within 2x (or 0.3 deg) of the tightest fit the data equally well (a camera rolled 180 deg about
    # its axis fits as well as the right one while the target stays near the image centre): among those, the
    # fewest changes, then the commonest convention. The rest follow by cluster size, one per distinct fix.
    tight = min(a.cluster.spread_m for a in found)
    tie = max(2 * tight, tight + 0.005 * min(a.cluster.distance_m for a in found))
    found.sort(key=lambda a: (a.cluster.spread_m > tie, a.n_changes, _rarity(a.convention), a.cluster.spread_m))
    out: list[Alternative] = []
    for a in found:
        if len(out) < limit and all(a.lines != b.lines or a.notes != b.notes for b in out):
            out.append(a)
    return out


_COMMON_FRAMES = ("flu_enu", "frd_ned", "optical_enu", "optical_ned", "frd_enu", "flu_ned")
_COMMON_MOUNTS = ("frd", "custom", "optical", "flu")


def _rarity(conv: Convention) -> tuple[int, int]:
    return _COMMON_MOUNTS.index(conv.mount), _COMMON_FRAMES.index(conv.frame)


def mark_checks(r: Flight, centre_m: np.ndarray | None, conv: Convention | None = None,
                now: Reading | None = None) -> tuple[list[str], list[str]]:
    """Every pixel mark of every target against the image bounds and the video's frames; the first target's
    first mark (the one the clock estimate tracks, where the gimbal and the laser point) also against the
    principal point and, with the cluster's centre, whether its line of sight passes near the cluster.
    Returns (problems, warnings)."""
    problems, warnings = [], []
    cam = r.camera
    w, h = cam.width_px, cam.height_px
    frame_numbers = {int(k): i for i, k in enumerate(np.asarray(r.frames.index))} if r.frames is not None else None

    def inside(a, b):  # OpenCV convention: integer coordinates at pixel centres, the image spans -0.5 .. size-0.5
        return in_image(a, b, w, h)

    first = True
    for target in flight_targets(r.config):
        for m in target.marks:
            primary, first = first, False
            if m.pixel is None:
                continue
            what = "target.pixel" if target.name is None else f"target '{target.name}' ({m.source}): pixel"
            u, v = m.pixel
            if not inside(u, v):
                hint = (f" it looks like [row, column]: give {'target.pixel' if target.name is None else 'the pixel'}"
                        " as [x (column), y (row)]" if inside(v, u) else "")
                problems.append(f"{what} [{u:g}, {v:g}] is outside the {w}x{h} image (x in -0.5..{w - 0.5:g}, y "
                                f"in -0.5..{h - 0.5:g}; OpenCV pixel centres at integers);{hint}".rstrip(";"))
                continue
            if frame_numbers is not None and m.frame_index is not None and m.frame_index not in frame_numbers:
                key = "target.frame_index" if target.name is None else f"target '{target.name}' ({m.source}): frame"
                problems.append(f"{key} {m.frame_index} is not a frame of the video")
                continue
            if primary:
                warnings += _primary_mark_checks(r, m, centre_m, conv, now, frame_numbers, problems,
                                                 "target.pixel" if target.name is None else what)
    return problems, warnings


def _primary_mark_checks(r: Flight, m, centre_m, conv, now, frame_numbers, problems: list[str],
                         what: str = "target.pixel") -> list[str]:
    """The first mark against the principal point (a warning, returned) and the cluster of the lines of sight
    (a problem, appended); `what` names the mark as the config or marks file gives it."""
    cam = r.camera
    u, v = m.pixel
    warnings = []
    off = math.hypot(u - cam.cx_px, v - cam.cy_px)
    if off > 0.25 * min(cam.width_px, cam.height_px):
        warnings.append(f"{what} [{u:g}, {v:g}] is {off:.0f} px from the principal point "
                        f"({cam.cx_px:.1f}, {cam.cy_px:.1f}): the laser may not be on the target")
    if centre_m is None or r.plan is None or m.frame_index is None or frame_numbers is None:
        return warnings
    t_mark = np.array([int(r.frames.t_ns[frame_numbers[m.frame_index]]) + r.config.clock.offset_ns("video")])
    cands = {"as given": (u, v)}
    if -0.5 <= v <= cam.width_px - 0.5 and -0.5 <= u <= cam.height_px - 0.5:
        cands["swapped (row, column)"] = (v, u)
    miss = {}
    for name, px in cands.items():
        o, d, k = rays(r, t_mark, np.array([px]), conv, now)
        if k[0]:
            miss[name] = float(np.linalg.norm(np.cross(centre_m - o[0], d[0])))
    if "as given" in miss:
        dist = float(np.linalg.norm(centre_m - o[0]))
        if miss["as given"] > 0.05 * dist:
            better = {k: mm for k, mm in miss.items() if k != "as given" and mm < 0.3 * miss["as given"]}
            hint = f"; swapped to [{v:g}, {u:g}] it misses by {_fmt_m(min(better.values()))}" if better else ""
            problems.append(f"the line of sight through {what} [{u:g}, {v:g}] in frame {m.frame_index} "
                            f"misses where the lines of sight meet by {_fmt_m(miss['as given'])}{hint}")
    return warnings


def geometry_checks(r: Flight, pixel_px: np.ndarray | None = None, t_ns: np.ndarray | None = None,
                    ranges_m: np.ndarray | None = None) -> GeometryResult:
    """The geometry checks at the planned observations (or at t_ns with pixel_px / ranges_m, as `run` has them)."""
    if t_ns is None:
        if r.plan is None:
            return GeometryResult(None, [], [f"no observations to check: {r.plan_error}"], [], "none")
        t_ns, ranges_m = r.plan.t_ns, r.plan.range_m
    now = current_reading(r.config, r.log)
    what = "optical axes" if pixel_px is None else "lines of sight through the tracked target"
    o, d, inside = rays(r, t_ns, pixel_px)
    problems, warnings = mark_checks(r, None)  # every mark against the image and the frames
    marks_ok = not problems
    if not inside.any():
        problems.append(outside_telemetry(r))
        return GeometryResult(None, [], problems, warnings, what)
    if not inside.all():
        warnings.append(f"{int((~inside).sum())} of {len(inside)} observation(s) fall outside the telemetry")
    c = cluster(o, d, ranges_m)
    if c is None:
        warnings.append("fewer than 3 observations with a line of sight: the geometry cannot be checked")
        return GeometryResult(None, [], problems, warnings, what)
    alts: list[Alternative] = []
    if c.no_baseline and not r.config.terrain:
        problems.append(_no_baseline(o, d))  # not a convention: nothing fixes where these lines of sight meet
    elif not c.consistent:
        alts = try_alternatives(r, now, t_ns, pixel_px, ranges_m, c)
        where = c.describe()
        if alts:
            best = alts[0]
            problems.append(f"the {what} do not converge ({where}); with " + "; ".join(best.lines or best.notes)
                            + f" they do ({best.cluster.describe()})")
        elif c.inconsistent:
            problems.append(f"the {what} do not converge ({where}) and no common alternative convention makes "
                            "them converge: check the gimbal's frame and mount"
                            + (", or the gimbal does not track the target (check with the tracked target: "
                               "`ridgeloc run`)" if pixel_px is None else ""))
        else:
            warnings.append(f"the {what} converge loosely ({where}): more than the attitude errors explain")
    rb = range_bias_problem(c)
    if rb and not alts and not c.no_baseline:
        problems.append(rb)
    warnings += cluster_warnings(c)
    level = ranges_end_at_sea_level(r, *(rays(r, t_ns)[:2] if pixel_px is not None else (o, d)), ranges_m)
    if level:
        warnings.append(level)
    if marks_ok and (c.consistent or alts):  # the first mark's line of sight against where the others meet
        problems += mark_checks(r, c.centre_m if c.consistent else (alts[0].cluster.centre_m if alts else None),
                                alts[0].convention if alts and not c.consistent else None, now)[0]
    return GeometryResult(c, alts, problems, warnings, what)


#: ranges whose end points all lie within this of sea level (m) look computed against it, not measured
SEA_LEVEL_BAND_M = 2.0


def ranges_end_at_sea_level(r: Flight, o: np.ndarray, d: np.ndarray, ranges_m) -> str | None:
    """A warning when every range (at least 3), laid along its line of sight o + d range (ENU m, (n, 3)), ends within
    SEA_LEVEL_BAND_M of mean sea level (EGM2008) although the platform's height changes: a slant range the payload
    computed against sea level (full-motion video without a laser) puts the answer at sea level, not on the
    ground; else None. (A laser on a target at sea level would show the same: the warning says what it means.)"""
    if ranges_m is None or r.origin is None:
        return None
    rng = np.asarray(ranges_m, dtype=np.float64)
    ok = np.isfinite(rng) & np.isfinite(o).all(axis=1) & np.isfinite(d).all(axis=1)
    if ok.sum() < 3:
        return None
    from pipeline.geometry.frames import lla_from_enu
    from pipeline.geometry.geoid import geoid_undulation_m

    end = o[ok] + d[ok] * rng[ok, None]
    lla = lla_from_enu(end, r.origin)
    lat, lon, h = lla[:, 0], lla[:, 1], lla[:, 2]
    msl = h - np.asarray(geoid_undulation_m(lat, lon), dtype=np.float64)
    if np.abs(msl).max() > SEA_LEVEL_BAND_M:
        return None
    return (f"the laser ranges all end at sea level ({float(np.median(msl)):+.1f} m, EGM2008, over {int(ok.sum())} "
            f"ranges from {float(rng[ok].min()):.0f} to {float(rng[ok].max()):.0f} m): they look computed by the "
            "payload against sea level, not measured, and then every answer that uses them lies at sea level, not "
            "on the ground; give a terrain model (terrain: dem) for the ground's height, or trust them only if the "
            "target really is at sea level")


def cluster_warnings(c: Cluster) -> list[str]:
    """The warnings of a consistent cluster, one line each (`check` and `run` alike): lines of sight so nearly
    parallel that where they meet is undetermined along them and the ranges cannot be checked against it."""
    undetermined = meet_undetermined_warning(c)
    return [undetermined] if undetermined and c.consistent else []


def run_checks(r: Flight, t_ns, pixel_px, ranges_m) -> tuple[str | None, list[str]]:
    """The geometry checks of `ridgeloc run` at its observations (lines of sight through the tracked target):
    (one line when the geometry is inconsistent beyond doubt (run refuses the flight), else None; the warnings
    `check` gives the same cluster (`cluster_warnings`))."""
    o, d, _ = rays(r, t_ns, pixel_px)
    c = cluster(o, d, ranges_m)
    warnings = [] if c is None else cluster_warnings(c)
    oa, da, _ = rays(r, t_ns)  # the ranges lie along the optical axis, where the laser points
    level = ranges_end_at_sea_level(r, oa, da, ranges_m)
    return _refusal(r, t_ns, pixel_px, ranges_m, c), warnings + ([level] if level else [])


def _no_baseline(o: np.ndarray, d: np.ndarray) -> str:
    """The one line naming a missing baseline (`pipeline.answer.baseline_problem`, as a target's answer says it)."""
    ok = np.isfinite(o).all(axis=1) & np.isfinite(d).all(axis=1)
    return baseline_problem(lines_of_sight_from_rays(o[ok], d[ok]), False, False)


def _refusal(r: Flight, t_ns, pixel_px, ranges_m, c: Cluster | None) -> str | None:
    """`run_checks`' refusal, from the cluster c of its lines of sight. None without a baseline: no convention
    can be judged, and the target's answer says why it has none."""
    if c is not None and c.no_baseline:
        return None
    if c is None or not c.inconsistent:
        # consistent lines of sight through a wrong mark: the gimbal (and the laser) track something else
        oa, da, _ = rays(r, t_ns)
        axes = cluster(oa, da, ranges_m)
        # only for the single `target:`: the gimbal (and the laser) track it; a named target may lie anywhere
        if axes is not None and axes.consistent and r.config.target is not None:
            swapped = [p for p in mark_checks(r, axes.centre_m)[0] if "swapped to" in p or "row, column" in p]
            if swapped:
                return f"the marked target is not what the gimbal tracks: {swapped[0]}; give target.pixel as [x, y]"
        return None
    now = current_reading(r.config, r.log)
    alts = try_alternatives(r, now, t_ns, pixel_px, ranges_m, c, limit=1)
    head = f"inconsistent geometry: the lines of sight through the tracked target do not converge ({c.describe()})"
    if alts:
        a = alts[0]
        cause = _cause(a.convention, now)
        return (f"{head}; probable cause: {cause}; fix: {'; '.join(a.lines or a.notes)} (then "
                f"{_fmt_m(a.cluster.spread_m)}); details: ridgeloc check")
    return f"{head}; no common convention fixes it: check the gimbal frame and mount with `ridgeloc check`"


def _cause(conv: Convention, now: Reading) -> str:
    causes = []
    if conv.frame != now.frame:
        causes.append(f"the gimbal orientation is in {conv.frame}, not {now.frame}")
    if conv.quat_order != now.quat_order:
        causes.append(f"the gimbal quaternion is stored {conv.quat_order}, not {now.quat_order}")
    if conv.yaw_flipped:
        causes.append("the gimbal yaw is " + ("earth-referenced, not relative to the vehicle"
                                              if now.yaw_in_vehicle_frame else "relative to the vehicle heading, not "
                                              "earth-referenced"))
    if conv.mount != now.mount:
        causes.append(f"the camera mount is {conv.mount}, not {now.mount}")
    return " and ".join(causes)
