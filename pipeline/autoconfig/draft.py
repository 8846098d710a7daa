"""The flight config of a folder of flight files: what the files state and what the data show, every other fact a
marked placeholder (`draft_flight_config`).

Stated by the files: which file supplies position, attitude, gimbal, range and frames (the readers of `ridgeloc
inspect`); the intrinsics (a bag's CameraInfo, a full-motion video's or an SRT's field of view:
`pipeline.intrinsics`, read again at every run, so the config names only where they come from); the altitude
datum (AMSL: the EGM2008 geoid); the sensors' accuracies a bag's covariances state; the video clock (`timing`).
Shown by the data, with `ridgeloc check`'s own checks (`pipeline.check`): the conventions under which the optical
axes and the laser ranges meet (where no mark is given yet, the image centre is where a tracking gimbal and its
laser point), and, where the intrinsics are known, the video clock's offset estimated from the flight
(`pipeline.clock_estimate`). Not stated anywhere: a plain video's intrinsics and the target: placeholders, which
`FillIn` lists for the user.
"""

from __future__ import annotations

import copy
import dataclasses
import datetime
import os
from dataclasses import dataclass, field
from pathlib import Path

from pipeline.autoconfig.folder import Folder, flight_files, read_folder
from pipeline.autoconfig.timing import VideoClock, observation_choice, video_clock
from pipeline.check.conventions import current_reading, fix
from pipeline.check.flight import geometry_checks
from pipeline.check.report import check_flight
from pipeline.errors import ConfigError, RidgelocError
from pipeline.flight import Flight
from pipeline.flight_config import Camera, Files, FlightConfig, flight_config_from_dict
from pipeline.ingest.model import FlightLog
from pipeline.intrinsics import resolve_camera

# Without laser ranges, lines of sight closer to parallel than this do not show whether they meet.
MIN_CHECK_ANGLE_DEG = 3.0
# A provisional focal length (image widths) for checking the optical axes of a video whose intrinsics are not
# known yet: the optical axis does not depend on it.
PROVISIONAL_FX_WIDTHS = 1.0


@dataclass
class FillIn:
    """A fact no file states: the config key it goes under, YAML lines (written commented out) to put in its place,
    why, and whether the run needs it (required) or only does better with it."""

    key: str
    lines: list[str]
    why: str
    required: bool = True


@dataclass
class Draft:
    """A flight config in the making: `doc` its values (what the loader reads), `comments` paragraphs above each
    top-level key, `fill_in` the placeholders, `decisions` one line per fact found (key, how), `problems` what
    the data say is wrong and no line of the config can fix, `warnings` what `check` warns of."""

    doc: dict
    comments: dict[str, list[str]] = field(default_factory=dict)
    fill_in: list[FillIn] = field(default_factory=list)
    decisions: list[tuple[str, str]] = field(default_factory=list)
    problems: list[str] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)
    found: list[str] = field(default_factory=list)
    first_frame: int = 0  # the first observation frame, where the target is marked by default
    heights_above_takeoff: bool = False  # the take-off altitude is to be filled in (checks run with a provisional one)

    def note(self, key: str, text: str) -> None:
        self.comments.setdefault(key, []).append(text)


def draft_flight_config(root, out_path) -> Draft:
    """The flight config of the files in `root` (a folder, or one file), to be written to `out_path` (paths in it
    relative to that file's folder). InputError, one line, when the files do not make a flight."""
    root, out_path = Path(root), Path(out_path)
    folder = read_folder(root)
    if folder.photos and not folder.files:
        return _photo_draft(folder, out_path)
    ff = flight_files(folder)
    log = ff.log
    rel = _relative_to(out_path.parent)
    files: dict = {"telemetry": [rel(p) for p in ff.telemetry]}
    if ff.video is not None:
        files["video"] = rel(ff.video)
    draft = Draft({"name": _name(root), "files": files})
    draft.found = [f.describe() for f in folder.files if f.path in ff.telemetry or f.path == ff.video]
    draft.found += [f"{u} (skipped)" for u in folder.unreadable]
    draft.note("files", "Files: what each supplies, as `ridgeloc inspect` reads it: " + "; ".join(draft.found) + ".")
    _altitude(draft, log)
    _azimuth_north(draft, log)
    camera = _camera(draft, log)
    clock = _clock(draft, log, ff.video)
    choice = observation_choice(log, 0 if clock.shared else clock.start_ns)
    if choice.section is not None:
        draft.doc["observations"] = choice.section
    draft.note("observations", f"Observations: {choice.how}.")
    draft.decisions.append(("observations", choice.how))
    _sigma(draft, log)
    draft.note("lever_arms_m", "Lever arms: the camera's and the rangefinder's offsets from the GNSS antenna "
               "(body FRD, m) are in no file: zero unless you give them (lever_arms_m: {camera: [x, y, z], "
               "rangefinder: [x, y, z]}); they move the answer by about their own size.")
    if clock.known:
        _check_with_data(draft, out_path, camera, (log.frames.width_px, log.frames.height_px), clock)
    else:
        draft.decisions.append(("conventions", "not checked: the frames cannot be put on the telemetry clock yet "
                                "(`ridgeloc check` checks them once clock.video_start is given)"))
    _target_placeholder(draft, log.range is not None)
    flight_config_from_dict(draft.doc, out_path)  # what is written loads
    return draft


