"""Flight configuration: what an operator knows about one flight (docs/flight_config.md documents every key).

A YAML file is read into typed, frozen dataclasses. Every section rejects unknown keys (with a suggestion for a
near miss such as `fx` for `fx_px`), checks types, shapes and ranges, resolves paths relative to the config
file and names missing files. Units are in the key names (`_px`, `_m`, `_ns`, `_s`, `_deg`).

A run config (configs/sample.yaml) lists flight configs under `groups:`, a manifest is a YAML list of them;
`discover_flights` is the one parser of both (and of a folder of flights), `load_run_config` loads what it lists.
Validation is declarative (pydantic, `pipeline.config_schema`): bounds are annotations on the fields, the
estimators' names and options come from the registry `pipeline.solve.options`, and a mistake is one
`ConfigError` naming the file, the dotted key and, for a near miss, "did you mean".
"""

from __future__ import annotations

import dataclasses
import datetime
import json
import typing
from dataclasses import dataclass, field
from os import PathLike
from pathlib import Path
from typing import Annotated

import numpy as np
import pydantic
from annotated_types import Ge, Gt, Le, Lt

from pipeline.config_schema import NonNegative, Positive, load_dataclass, read_yaml
from pipeline.errors import ConfigError, InputError
from pipeline.solve_options import Method, SolveOptions, given_options, not_in_config_problem
from pipeline.targets import Geodetic, TargetEntry, check_mark, read_truth_file

# ---- the flight configuration ------------------------------------------------------------------------------


#: names a flight cannot have: the run's TAK outputs beside the group folders (OUTDIR/cot/, targets.zip)
RESERVED_FLIGHT_NAMES = ("cot", "targets.zip")


@dataclass(frozen=True)
class Files:
    telemetry: tuple[str, ...] = ()
    video: str | None = None
    frames_csv: str | None = None
    # drone photos as the flight (a folder or a list of JPEGs), and their marks CSV
    # (photo,x_px,y_px; none: every image centre, where the laser points). docs/locate.md
    photos: tuple[str, ...] = ()
    marks: str | None = None

    def __post_init__(self):
        if not self.telemetry and not self.photos:
            raise ValueError("'telemetry' must list at least one file (or 'photos' the flight's photos)")


@dataclass(frozen=True)
class Camera:
    """Intrinsics (OpenCV pinhole + distortion; pixel coordinates with integer values at pixel centres, (0, 0) the
    centre of the top-left pixel) and the camera's mounting in the gimbal (or on the body: `fixed_to_body`). The
    intrinsics may be left out
    together (all of width_px .. cy_px, and dist): they then come from the logs (`pipeline.intrinsics`)."""

    width_px: Annotated[int, Gt(0)] | None = None
    height_px: Annotated[int, Gt(0)] | None = None
    fx_px: Positive | None = None
    fy_px: Positive | None = None
    cx_px: float | None = None
    cy_px: float | None = None
    dist: tuple[float, ...] | None = None
    R_optical_from_gimbal: tuple[tuple[float, float, float], tuple[float, float, float],
                                 tuple[float, float, float]] = ((0.0, 1.0, 0.0), (0.0, 0.0, 1.0), (1.0, 0.0, 0.0))
    # a camera fixed to the airframe (no gimbal): the vehicle's attitude is the camera's, R_optical_from_gimbal its
    # mounting on the body (body FRD -> optical)
    fixed_to_body: bool = False

    def __post_init__(self):
        given = [k for k in INTRINSIC_KEYS if getattr(self, k) is not None]
        if given and len(given) < len(INTRINSIC_KEYS):
            missing = [k for k in INTRINSIC_KEYS if getattr(self, k) is None]
            raise ValueError(f"give all of {', '.join(INTRINSIC_KEYS)} or none (to take them from the logs' "
                             f"CameraInfo); missing: {', '.join(missing)}")
        if self.dist is not None and len(self.dist) not in (4, 5, 8):
            raise ValueError(f"'dist' must be [k1, k2, p1, p2] or [k1, k2, p1, p2, k3] (or 8), got {len(self.dist)}")
        if self.dist is not None and not given:
            raise ValueError("'dist' needs the intrinsics it belongs to (width_px .. cy_px)")
        R = np.array(self.R_optical_from_gimbal)
        if not np.allclose(R @ R.T, np.eye(3), atol=1e-6) or np.linalg.det(R) < 0:
            raise ValueError("'R_optical_from_gimbal' must be a proper rotation matrix")
        if given and self.dist is None:
            object.__setattr__(self, "dist", (0.0, 0.0, 0.0, 0.0, 0.0))

    @property
    def has_intrinsics(self) -> bool:
        return self.fx_px is not None

    @property
    def K(self) -> np.ndarray:
        return np.array([[self.fx_px, 0.0, self.cx_px], [0.0, self.fy_px, self.cy_px], [0.0, 0.0, 1.0]])


