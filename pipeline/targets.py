"""Many targets per flight: the flight config's `targets:` list and the marks files it may point at.

A target is a name and one or more marks. A mark is a pixel (x_px, y_px; image pixels, (0, 0) the centre of the
top-left pixel) in one frame of the flight's video, or a template image (a view of the target area, the target at
`template_pixel`, default its centre) searched for in the observation frames. Sources, all giving `NamedTarget`s:

- `target:` (the single mark of old configs): one target, name None; its outputs are those of ridgeloc before
  `targets:` existed (no target column).
- `targets:` in the flight config: a list of {name, frame_index + pixel | template (+ template_pixel), marks,
  truth}; `marks` lists further {frame_index, pixel} marks of the same point.
- `marks_file:` a CSV with the header `name,frame_or_image,x_px,y_px`, one row per mark (several rows per target
  allowed): `frame_or_image` is a frame number of the video, or an image file (relative to the CSV) used as a
  template with the target at (x_px, y_px) in it.
- `marks_file:` an OpenDroneMap `gcp_list.txt`: a projection line, then `geo_x geo_y geo_z im_x im_y image
  [name]` rows. The image is an image file beside the list (a template) or a frame named by its number
  (`123`, `frame_123.png`, `frame123.jpg`). The surveyed coordinates are kept only as the target's truth (the
  error columns, as `truth_file`), when the projection is geographic WGS84 (EPSG:4326, lon lat, ellipsoid
  height); other projections keep the marks and drop the truth with a note.

Errors are one line naming the file, the row and the problem (`marks_error`).
"""

from __future__ import annotations

import csv
import functools
import json
import re
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Annotated

from annotated_types import Ge, Le

from pipeline.config_schema import OTHER_KEYS_IGNORED, load_dataclass
from pipeline.errors import ConfigError
from pipeline.frames_csv import read_frames_csv

MARKS_CSV_HEADER = ("name", "frame_or_image", "x_px", "y_px")
IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".tif", ".tiff", ".bmp")


@dataclass(frozen=True)
class Mark:
    """One mark: a pixel in a frame, or a template image (absolute path once resolved) with the target's pixel in
    it. `source` names where it came from ("file, row N" or "targets[i]"), for error messages."""

    frame_index: int | None = None
    pixel: tuple[float, float] | None = None
    template: str | None = None
    template_pixel: tuple[float, float] | None = None
    source: str = ""

    def __post_init__(self):
        check_mark(self)


def check_mark(mark) -> None:
    """A mark (this module's TargetMark, or the flight config's single `target:`) is a pixel in a frame or a
    template image: ValueError otherwise."""
    if mark.template is None and (mark.frame_index is None or mark.pixel is None):
        raise ValueError("give either 'frame_index' and 'pixel', or 'template'")
    if mark.template is not None and mark.pixel is not None:
        raise ValueError("give either 'frame_index' and 'pixel', or 'template', not both")


@dataclass(frozen=True)
class NamedTarget:
    """A target of a flight: its name (None for the old single `target:`), its marks (the first is the primary one,
    the others re-acquire it), and its true position (lat_deg, lon_deg, ellipsoid alt_m) when known."""

    name: str | None
    marks: tuple[Mark, ...]
    truth_lla: tuple[float, float, float] | None = None


# ---- the `targets:` list of a flight config ----------------------------------------------------------------


FrameIndex = Annotated[int, Ge(0)]


@dataclass(frozen=True)
class FramePixel:
    frame_index: FrameIndex
    pixel: tuple[float, float]


@dataclass(frozen=True)
class Geodetic:
    """A WGS84 position: latitude, longitude (degrees), ellipsoidal height (m); the flight config's `origin:` and
    `truth:` and a named target's `truth:`."""

    lat_deg: Annotated[float, Ge(-90), Le(90)]
    lon_deg: Annotated[float, Ge(-180), Le(360)]
    alt_m: float

    def as_tuple(self) -> tuple[float, float, float]:
        return (self.lat_deg, self.lon_deg, self.alt_m)


