"""Flight configuration: what an operator knows about one flight (docs/flight_config.md documents every key).

A YAML file is read into typed, frozen dataclasses. Every section rejects unknown keys (with a suggestion for a
near miss such as `fx` for `fx_px`), checks types, shapes and ranges, resolves paths relative to the config
file and names missing files. Units are in the key names (`_px`, `_m`, `_ns`, `_s`, `_deg`).

A run config (configs/sample.yaml) lists flight configs under `groups:`; `load_run_config` accepts either.
"""

from __future__ import annotations

import dataclasses
import datetime
import json
import typing
from dataclasses import dataclass, field
from os import PathLike
from pathlib import Path

import numpy as np
import yaml

from pipeline.config_schema import load_dataclass, read_yaml
from pipeline.errors import ConfigError
from pipeline.targets import TargetEntry  # issue 21: many targets per flight
from pipeline.track.sift import TrackerSettings

# ---- the flight configuration ------------------------------------------------------------------------------


@dataclass(frozen=True)
class Files:
    telemetry: tuple[str, ...]
    video: str | None = None
    frames_csv: str | None = None

    def __post_init__(self):
        if not self.telemetry:
            raise ValueError("'telemetry' must list at least one file")


@dataclass(frozen=True)
class Camera:
    """Intrinsics (OpenCV pinhole + distortion; pixel coordinates with integer values at pixel centres, (0, 0) the
    centre of the top-left pixel) and the camera's mounting in the gimbal. The intrinsics may be left out
    together (all of width_px .. cy_px, and dist): they then come from the logs (`pipeline.intrinsics`)."""

    width_px: int | None = None
    height_px: int | None = None
    fx_px: float | None = None
    fy_px: float | None = None
    cx_px: float | None = None
    cy_px: float | None = None
    dist: tuple[float, ...] | None = None
    R_optical_from_gimbal: tuple[tuple[float, float, float], tuple[float, float, float],
                                 tuple[float, float, float]] = ((0.0, 1.0, 0.0), (0.0, 0.0, 1.0), (1.0, 0.0, 0.0))

    def __post_init__(self):
        given = [k for k in INTRINSIC_KEYS if getattr(self, k) is not None]
        if given and len(given) < len(INTRINSIC_KEYS):
            missing = [k for k in INTRINSIC_KEYS if getattr(self, k) is None]
            raise ValueError(f"give all of {', '.join(INTRINSIC_KEYS)} or none (to take them from the logs' "
                             f"CameraInfo); missing: {', '.join(missing)}")
        if given and (self.width_px <= 0 or self.height_px <= 0 or self.fx_px <= 0 or self.fy_px <= 0):
            raise ValueError("image size and focal lengths must be positive")
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


CLOCK_SOURCES = ("video", "range", "position", "attitude", "gimbal")


@dataclass(frozen=True)
class Clock:
    """How each source's timestamps map onto the telemetry clock, and whether to estimate the video's offset.

    Per source (video, range, position, attitude, gimbal) the offset added to its timestamps is
        <source>_offset_s (or the integer <source>_offset_ns; the video's is video_to_telemetry_offset_ns)
        + video_start (video only: the first frame's time on the telemetry clock, UNIX seconds or ISO 8601)
        - <source>_latency_s (how long after the measurement its timestamp was taken).
    estimate: estimate the video-to-telemetry offset from the flight itself, within +-search_s of the configured
    one (`pipeline.sync.clock_estimate`)."""

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
    search_s: float = 2.0

    def __post_init__(self):
        for src in CLOCK_SOURCES:
            ns_key = "video_to_telemetry_offset_ns" if src == "video" else f"{src}_offset_ns"
            given = [k for k in (ns_key, f"{src}_offset_s") if getattr(self, k) not in (None, 0)]
            if src == "video" and self.video_start is not None:
                given.append("video_start")
            if len(given) > 1:
                raise ValueError(f"give one of {' and '.join(given)}: both set the {src} offset")
        if not 0 < self.search_s <= 600:
            raise ValueError(f"'search_s' must be in (0, 600] seconds, got {self.search_s}")
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


@dataclass(frozen=True)
class Altitude:
    """Altitude datum conversion: ellipsoid height = AMSL altitude + geoid_separation_m. `"auto"` takes it from
    the EGM2008 geoid model at the flight's first position (pipeline.geometry.geoid)."""

    geoid_separation_m: float | str | None = None

    def __post_init__(self):
        if isinstance(self.geoid_separation_m, str) and self.geoid_separation_m != "auto":
            raise ValueError("geoid_separation_m must be a number (m) or 'auto' (the EGM2008 geoid model), "
                             f"got {self.geoid_separation_m!r}")


@dataclass(frozen=True)
class Target:
    """Where the operator marked the target: a pixel in a frame, or a template image."""

    frame_index: int | None = None
    pixel: tuple[float, float] | None = None
    template: str | None = None
    template_pixel: tuple[float, float] | None = None

    def __post_init__(self):
        if self.template is None and (self.frame_index is None or self.pixel is None):
            raise ValueError("give either 'frame_index' and 'pixel', or 'template'")
        if self.template is not None and self.pixel is not None:
            raise ValueError("give either 'frame_index' and 'pixel', or 'template', not both")