INTRINSIC_KEYS = ("width_px", "height_px", "fx_px", "fy_px", "cx_px", "cy_px")


Vec3 = tuple[float, float, float]


@dataclass(frozen=True)
class LeverArms:
    """Offsets from the GNSS antenna, body FRD metres."""

    camera: Vec3 = (0.0, 0.0, 0.0)
    rangefinder: Vec3 = (0.0, 0.0, 0.0)


@dataclass(frozen=True)
class TrackerSettings:
    """Thresholds of the tracker (`pipeline.track.sift`; flight config `tracking:` keys of the same names)."""

    n_features: Annotated[int, Ge(50)] = 1000
    ratio: Annotated[float, Gt(0), Lt(1)] = 0.75
    ransac_reproj_px: Positive = 3.0
    min_inliers: Annotated[int, Ge(4)] = 12  # a homography needs 4 points
    min_inlier_ratio: Annotated[float, Ge(0), Le(1)] = 0.25
    min_correlation: Annotated[float, Ge(-1), Le(1)] = 0.5
    min_contrast_ratio: Annotated[float, Gt(0), Le(1)] = 0.6
    patch_half_px: Annotated[int, Ge(3)] = 15
    search_half_px: Annotated[int, Ge(1)] = 6
    keyframe_inlier_fraction: Annotated[float, Ge(0), Le(1)] = 0.5
    neighbours: Annotated[int, Ge(0)] = 2
    detect_scale: Annotated[float, Ge(0.1), Le(1)] = 0.5  # features found on the image resized by this factor
    max_detect_px: Annotated[int, Ge(160)] = 960  # ... and at most this many pixels on its long side
    # features found at full resolution in a square of this side around the target instead, where it has at most
    # half the pixels of the reduced frame (large videos); 0: never
    detect_window_px: Annotated[int, Ge(0)] = 512


CLOCK_SOURCES = ("video", "range", "position", "attitude", "gimbal")