@dataclass(frozen=True)
class NamedTruth(Geodetic):
    """A named target's true position in a truth file's `targets` list (other keys there are the generator's)."""

    __pydantic_config__ = OTHER_KEYS_IGNORED
    name: str


@dataclass(frozen=True)
class TruthFile:
    """What ridgeloc reads of a `truth_file` (the synth's truth.json: docs/synth.md): the target's true WGS84
    position (`target`) and the named targets' (`targets`); its other keys describe the generated flight and are
    not read. Latitude and longitude in range, heights finite: `read_truth_file` refuses anything else."""

    __pydantic_config__ = OTHER_KEYS_IGNORED
    target: Geodetic | None = None
    targets: tuple[NamedTruth, ...] | None = None

    def __post_init__(self):
        names = [t.name for t in self.targets or ()]
        if len(set(names)) < len(names):
            raise ValueError(f"targets: duplicate name {next(n for n in names if names.count(n) > 1)!r}")

    def named(self) -> dict[str, tuple[float, float, float]]:
        """{name: (lat_deg, lon_deg, alt_m)} of the named targets."""
        return {t.name: t.as_tuple() for t in self.targets or ()}


def read_truth_file(path) -> TruthFile:
    """The truth file at `path`, or one ConfigError naming it and the problem (unreadable, not JSON, a key out of
    range or of the wrong type, e.g. `targets[1].lat_deg: must be <= 90, got 400`, a name given twice). Parsed
    once per version of the file (a flight reads it at load and per target)."""
    path = Path(path)
    try:
        st = path.stat()
    except OSError as exc:
        raise ConfigError(f"cannot read the target truth: {exc.strerror or exc}", path) from None
    return _read_truth_file(str(path), st.st_mtime_ns, st.st_size)


@functools.lru_cache(maxsize=8)
def _read_truth_file(path: str, mtime_ns: int, size: int) -> TruthFile:
    try:
        doc = json.loads(Path(path).read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, ValueError, RecursionError) as exc:
        raise ConfigError(f"cannot read the target truth: {exc}", path) from None
    return load_dataclass(TruthFile, doc, source=path)


@dataclass(frozen=True)
class TargetEntry:
    """One entry of the flight config's `targets:` list."""

    name: str
    frame_index: FrameIndex | None = None
    pixel: tuple[float, float] | None = None
    template: str | None = None
    template_pixel: tuple[float, float] | None = None
    marks: tuple[FramePixel, ...] = field(default_factory=tuple)
    truth: Geodetic | None = None

    def __post_init__(self):
        check_name(self.name)
        if self.template is None and (self.frame_index is None or self.pixel is None) and not self.marks:
            raise ValueError("give 'frame_index' and 'pixel', 'template', or 'marks'")
        if self.template is not None and self.pixel is not None:
            raise ValueError("give either 'frame_index' and 'pixel', or 'template', not both")


def check_name(name: str) -> str:
    if not isinstance(name, str) or not name.strip() or any(c in name for c in "/\\:\n\r\t,") \
            or name.startswith("."):
        raise ValueError(f"a target name must be a non-empty folder-safe name without , / \\ :, got {name!r}")
    return name


def entries_to_targets(entries: Sequence[TargetEntry], where=None) -> list[NamedTarget]:
    out = []
    for i, t in enumerate(entries):
        src = (f"{where}: " if where else "") + f"targets[{i}] ({t.name})"
        marks = []
        if t.template is not None:
            marks.append(Mark(template=t.template, template_pixel=t.template_pixel, source=src))
        elif t.frame_index is not None:
            marks.append(Mark(frame_index=t.frame_index, pixel=t.pixel, source=src))
        marks += [Mark(frame_index=m.frame_index, pixel=m.pixel, source=f"{src}.marks[{j}]")
                  for j, m in enumerate(t.marks)]
        truth = None if t.truth is None else (t.truth.lat_deg, t.truth.lon_deg, t.truth.alt_m)
        out.append(NamedTarget(t.name, tuple(marks), truth))
    return out


def check_unique(targets: Sequence[NamedTarget], where) -> None:
    seen: set[str] = set()
    for t in targets:
        if t.name in seen:
            raise ConfigError(f"two targets are named {t.name!r}", where)
        seen.add(t.name)