@dataclass(frozen=True)
class ObservationSelection:
    mode: typing.Literal["range_times", "frames", "bursts"] = "range_times"
    frame_tolerance_s: float = 0.1
    max_range_gap_s: float = 0.1
    frame_indices: tuple[int, ...] = ()
    max_laser_offset_px: float | None = 50.0
    burst_gap_s: float = 0.5

    def __post_init__(self):
        if self.frame_tolerance_s <= 0 or self.max_range_gap_s < 0:
            raise ValueError("tolerances must be positive")
        if self.mode == "frames" and not self.frame_indices:
            raise ValueError("mode 'frames' needs 'frame_indices'")


@dataclass(frozen=True)
class Geodetic:
    lat_deg: float
    lon_deg: float
    alt_m: float

    def __post_init__(self):
        if not (-90 <= self.lat_deg <= 90 and -180 <= self.lon_deg <= 360):
            raise ValueError(f"latitude/longitude out of range: {self.lat_deg}, {self.lon_deg}")

    def as_tuple(self) -> tuple[float, float, float]:
        return (self.lat_deg, self.lon_deg, self.alt_m)


@dataclass(frozen=True)
class Solve:
    methods: tuple[str, ...] | str = "all"
    options: dict[str, typing.Any] = field(default_factory=dict)


@dataclass(frozen=True)
class SigmaPriors:
    pixel_px: float | None = None
    range_m: float | None = None
    position_m: float | None = None
    attitude_deg: float | None = None
    attitude_tau_s: float | None = None  # correlation times of the attitude and position errors (None: white)
    position_tau_s: float | None = None


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
    # issue 21: named targets (pipeline.targets); `target:` is the one-element case and excludes these two
    targets: tuple[TargetEntry, ...] = ()
    marks_file: str | None = None
    path: str | None = None

    def __post_init__(self):
        if self.target is not None and (self.targets or self.marks_file is not None):  # issue 21
            raise ValueError("give 'target' (one mark) or 'targets'/'marks_file', not both")
        if isinstance(self.origin, str) and self.origin != "auto":
            raise ValueError("'origin' must be 'auto' or {lat_deg, lon_deg, alt_m}")
        if not self.name or any(c in self.name for c in "/\\:") or self.name.startswith("."):
            raise ValueError(f"'name' must be a folder-safe name, got {self.name!r}")
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
        try:
            doc = json.loads(Path(self.truth_file).read_text())
            t = doc["target"]
            return float(t["lat_deg"]), float(t["lon_deg"]), float(t["alt_m"])
        except (OSError, ValueError, KeyError, TypeError) as exc:
            raise ConfigError(f"cannot read the target truth: {exc}", self.truth_file) from None


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
    cfg = load_dataclass(FlightConfig, doc, source=where, integral_floats=True)
    files = dataclasses.replace(
        cfg.files,
        telemetry=tuple(_resolve(base, p, f"files.telemetry[{i}]", where) for i, p in enumerate(cfg.files.telemetry)),
        video=_resolve(base, cfg.files.video, "files.video", where),
        frames_csv=_resolve(base, cfg.files.frames_csv, "files.frames_csv", where))
    target = cfg.target
    if target is not None and target.template is not None:
        target = dataclasses.replace(target, template=_resolve(base, target.template, "target.template", where))
    cfg = dataclasses.replace(cfg, files=files, target=target,
                              truth_file=_resolve(base, cfg.truth_file, "truth_file", where),
                              path=None if where is None else str(where.resolve()))
    from pipeline.targets import resolve_config_targets  # issue 21: paths resolved, marks file read and checked

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
    where the boresighted laser points, the crosshair of the first observation frame."""
    path = Path(path).resolve()
    if not path.is_file():
        raise ConfigError("no such file", path)
    name = "".join(c if c.isalnum() or c in "-_" else "_" for c in path.stem) or "flight"
    return FlightConfig(name=name.lstrip("."), files=Files(telemetry=(str(path),)), path=str(path))


@dataclass(frozen=True)
class GroupEntry:
    """One flight group of a run: its config path, or the error that stops it from loading."""

    source: str
    config: FlightConfig | None = None
    error: str | None = None


def load_run_config(path: str | PathLike) -> list[GroupEntry]:
    """The flight groups of a run config (`groups: [flight config paths]`), a manifest (a YAML list of flight config
    paths), a folder (every `flight.yaml` in it or below), a single flight config, or a full-motion video file.

    A group whose flight config does not load is returned with its error (the others still run); a run config
    that is itself malformed raises ConfigError."""
    path = Path(path)
    if path.is_dir():
        from pipeline.batch import discover_flights

        return _load_groups(discover_flights(path), path)
    if path.suffix.lower() in FMV_SUFFIXES:
        return [GroupEntry(str(path), flight_config_for_video(path))]
    try:
        doc = yaml.safe_load(path.read_text())
    except FileNotFoundError:
        raise ConfigError("config file not found", path) from None
    except (OSError, UnicodeDecodeError, yaml.YAMLError):
        doc = None  # _read_yaml below reports it
    if isinstance(doc, list):  # a manifest: a plain list of flight config paths
        groups = doc
    else:
        doc = _read_yaml(path)
        if "groups" not in doc:
            return [GroupEntry(str(path), load_flight_config(path))]
        unknown = sorted(set(doc) - {"groups", "description"})
        if unknown:
            raise ConfigError(f"{unknown[0]}: unknown key in a run config (known: groups, description)", path)
        groups = doc["groups"]
    if not isinstance(groups, list) or not groups or not all(isinstance(g, str) for g in groups):
        raise ConfigError("'groups' must be a non-empty list of flight config paths", path)
    return _load_groups([(path.resolve().parent / g).resolve() for g in groups], path)


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