@dataclass(frozen=True)
class Clock:
    """How each source's timestamps map onto the telemetry clock, and whether to estimate the video's offset.

    Per source (video, range, position, attitude, gimbal) the offset added to its timestamps is
        <source>_offset_s (or the integer <source>_offset_ns; the video's is video_to_telemetry_offset_ns)
        + video_start (video only: the first frame's time on the telemetry clock, UNIX seconds or ISO 8601)
        - <source>_latency_s (how long after the measurement its timestamp was taken).
    estimate: estimate the video-to-telemetry offset from the flight itself, within +-search_s of the configured
    one (`pipeline.clock_estimate`)."""

    video_to_telemetry_offset_ns: int = 0
    range_offset_ns: int = 0
    position_offset_ns: int = 0
    attitude_offset_ns: int = 0
    gimbal_offset_ns: int = 0
    video_start: float | datetime.datetime | str | None = None
    video_offset_s: float | None = None
    range_offset_s: float | None = None
    position_offset_s: float | None = None
    attitude_offset_s: float | None = None
    gimbal_offset_s: float | None = None
    video_latency_s: float = 0.0
    range_latency_s: float = 0.0
    position_latency_s: float = 0.0
    attitude_latency_s: float = 0.0
    gimbal_latency_s: float = 0.0
    estimate: bool = False
    search_s: Annotated[float, Gt(0), Le(600)] = 2.0

    def __post_init__(self):
        for src in CLOCK_SOURCES:
            ns_key = "video_to_telemetry_offset_ns" if src == "video" else f"{src}_offset_ns"
            given = [k for k in (ns_key, f"{src}_offset_s") if getattr(self, k) not in (None, 0)]
            if src == "video" and self.video_start is not None:
                given.append("video_start")
            if len(given) > 1:
                raise ValueError(f"give one of {' and '.join(given)}: both set the {src} offset")
        self.video_start_ns  # noqa: B018 (validates the time)

    @property
    def video_start_ns(self) -> int | None:
        """video_start as UNIX ns (None when not given)."""
        v = self.video_start
        if v is None:
            return None
        if isinstance(v, (int, float)):
            return round(float(v) * 1e6) * 1000
        if isinstance(v, str):
            try:
                v = datetime.datetime.fromisoformat(v.strip().replace("Z", "+00:00"))
            except ValueError:
                raise ValueError(f"'video_start' must be UNIX seconds or an ISO 8601 time, got {v!r}") from None
        if isinstance(v, datetime.date) and not isinstance(v, datetime.datetime):
            raise ValueError("'video_start' needs a time of day, not only a date")
        if v.tzinfo is None:
            v = v.replace(tzinfo=datetime.timezone.utc)  # ISO 8601 without a zone: UTC, as logs keep time
        whole = v.replace(microsecond=0)
        return round(whole.timestamp()) * 1_000_000_000 + v.microsecond * 1000

    def offset_ns(self, source: str) -> int:
        """The offset (ns) added to `source`'s timestamps (one of CLOCK_SOURCES), every key above combined."""
        ns_key = "video_to_telemetry_offset_ns" if source == "video" else f"{source}_offset_ns"
        seconds = getattr(self, f"{source}_offset_s")
        total = int(getattr(self, ns_key)) + (0 if seconds is None else round(seconds * 1e9))
        if source == "video" and self.video_start is not None:
            total += self.video_start_ns
        return total - round(getattr(self, f"{source}_latency_s") * 1e9)


#: the largest geoid separation a config may state (m): EGM2008's undulation spans -107..+86 m
MAX_GEOID_SEPARATION_M = 150.0


@dataclass(frozen=True)
class Altitude:
    """Altitude datum conversion: ellipsoid height = AMSL altitude + geoid_separation_m. `"auto"` takes it from
    the EGM2008 geoid model at the flight's first position (pipeline.geometry.geoid)."""

    geoid_separation_m: float | str | None = None

    def __post_init__(self):
        if isinstance(self.geoid_separation_m, str) and self.geoid_separation_m != "auto":
            raise ValueError("geoid_separation_m must be a number (m) or 'auto' (the EGM2008 geoid model), "
                             f"got {self.geoid_separation_m!r}")
        if isinstance(self.geoid_separation_m, (int, float)) and abs(self.geoid_separation_m) > MAX_GEOID_SEPARATION_M:
            raise ValueError(f"geoid_separation_m must be within +-{MAX_GEOID_SEPARATION_M:.0f} m (the geoid lies "
                             "-107..+86 m from the WGS84 ellipsoid, EGM2008), or 'auto', "
                             f"got {self.geoid_separation_m!r}")


@dataclass(frozen=True)
class Target:
    """Where the operator marked the target: a pixel in a frame, or a template image."""

    frame_index: Annotated[int, Ge(0)] | None = None
    pixel: tuple[float, float] | None = None
    template: str | None = None
    template_pixel: tuple[float, float] | None = None

    def __post_init__(self):
        check_mark(self)