# ---- facts the files state ----------------------------------------------------------------------------------


def _name(root: Path) -> str:
    stem = root.name if root.is_dir() else root.stem
    name = "".join(c if c.isalnum() or c in "-_" else "_" for c in stem).lstrip("._")
    return name or "flight"


def _relative_to(base: Path):
    """path -> text: relative to `base` (the config's folder) when near it, else absolute."""
    def rel(p) -> str:
        p = Path(p).resolve()
        r = Path(os.path.relpath(p, base.resolve()))
        return r.as_posix() if r.parts[:3].count("..") < 3 else p.as_posix()
    return rel


def _altitude(draft: Draft, log: FlightLog) -> None:
    pos = log.position
    if pos.alt_datum == "amsl":
        draft.doc["altitude"] = {"geoid_separation_m": "auto"}
        draft.note("altitude", f"Altitude: {_source(pos)} gives altitudes above mean sea level: they are put on "
                   "the WGS84 ellipsoid with the EGM2008 geoid at the flight's first position (auto); give the "
                   "number your autopilot uses if it is another geoid model.")
        draft.decisions.append(("altitude", "AMSL, converted with the EGM2008 geoid (auto)"))
    elif pos.alt_datum == "relative":  # an SRT's heights above the take-off point (flight_files refuses others)
        draft.doc["altitude"] = {"geoid_separation_m": "auto"}  # used when the take-off altitude is AMSL
        draft.fill_in.append(FillIn("mapping", [
            "mapping:                # FILL IN: the SRT's heights are above the take-off point: its altitude (m), "
            "AMSL (or ellipsoid, an RTK fix's), is added to them",
            "  srt: {takeoff_altitude_m: FILL_IN, abs_datum: amsl}"],
            f"mapping: the take-off point's altitude (srt.takeoff_altitude_m: {_source(pos)} gives heights above "
            "it only)"))
        draft.heights_above_takeoff = True
        draft.decisions.append(("altitude", "heights above the take-off point; its altitude is to be filled in "
                                "(AMSL converted with the EGM2008 geoid, auto)"))
    else:
        draft.decisions.append(("altitude", "heights above the WGS84 ellipsoid"))


def _azimuth_north(draft: Draft, log: FlightLog) -> None:
    """A KLV stream whose frame centres the line of sight misses as a grid-north azimuth would (or true north,
    when read as grid) is read the way that explains them (`ridgeloc check`'s frame-centre check)."""
    from pipeline.ingest.frame_centre import GRID_NORTH, TRUE_NORTH, frame_centre_checks

    for path, c in frame_centre_checks(log):
        north = {GRID_NORTH: "grid", TRUE_NORTH: "true"}.get(c.explained_by)
        if north is None:
            continue
        _merge(draft.doc, {"mapping": {"klv": {"azimuth_north": north}}})
        name = Path(path).name
        draft.note("mapping", f"Azimuths: {name}'s frame centres lie {c.median_m:.1f} m (median) from the line of "
                   f"sight at the slant range as the standard reads the angles, "
                   f"{c.alternatives[c.explained_by]:.1f} m with {c.explained_by}: read so (klv.azimuth_north).")
        draft.decisions.append(("azimuths", f"{name}: from {'UTM grid' if north == 'grid' else 'true'} north: the "
                                f"frame centres {c.alternatives[c.explained_by]:.1f} m from the line of sight "
                                f"(median; {c.median_m:.1f} m read the other way)"))
        return