# ---- marks files --------------------------------------------------------------------------------------------


def marks_error(path, row: int, problem: str) -> ConfigError:
    return ConfigError(f"row {row}: {problem}", path)


_FRAME_NAME = re.compile(r"^(?:frame[_-]?)?(\d+)(?:\.[A-Za-z]+)?$")


def _frame_or_image(value: str, base: Path, path, row: int, digits_only: bool) -> tuple[int | None, str | None]:
    """(frame index, None) or (None, absolute template path) for a marks file's image column."""
    v = value.strip()
    if re.fullmatch(r"[+-]?\d+", v):
        idx = int(v)
        if idx < 0:
            raise marks_error(path, row, f"frame index {idx} is negative")
        return idx, None
    candidate = (base / v) if not Path(v).is_absolute() else Path(v)
    if Path(v).suffix.lower() in IMAGE_SUFFIXES and candidate.is_file():
        return None, str(candidate.resolve())
    m = None if digits_only else _FRAME_NAME.match(v)
    if m is not None:
        return int(m.group(1)), None
    raise marks_error(path, row, f"unknown image {v!r}: neither a frame number nor an image file beside the "
                                 "marks file")


def _pixel(x: str, y: str, path, row: int) -> tuple[float, float]:
    try:
        px = (float(x), float(y))
    except ValueError:
        raise marks_error(path, row, f"pixel ({x!r}, {y!r}) is not two numbers") from None
    if not all(abs(v) < float("inf") for v in px):
        raise marks_error(path, row, f"pixel {px} is not finite")
    if not in_image(px[0], px[1]):
        raise marks_error(path, row, f"pixel ({px[0]:g}, {px[1]:g}) is outside the image (left of or above it)")
    return px


def in_image(u_px: float, v_px: float, width_px: int | None = None, height_px: int | None = None) -> bool:
    """Whether pixel (u, v) (scalars or arrays) lies on an image of width_px x height_px (either None: of any
    size). The one rule of marks, photo marks, `ridgeloc check` and the marking page: pixel centres at integers
    (OpenCV's convention), so the image covers -0.5 .. width_px - 0.5 and -0.5 .. height_px - 0.5."""
    u_max = width_px - 0.5 if width_px is not None else float("inf")
    v_max = height_px - 0.5 if height_px is not None else float("inf")
    return (-0.5 <= u_px) & (u_px <= u_max) & (-0.5 <= v_px) & (v_px <= v_max)  # numpy arrays too


def _file_mark(frame: int | None, image: str | None, pixel_px: tuple[float, float], source: str) -> Mark:
    """A marks-file row's mark: a pixel in a video frame, or in an image (a template)."""
    if image is None:
        return Mark(frame_index=frame, pixel=pixel_px, source=source)
    return Mark(template=image, template_pixel=pixel_px, source=source)


def _group(rows: list[tuple[str, Mark]], truths: dict[str, tuple | None]) -> list[NamedTarget]:
    order: dict[str, list[Mark]] = {}
    for name, mark in rows:
        order.setdefault(name, []).append(mark)
    return [NamedTarget(n, tuple(ms), truths.get(n)) for n, ms in order.items()]


def unreadable_marks(exc: BaseException) -> str:
    """Why a marks file cannot be read, without the path again (ConfigError puts it first)."""
    if isinstance(exc, IsADirectoryError):
        return "a folder, not a marks file: give the marks CSV in it (`ridgeloc mark` saves marks.csv)"
    if isinstance(exc, UnicodeDecodeError):
        return "cannot read the marks file: not UTF-8 text (a CSV is expected)"
    return f"cannot read the marks file: {getattr(exc, 'strerror', None) or exc}"