@dataclass(frozen=True)
class ObservationSelection:
    mode: typing.Literal["range_times", "frames", "bursts"] = "range_times"
    frame_tolerance_s: Positive = 0.1
    max_range_gap_s: NonNegative = 0.1
    frame_indices: tuple[Annotated[int, Ge(0)], ...] = ()
    max_laser_offset_px: Positive | None = 50.0
    burst_gap_s: Positive = 0.5
    # mode range_times: each shot's observation at the nearest key frame, its range interpolated there
    # (pipeline/sync/key_frames.py): true, false, or auto (where it pays: pipeline/sync/select.py)
    at_key_frames: bool | typing.Literal["auto"] = "auto"
    key_frame_tolerance_s: Positive = 0.5
    range_interpolation_gap_s: Positive = 1.5  # the two shots a range is interpolated between, at most this apart

    def __post_init__(self):
        if self.mode == "frames" and not self.frame_indices:
            raise ValueError("mode 'frames' needs 'frame_indices'")


@dataclass(frozen=True)
class Solve:
    """methods: "all", one name or a list of names of `pipeline.solve.options.METHODS`. options: per method, the
    options of `pipeline.solve.options.OPTIONS` (validated against that table at load; read as a plain
    `{method: {option: value}}` dict of the options given)."""

    methods: tuple[Method, ...] | Method | typing.Literal["all"] = "all"
    options: Annotated[SolveOptions, pydantic.AfterValidator(given_options)] = field(default_factory=dict)


@dataclass(frozen=True)
class SigmaPriors:
    """The sensors' standard deviations (>= 0; None: unknown, the mle estimates them)."""

    pixel_px: NonNegative | None = None
    range_m: NonNegative | None = None
    position_m: NonNegative | None = None
    attitude_deg: NonNegative | None = None
    attitude_tau_s: NonNegative | None = None  # correlation times of the attitude and position errors (None: white)
    position_tau_s: NonNegative | None = None


@dataclass(frozen=True)
class Terrain:
    """A GeoTIFF DEM of the target's area (docs/terrain.md). `vertical_datum` overrides what the file says
    (orthometric: EGM96/EGM2008 heights; ellipsoidal: WGS84); `vertical_sigma_m` is the DEM's vertical error
    (1 sigma, m) at the target, for the MLE's terrain prior (None: no prior, `dem` only)."""

    dem: str
    vertical_sigma_m: float | None = None
    vertical_datum: typing.Literal["orthometric", "ellipsoidal"] | None = None

    def __post_init__(self):
        if self.vertical_sigma_m is not None and not (np.isfinite(self.vertical_sigma_m) and self.vertical_sigma_m > 0):
            raise ValueError(f"'vertical_sigma_m' must be a positive number of metres, got {self.vertical_sigma_m}")


@dataclass(frozen=True)
class FlightConfig:
    """One flight, resolved: every file path is absolute. `path` is the config file (None if built in code)."""

    name: str
    files: Files
    target: Target | None = None  # None: the crosshair (principal point) of the first observation frame
    camera: Camera = field(default_factory=Camera)
    mapping: dict[str, typing.Any] | None = None
    lever_arms_m: LeverArms = field(default_factory=LeverArms)
    clock: Clock = field(default_factory=Clock)
    altitude: Altitude = field(default_factory=Altitude)
    observations: ObservationSelection = field(default_factory=ObservationSelection)
    tracking: TrackerSettings = field(default_factory=TrackerSettings)
    origin: Geodetic | str = "auto"
    truth: Geodetic | None = None
    truth_file: str | None = None
    solve: Solve = field(default_factory=Solve)
    sigma: SigmaPriors = field(default_factory=SigmaPriors)
    terrain: Terrain | None = None
    # named targets (pipeline.targets); `target:` is the one-element case and excludes these two
    targets: tuple[TargetEntry, ...] = ()
    marks_file: str | None = None
    path: str | None = None

    def __post_init__(self):
        if self.target is not None and (self.targets or self.marks_file is not None):
            raise ValueError("give 'target' (one mark) or 'targets'/'marks_file', not both")
        if isinstance(self.origin, str) and self.origin != "auto":
            raise ValueError("'origin' must be 'auto' or {lat_deg, lon_deg, alt_m}")
        if not self.name or any(c in self.name for c in "/\\:") or self.name.startswith("."):
            raise ValueError(f"'name' must be a folder-safe name, got {self.name!r}")
        if self.name.lower() in RESERVED_FLIGHT_NAMES:
            raise ValueError(f"'name' {self.name!r} is taken by the run's TAK events (OUTDIR/cot/, targets.zip): "
                             "name the flight otherwise")
        if self.truth is not None and self.truth_file is not None:
            raise ValueError("give 'truth' or 'truth_file', not both")

    def to_dict(self) -> dict:
        """JSON-serialisable form (for reports and GroupResult.settings; `clock.video_start` as given)."""
        return json.loads(json.dumps(dataclasses.asdict(self), default=str))

    def truth_lla(self) -> tuple[float, float, float] | None:
        """The target's true WGS84 position (ellipsoid height), from `truth` or `truth_file`, else None."""
        if self.truth is not None:
            return self.truth.as_tuple()
        if self.truth_file is None:
            return None
        target = read_truth_file(self.truth_file).target
        if target is None:
            raise ConfigError("cannot read the target truth: no 'target' in it", self.truth_file)
        return target.as_tuple()