def _source(series) -> str:
    return str(series.source).split(":", 1)[0].rsplit("/", 1)[-1] or "the log"


def _camera(draft: Draft, log: FlightLog) -> Camera | None:
    """The intrinsics the logs give; None when none do (a placeholder is added)."""
    probe = FlightConfig(name="init", files=Files(telemetry=("-",)))
    try:
        camera, source = resolve_camera(probe, log)
    except ConfigError as exc:
        frames = log.frames
        w, h = frames.width_px, frames.height_px
        why = str(exc).split(": ", 1)[-1] if "CameraInfo is for" in str(exc) else "no file states this camera's " \
            "intrinsics"
        draft.fill_in.append(FillIn("camera", [
            f"camera:                 # FILL IN: {why}; from a calibration (OpenCV), or fx_px = width_px / "
            "(2 tan(horizontal field of view / 2))",
            f"  width_px: {w}", f"  height_px: {h}", "  fx_px: FILL_IN", "  fy_px: FILL_IN",
            f"  cx_px: {(w - 1) / 2:g}", f"  cy_px: {(h - 1) / 2:g}",
            "  dist: [0.0, 0.0, 0.0, 0.0, 0.0]   # OpenCV k1, k2, p1, p2, k3, if the calibration gives them"],
            f"camera: the intrinsics of the {w}x{h} video (fx_px, fy_px: {why})"))
        return None
    what = (f"{camera.width_px}x{camera.height_px} px, fx {camera.fx_px:.1f} fy {camera.fy_px:.1f}, principal "
            f"point ({camera.cx_px:.1f}, {camera.cy_px:.1f})")
    draft.note("camera", f"Intrinsics: from the {source} ({what}), read again at every run (camera: width_px .. "
               "cy_px, dist would override them).")
    draft.decisions.append(("intrinsics", f"{what} from the {source}"))
    return camera


def _clock(draft: Draft, log: FlightLog, video) -> VideoClock:
    clock = video_clock(log, video)
    if clock.shared:
        draft.note("clock", f"Clock: no offset: {clock.how}.")
        draft.decisions.append(("clock", clock.how))
    elif clock.start_ns is not None:
        _set_video_start(draft, clock.start_ns, clock.estimate_s)
        draft.note("clock", f"Clock: the video clock's zero on the telemetry clock, from {clock.how}.")
        draft.decisions.append(("clock", f"video_start {_iso(clock.start_ns)}, from {clock.how}"))
    else:
        draft.fill_in.append(FillIn("clock", [
            "clock: {video_start: FILL_IN}   # FILL IN: when the video clock's zero (its first frame, or the time "
            "a frames CSV counts from) was on the telemetry clock: ISO 8601 (UTC if no zone) or UNIX seconds; "
            "`ridgeloc check` then estimates the rest (clock: {estimate: true})"],
            f"clock.video_start: when the video started ({clock.how})"))
    return clock


def _set_video_start(draft: Draft, start_ns: int, estimate_s: float | None) -> None:
    section: dict = {"video_start": _iso(start_ns)}
    if estimate_s is not None:
        section.update(estimate=True, search_s=estimate_s)
    draft.doc["clock"] = section