def read_marks_csv(path: str | Path) -> list[NamedTarget]:
    """Targets of a marks CSV (`name,frame_or_image,x_px,y_px`); ConfigError naming file, row and problem.
    Row numbers count the header as row 1. A name may repeat (several marks of one target) but not with the
    same frame twice (a duplicate)."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8-sig")
    except (OSError, UnicodeDecodeError) as exc:
        raise ConfigError(unreadable_marks(exc), path) from None
    reader = csv.reader(text.splitlines())
    header = next(reader, None)
    if header is None or tuple(h.strip() for h in header) != MARKS_CSV_HEADER:
        raise marks_error(path, 1, f"the header must be {','.join(MARKS_CSV_HEADER)}, got {','.join(header or [])!r}")
    rows: list[tuple[str, Mark]] = []
    seen: dict[tuple[str, object], int] = {}
    for row_no, cells in enumerate(reader, start=2):
        if not cells or all(not c.strip() for c in cells):
            continue
        if len(cells) != 4:
            raise marks_error(path, row_no, f"expected 4 columns ({','.join(MARKS_CSV_HEADER)}), got {len(cells)}")
        name, where, x, y = (c.strip() for c in cells)
        try:
            check_name(name)
        except ValueError as exc:
            raise marks_error(path, row_no, str(exc)) from None
        frame, image = _frame_or_image(where, path.parent, path, row_no, digits_only=True)
        px = _pixel(x, y, path, row_no)
        key = (name, frame if image is None else image)
        if key in seen:
            raise marks_error(path, row_no, f"duplicate name {name!r} (already marked in row {seen[key]} on the "
                                            "same frame or image)")
        seen[key] = row_no
        rows.append((name, _file_mark(frame, image, px, f"{path}: row {row_no}")))
    if not rows:
        raise ConfigError("the marks file lists no mark", path)
    return _group(rows, {})


_GEOGRAPHIC = ("EPSG:4326", "WGS84", "+PROJ=LONGLAT", "+PROJ=LATLONG")


def read_gcp_list(path: str | Path) -> tuple[list[NamedTarget], list[str]]:
    """Targets of an OpenDroneMap gcp_list.txt (see the module docstring) and notes. A row without a name gets
    `gcp<row>`; rows with the same name are marks of one point (their coordinates must agree)."""
    path = Path(path)
    try:
        lines = path.read_text(encoding="utf-8-sig").splitlines()
    except (OSError, UnicodeDecodeError) as exc:
        raise ConfigError(f"cannot read the GCP list: {exc}", path) from None
    if not lines or not lines[0].strip():
        raise marks_error(path, 1, "the first line must name the projection (e.g. EPSG:4326)")
    projection = lines[0].strip()
    geographic = projection.upper().replace(" ", "").startswith(tuple(p.replace(" ", "") for p in _GEOGRAPHIC))
    notes = [] if geographic else [f"{path.name}: projection {projection!r} is not geographic WGS84 (EPSG:4326): "
                                   "its surveyed coordinates are not used as truth"]
    rows: list[tuple[str, Mark]] = []
    truths: dict[str, tuple | None] = {}
    seen: dict[tuple[str, object], int] = {}
    for row_no, line in enumerate(lines[1:], start=2):
        cells = line.split()
        if not cells or line.lstrip().startswith("#"):
            continue
        if len(cells) < 6:
            raise marks_error(path, row_no, "expected geo_x geo_y geo_z im_x im_y image [name]")
        try:
            geo = tuple(float(c) for c in cells[:3])
        except ValueError:
            raise marks_error(path, row_no, f"surveyed coordinates {cells[:3]} are not numbers") from None
        px = _pixel(cells[3], cells[4], path, row_no)
        frame, image = _frame_or_image(cells[5], path.parent, path, row_no, digits_only=False)
        name = cells[6] if len(cells) > 6 else f"gcp{row_no}"
        try:
            check_name(name)
        except ValueError as exc:
            raise marks_error(path, row_no, str(exc)) from None
        key = (name, frame if image is None else image)
        if key in seen:
            raise marks_error(path, row_no, f"duplicate name {name!r} (already marked in row {seen[key]} on the "
                                            "same image)")
        seen[key] = row_no
        truth = (geo[1], geo[0], geo[2]) if geographic else None
        if geographic and not (-90 <= truth[0] <= 90 and -180 <= truth[1] <= 360):
            raise marks_error(path, row_no, f"latitude/longitude out of range: {truth[0]}, {truth[1]}")
        if name in truths and truths[name] != truth:
            raise marks_error(path, row_no, f"{name!r} has other surveyed coordinates in an earlier row")
        truths[name] = truth
        rows.append((name, _file_mark(frame, image, px, f"{path}: row {row_no}")))
    if not rows:
        raise ConfigError("the GCP list holds no point", path)
    return _group(rows, truths), notes


def read_marks_file(path: str | Path) -> tuple[list[NamedTarget], list[str]]:
    """A marks CSV or an OpenDroneMap gcp_list.txt (told apart by the CSV header): (targets, notes)."""
    path = Path(path)
    try:
        first = path.read_text(encoding="utf-8-sig").split("\n", 1)[0]
    except (OSError, UnicodeDecodeError) as exc:
        raise ConfigError(unreadable_marks(exc), path) from None
    if first.strip().startswith("name,") or path.suffix.lower() == ".csv":
        return read_marks_csv(path), []
    return read_gcp_list(path)


def check_marks_in_video(targets: Sequence[NamedTarget], frame_indices, width_px: int | None,
                         height_px: int | None, where=None) -> None:
    """ConfigError (naming the mark's file and row) for a mark on a frame the video does not have or a pixel
    outside the image (`width_px` x `height_px`, when known)."""
    frames = set(int(i) for i in frame_indices) if frame_indices is not None else None
    for t in targets:
        for m in t.marks:
            if m.template is not None:
                continue
            src = m.source or str(where or "")
            if frames is not None and m.frame_index not in frames:
                lo, hi = (min(frames), max(frames)) if frames else (None, None)
                raise ConfigError(f"{src}: frame index {m.frame_index} out of range (the video has frames "
                                  f"{lo}..{hi})")
            u, v = m.pixel
            if width_px is not None and not in_image(u, v, width_px, height_px):
                swapped = "; it looks like [row, column]: give [x (column), y (row)]" \
                    if in_image(v, u, width_px, height_px) else ""
                raise ConfigError(f"{src}: pixel ({u:g}, {v:g}) is outside the image ({width_px}x{height_px} px)"
                                  f"{swapped}")


def flight_targets(config) -> list[NamedTarget]:
    """Every target of a flight config: `targets:` entries, then the marks file's, or the single `target:`
    (name None), or [] when no mark is given (the crosshair of the first observation)."""
    if config.targets or config.marks_file:
        out = entries_to_targets(config.targets, config.path)
        if config.marks_file:
            out += read_marks_file(config.marks_file)[0]
        check_unique(out, config.path)
        return out
    if config.target is None:
        return []
    t, src = config.target, (f"{config.path}: " if config.path else "") + "target"
    mark = (Mark(template=t.template, template_pixel=t.template_pixel, source=src) if t.template is not None
            else Mark(frame_index=t.frame_index, pixel=t.pixel, source=src))
    return [NamedTarget(None, (mark,), None)]


def first_mark(config) -> Mark | None:
    """The first target's first mark (None: the crosshair): the one the clock estimate tracks."""
    targets = flight_targets(config)
    return targets[0].marks[0] if targets else None


def resolve_config_targets(cfg, base: Path, where, resolve):
    """The flight config with its targets' template paths and marks file made absolute (`resolve(base, p, what,
    where)`), the marks file read (its errors raised now, before anything runs) and, when the config gives the
    image size and a frames CSV, every mark (the single `target:`'s too) checked against them."""
    import dataclasses

    if cfg.targets or cfg.marks_file is not None:
        entries = tuple(t if t.template is None else
                        dataclasses.replace(t, template=resolve(base, t.template, f"targets[{i}].template", where))
                        for i, t in enumerate(cfg.targets))
        cfg = dataclasses.replace(cfg, targets=entries, marks_file=resolve(base, cfg.marks_file, "marks_file", where))
    elif cfg.target is None or cfg.target.pixel is None:
        return cfg
    frames = None
    if cfg.files.frames_csv is not None:  # the frame numbers too (else once `run` reads the video's index)
        frames = read_frames_csv(Path(cfg.files.frames_csv))[0]
    check_marks_in_video(flight_targets(cfg), frames, cfg.camera.width_px, cfg.camera.height_px, where)
    return cfg