def _resolve(base: Path, p: str | None, what: str, where: Path) -> str | None:
    if p is None:
        return None
    path = (base / p).resolve() if not Path(p).is_absolute() else Path(p)
    if not path.exists():
        raise ConfigError(f"{what}: file not found: {path}", where)
    return str(path)


def flight_config_from_dict(doc: dict, path: str | PathLike | None = None) -> FlightConfig:
    """Validate a parsed flight config; relative paths are resolved against the config file's folder."""
    where = Path(path) if path is not None else None
    base = where.resolve().parent if where is not None else Path.cwd()
    if isinstance(doc, dict) and "path" in doc:
        raise ConfigError("path: unknown key", where)
    if isinstance(doc, dict) and isinstance(doc.get("files"), dict) and isinstance(doc["files"].get("photos"), str):
        doc = {**doc, "files": {**doc["files"], "photos": [doc["files"]["photos"]]}}  # a folder
    if (problem := not_in_config_problem(doc)) is not None:
        raise ConfigError(problem, where)
    cfg = load_dataclass(FlightConfig, doc, source=where, integral_floats=True)
    files = dataclasses.replace(
        cfg.files,
        telemetry=tuple(_resolve(base, p, f"files.telemetry[{i}]", where) for i, p in enumerate(cfg.files.telemetry)),
        video=_resolve(base, cfg.files.video, "files.video", where),
        frames_csv=_resolve(base, cfg.files.frames_csv, "files.frames_csv", where),
        photos=tuple(_resolve(base, p, f"files.photos[{i}]", where) for i, p in enumerate(cfg.files.photos)),
        marks=_resolve(base, cfg.files.marks, "files.marks", where))
    target = cfg.target
    if target is not None and target.template is not None:
        target = dataclasses.replace(target, template=_resolve(base, target.template, "target.template", where))
    if cfg.terrain is not None:
        cfg = dataclasses.replace(cfg, terrain=dataclasses.replace(
            cfg.terrain, dem=_resolve(base, cfg.terrain.dem, "terrain.dem", where)))
    cfg = dataclasses.replace(cfg, files=files, target=target,
                              truth_file=_resolve(base, cfg.truth_file, "truth_file", where),
                              path=None if where is None else str(where.resolve()))
    if cfg.truth_file is not None:  # a broken truth file is refused at load, not after tracking
        if read_truth_file(cfg.truth_file).target is None and not (cfg.targets or cfg.marks_file):
            raise ConfigError(f"truth_file: no 'target' in {cfg.truth_file} (the truth of the flight's one target)",
                              where)
    from pipeline.targets import resolve_config_targets  # paths resolved, marks file read and checked

    return resolve_config_targets(cfg, base, where, _resolve)


def _read_yaml(path: Path) -> dict:
    doc = read_yaml(path)
    if not isinstance(doc, dict):
        raise ConfigError("the top level must be a mapping of keys", path)
    return doc


def load_flight_config(path: str | PathLike) -> FlightConfig:
    path = Path(path)
    return flight_config_from_dict(_read_yaml(path), path)


FMV_SUFFIXES = (".ts", ".m2ts", ".mts", ".mpg", ".mpeg", ".mp4", ".mkv", ".mov")