def _iso(t_ns: int) -> str:
    when = datetime.datetime.fromtimestamp(t_ns // 10**9, tz=datetime.timezone.utc)
    return when.strftime("%Y-%m-%dT%H:%M:%S") + f".{(t_ns % 10**9) // 1000:06d}Z"


def _sigma(draft: Draft, log: FlightLog) -> None:
    stated, said = {}, []
    if log.position.sigma_m is not None:
        stated["position_m"] = round(log.position.sigma_m, 3)
        said.append(f"position {stated['position_m']:g} m ({_source(log.position)})")
    pointing = next((s for s in (log.gimbal, log.attitude) if s.sigma_deg is not None), None)
    if pointing is not None:
        stated["attitude_deg"] = round(pointing.sigma_deg, 4)
        said.append(f"attitude {stated['attitude_deg']:g} deg ({_source(pointing)})")
    unstated = [k for k in ("range_m", "position_m", "attitude_deg") if k not in stated]
    if unstated:
        draft.fill_in.append(FillIn("sigma", [
            "sigma:   # recommended: your sensors' specified standard deviations (none: the answer's uncertainty "
            "rests on defaults and the flight's own misfit, too small on a short or smooth flight)",
            *(f"  {k}: FILL_IN" for k in unstated)],
            "sigma: " + ", ".join(unstated) + " from your sensors' specifications (without them the CE90 rests "
            "on defaults and may be too small)", required=False))
    if stated:
        draft.doc["sigma"] = stated
        draft.note("sigma", "Accuracies: the sensors' standard deviations as the files state them (their covariances): "
                   + ", ".join(said) + ". The MLE estimates what is not given; add range_m and pixel_px from "
                   "your rangefinder's and tracker's specifications if you know them.")
        draft.decisions.append(("sigma", ", ".join(said) + " as stated"))


# ---- what the data show -------------------------------------------------------------------------------------


def _check_with_data(draft: Draft, out_path: Path, camera: Camera | None, size_px: tuple[int, int],
                     clock: VideoClock) -> None:
    """The conventions (check's alternatives, tried on the optical axes and laser ranges) and, with intrinsics,
    the video clock estimated from the flight."""
    fixed = None  # the config lines of a convention fixed
    for _ in range(2):  # a convention fixed: checked once more as written
        config = _config_for_checks(draft, out_path)
        if camera is None:  # the optical axes do not depend on the intrinsics: any will do for them
            w, h = size_px
            config = dataclasses.replace(config, camera=dataclasses.replace(
                config.camera, width_px=w, height_px=h, fx_px=PROVISIONAL_FX_WIDTHS * w,
                fy_px=PROVISIONAL_FX_WIDTHS * w, cx_px=(w - 1) / 2, cy_px=(h - 1) / 2, dist=(0.0,) * 5))
        with Flight.open(config) as r:
            if r.plan is None:
                draft.problems.append(f"no observations: {r.plan_error}")
                return
            draft.first_frame = int(r.plan.frame_index[0])
            geo = geometry_checks(r)
            c = geo.cluster
            now = current_reading(config, r.log)
        if c is None:
            draft.problems += geo.problems
            draft.decisions.append(("conventions", "not checked: " + "; ".join(geo.warnings or geo.problems)))
            return
        if c.n_ranged < 3 and c.gamma_deg < MIN_CHECK_ANGLE_DEG:
            draft.note("mapping", f"Conventions: the readers' defaults: without laser ranges, lines of sight "
                       f"{c.gamma_deg:.1f} deg apart do not show whether they meet (`ridgeloc check` after marking "
                       "the target does).")
            draft.decisions.append(("conventions", f"not checked: lines of sight {c.gamma_deg:.1f} deg apart and "
                                    "no laser ranges"))
            return
        if c.consistent:
            where = c.describe()
            if fixed is None:
                draft.note("mapping", "Conventions: the readers' defaults fit: the optical axes (the image centre, "
                           f"where a tracking gimbal's laser points) meet: {where}.")
                draft.decisions.append(("conventions", f"the readers' defaults: the optical axes meet: {where}"))
            else:
                draft.decisions.append(("conventions", f"{fixed}: the optical axes meet: {where} (with the "
                                        "readers' defaults they do not)"))
            draft.problems += [p for p in geo.problems if "do not converge" not in p]
            draft.warnings += geo.warnings
            break
        if not geo.alternatives:
            draft.problems += geo.problems
            return
        best = geo.alternatives[0]
        changes, notes = fix(best.convention, now)
        if not changes:
            draft.problems += [f"the optical axes do not converge ({c.describe()}); {n}" for n in notes]
            return
        _merge(draft.doc, changes)
        fixed = "; ".join(best.lines)
        draft.note("mapping", f"Conventions: as the readers' defaults read the files, the optical axes (the image "
                   f"centre, where a tracking gimbal's laser points) do not meet ({c.describe()}); with {fixed} "
                   f"they do ({best.cluster.describe()}), as `ridgeloc check` finds.")
    else:
        return
    if not clock.shared and camera is not None:
        _estimate_clock(draft, out_path, clock)


def _config_for_checks(draft: Draft, out_path: Path) -> FlightConfig:
    """The drafted config, with a provisional take-off altitude (0 m, ellipsoid) where the take-off point's altitude
    is still to be filled in: whether the lines of sight meet, and when, does not depend on a height shared by every
    position."""
    doc = draft.doc
    if draft.heights_above_takeoff:
        doc = copy.deepcopy(doc)
        srt = doc.setdefault("mapping", {}).setdefault("srt", {})
        srt.setdefault("takeoff_altitude_m", 0.0)
        srt.setdefault("abs_datum", "ellipsoid")
    return flight_config_from_dict(doc, out_path)


def _merge(doc: dict, changes: dict) -> None:
    for key, value in changes.items():
        if isinstance(value, dict) and isinstance(doc.get(key), dict):
            _merge(doc[key], value)
        else:
            doc[key] = value


def _estimate_clock(draft: Draft, out_path: Path, clock: VideoClock) -> None:
    """The video offset estimated from the flight (the image centre tracked, `check`'s estimate)."""
    config = _config_for_checks(draft, out_path)
    try:
        result = check_flight(config, clock=True)
    except RidgelocError as exc:
        draft.problems.append(f"clock offset not estimated: {exc}")
        return
    v = getattr(result.clock, "video", None)
    if v is None:
        draft.decisions.append(("clock check", "too few frames tracked to estimate the offset from the flight"))
        return
    if not v.determined:
        draft.note("clock", f"The flight does not determine the offset better: {v.describe()}.")
        draft.decisions.append(("clock check", v.describe()))
        return
    if clock.estimate_s is None and v.low_s <= 0 <= v.high_s:
        draft.note("clock", f"The flight agrees (the image centre tracked against the poses): {v.describe()}.")
        draft.decisions.append(("clock check", f"the flight agrees: {v.describe()}"))
        return
    start_ns = clock.start_ns + round(v.delta_s * 1e9)
    _set_video_start(draft, start_ns, None)
    draft.note("clock", f"Estimated from the flight (the image centre tracked against the poses): {v.describe()}.")
    draft.decisions.append(("clock", f"video_start {_iso(start_ns)}, estimated from the flight"))


def _target_placeholder(draft: Draft, laser: bool) -> None:
    frame = draft.first_frame
    draft.fill_in.append(FillIn("target", [
        f"target: {{frame_index: {frame}, pixel: [FILL_IN_x, FILL_IN_y]}}   # FILL IN the target's pixel in a "
        "frame (ridgeloc mark shows the frames), or marks_file: marks.csv"],
        "target: the target's pixel (until then the image centre of the first observation"
        + (", where the laser points)" if laser else ": without a laser, whatever the camera looked at)")))


# ---- photos -------------------------------------------------------------------------------------------------


def _photo_draft(folder: Folder, out_path: Path) -> Draft:
    rel = _relative_to(out_path.parent)
    root = folder.root
    draft = Draft({"name": _name(root), "files": {"photos": [rel(root)]}})
    draft.found = [f"{len(folder.photos)} photo(s)"]
    draft.note("files", f"{len(folder.photos)} drone photos: each states its pose and camera (and its laser range, "
               "with a rangefinder) in its metadata (`ridgeloc inspect` lists them); `ridgeloc locate` and `ridgeloc "
               "run` read them.")
    draft.decisions.append(("photos", f"{len(folder.photos)} photo(s); intrinsics and poses from their metadata"))
    if len(folder.dems) == 1:
        draft.doc["terrain"] = {"dem": rel(folder.dems[0])}
        draft.note("terrain", "The GeoTIFF DEM beside the photos; add vertical_sigma_m (its vertical error, m) for "
                   "the MLE's terrain prior.")
    elif folder.dems:  # which one covers the target is not for init to guess
        names = ", ".join(rel(d) for d in folder.dems)
        draft.fill_in.append(FillIn("terrain", [
            f"terrain: {{dem: {rel(folder.dems[0])}}}   # optional: the DEM that covers the target, one of {names}"],
            f"terrain: the DEM that covers the target, one of the {len(folder.dems)} beside the photos ({names})",
            required=False))
    draft.fill_in.append(FillIn("marks_file", [
        "marks_file: marks.csv   # FILL IN: the CSV `ridgeloc mark` saves, name,frame_or_image,x_px,y_px per "
        "target and photo (none: the target at every image centre, where the laser points)"],
        "marks_file: the targets' pixels in the photos (until then the image centres, where the laser points)"))
    flight_config_from_dict(draft.doc, out_path)
    return draft


__all__ = ["Draft", "FillIn", "draft_flight_config"]