def flight_config_for_video(path: str | PathLike) -> FlightConfig:
    """The flight config of a full-motion video (MISB ST 0601 KLV beside the video) given alone on the command
    line: the file is the telemetry and the video, the intrinsics come from its field of view and the target is
    where the boresighted laser points, the crosshair of the first observation frame; its azimuths are read from
    true or UTM grid north as its frame centres say (`mapping: {klv: {azimuth_north: auto}}`)."""
    path = Path(path).resolve()
    if not path.is_file():
        raise ConfigError("no such file", path)
    name = "".join(c if c.isalnum() or c in "-_" else "_" for c in path.stem) or "flight"
    # MSL altitudes (EG 0104, ST 0601 tag 15 alone) converted with the EGM2008 geoid; unused for ellipsoid heights
    return FlightConfig(name=name.lstrip("."), files=Files(telemetry=(str(path),)), path=str(path),
                        altitude=Altitude(geoid_separation_m="auto"), mapping={"klv": {"azimuth_north": "auto"}})


@dataclass(frozen=True)
class GroupEntry:
    """One flight group of a run: its config path, or the error that stops it from loading."""

    source: str
    config: FlightConfig | None = None
    error: str | None = None


@dataclass(frozen=True)
class RunConfig:
    """A run config: the flight configs of a run (paths relative to the run config's folder)."""

    groups: Annotated[tuple[Annotated[str, pydantic.StringConstraints(min_length=1)], ...],
                      pydantic.Field(min_length=1)]
    description: str = ""


def discover_flights(path: str | PathLike, config_name: str = "flight.yaml") -> list[Path]:
    """The flight config files a run processes (absolute paths), from:

    - a folder: every `config_name` file in it or below (hidden folders skipped), sorted by path;
    - a manifest: a YAML list of flight config paths;
    - a run config: a mapping with such a list under `groups` (RunConfig);
    - any other YAML file: that one flight config.
    Listed paths are relative to the listing file's folder; the listed files are not opened here."""
    path = Path(path)
    if path.is_dir():
        found = sorted(p for p in path.rglob(config_name)
                       if p.is_file() and not any(part.startswith(".") for part in p.relative_to(path).parts[:-1]))
        if not found:
            raise InputError(f"no flight configs named {config_name} in this folder or below", path)
        return [p.resolve() for p in found]
    if not path.is_file():
        raise InputError("no such file or folder", path)
    doc = read_yaml(path)
    if isinstance(doc, list):
        doc = {"groups": doc}
    elif not isinstance(doc, dict) or "groups" not in doc:
        return [path.resolve()]
    run = load_dataclass(RunConfig, doc, source=path)
    return [(path.resolve().parent / g).resolve() for g in run.groups]


def load_run_config(path: str | PathLike) -> list[GroupEntry]:
    """The flight groups of a run config, a manifest, a folder (see `discover_flights`), a single flight config,
    or a full-motion video file.

    A listed group whose flight config does not load is returned with its error (the others still run); a run
    config that is itself malformed, or a single flight config that does not load, raises ConfigError."""
    path = Path(path)
    if path.suffix.lower() in FMV_SUFFIXES and not path.is_dir():
        return [GroupEntry(str(path), flight_config_for_video(path))]
    if not path.exists():
        raise ConfigError("config file not found", path)
    listed = discover_flights(path)
    if not path.is_dir() and listed == [path.resolve()]:
        return [GroupEntry(str(path), load_flight_config(path))]
    return _load_groups(listed, path)


def _load_groups(paths: list[Path], source: Path) -> list[GroupEntry]:
    entries = []
    names: set[str] = set()
    for gpath in paths:
        try:
            cfg = load_flight_config(gpath)
        except ConfigError as exc:
            entries.append(GroupEntry(str(gpath), error=str(exc)))
            continue
        if cfg.name in names:
            raise ConfigError(f"two groups are named {cfg.name!r}", source)
        names.add(cfg.name)
        entries.append(GroupEntry(str(gpath), cfg))
    return entries
