"""A synthetic flight's configuration: typed defaults, loaded from YAML, unknown keys rejected.

Every number the generator uses is a key here (docs/synth.md explains each default). Defaults describe the
paper's flight experiments (section 3.2): 600x400 px camera at 25 Hz, about 2 km above and 5 km from the
target (observation angle 66.42 deg), laser noise ~5 m, position noise ~2 m, attitude noise ~0.2 deg.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from datetime import datetime, timezone
from os import PathLike
from pathlib import Path
from typing import Annotated, Literal

from annotated_types import Ge, Gt, Le, Lt, MinLen

from pipeline.config_schema import NonNegative, Positive, load_dataclass, read_yaml, to_plain
from pipeline.errors import ConfigError

FORMATS = ("tlog", "ros1", "ros2-sqlite3", "ros2-mcap", "mcap", "klv")

Index = Annotated[int, Ge(0)]
Vec3 = tuple[float, float, float]
Rate = Annotated[float, Gt(0), Le(200)]


@dataclass(frozen=True)
class ExtraTargetConfig:
    """Another target of the flight: a panel like the main one, east_m/north_m metres from it on the
    ground, size_m across, contrast 0..1 of its pattern (1: the main panel's white and black; less: greyer),
    hidden by a cloud around the listed observations. The laser aims at the main target only."""

    name: Annotated[str, MinLen(1)]
    east_m: float
    north_m: float
    size_m: Positive = 36.0
    contrast: Annotated[float, Gt(0), Le(1)] = 1.0
    occluded_observations: tuple[Index, ...] = ()


@dataclass(frozen=True)
class SiteConfig:
    """Where the target stands. lat/lon WGS84 degrees, alt_m above the WGS84 ellipsoid (the ground there).

    geoid_separation_m: N = ellipsoid height - AMSL height, held constant over the flight (used to write AMSL
        altitudes in MAVLink; ~ -28 m on the Guanzhong plain near Xi'an, the default site).
    """

    lat_deg: float = 34.36
    lon_deg: float = 108.76
    alt_m: float = 372.0
    geoid_separation_m: float = -28.0
    target_size_m: float = 36.0
    target_name: str = "target"  # named only in flights with extra_targets
    extra_targets: tuple[ExtraTargetConfig, ...] = ()


@dataclass(frozen=True)
class PathConfig:
    """The camera's path in the target's local ENU frame.

    kind: "arc" = a circle around the target at height_m above it and slant_distance_m from it; "straight" =
        a level line perpendicular to the horizontal line of sight at its midpoint (slant_distance_m there);
        "waypoints" = a smooth curve through waypoints_enu_m (E, N, Up metres from the target) at speed_mps;
        "hover" = a multirotor holding still at height_m above the target, slant_distance_m from it, at
        start_azimuth_deg, heading towards it (no baseline: its lines of sight do not meet).
    intersection_angle_deg: arc / straight: the angle between the first and last lines of sight (exact).
    start_azimuth_deg: arc / straight: azimuth (from north, clockwise) of the platform seen from the target at
        the first observation (straight: at the line's midpoint).
    direction: "cw" or "ccw" seen from above (arc); straight: which way along the line.
    speed_mps: nominal ground speed; the observation spacing is a whole number of seconds near it, so the
        actual speed is adjusted slightly (truth.json records it).
    """

    kind: Literal["arc", "straight", "waypoints", "hover"] = "arc"
    height_m: Positive = 2000.0
    slant_distance_m: float = 5000.0
    intersection_angle_deg: float = 40.0
    start_azimuth_deg: float = 200.0
    direction: Literal["cw", "ccw"] = "ccw"
    speed_mps: Annotated[float, Ge(5), Le(120)] = 35.0
    waypoints_enu_m: tuple[Vec3, ...] = ()
    pitch_deg: float = 2.0


@dataclass(frozen=True)
class ObservationConfig:
    """count: observation epochs (laser shot + video frame). spacing_s: seconds between them (0 = derived from
    the path length and speed; waypoints need it). lead_in_s / lead_out_s: flight time before the first and
    after the last observation."""

    count: Annotated[int, Ge(2)] = 10
    spacing_s: Annotated[int, Ge(0)] = 0
    lead_in_s: Annotated[float, Ge(1)] = 8.0
    lead_out_s: Annotated[float, Ge(1)] = 4.0


@dataclass(frozen=True)
class CameraConfig:
    """OpenCV pinhole + distortion (k1, k2, p1, p2, k3), 25 Hz video. zoom: [[seconds after the video start,
    factor], ...], a zoom lens stepping to `factor` times the focal lengths at that time (needs dist all 0)."""

    width_px: Annotated[int, Ge(16)] = 600
    height_px: Annotated[int, Ge(16)] = 400
    fx_px: Positive = 1800.0
    fy_px: Positive = 1800.0
    cx_px: float = 301.7
    cy_px: float = 198.4
    dist: tuple[float, float, float, float, float] = (-0.12, 0.08, 0.0006, -0.0004, 0.0)
    fps: Annotated[int, Ge(1)] = 25
    zoom: tuple[tuple[float, Positive], ...] = ()


@dataclass(frozen=True)
class GimbalConfig:
    """jitter_px: std of the tracker's pointing error (Ornstein-Uhlenbeck, per image axis, in pixels at the
    principal point) so the target is near but not at the centre; jitter_tau_s its correlation time.
    yaw_in_vehicle_frame: log the gimbal quaternion with yaw relative to the vehicle heading (MAVLink flag 32).
    ros_frame: bags only: the frame the gimbal topic's orientation is written in (<body>_<world>, body frd, flu or
        optical, world ned or enu; REP-103 flu_enu by default), to test other vehicles' conventions.
    quat_order: plain MCAP only: the order of the gimbal's `q_wxyz` array (xyzw writes it scalar last)."""

    jitter_px: float = 2.0
    jitter_tau_s: float = 2.0
    yaw_in_vehicle_frame: bool = False
    ros_frame: Literal["flu_enu", "frd_ned", "optical_enu", "optical_ned", "flu_ned", "frd_enu"] = "flu_enu"
    quat_order: Literal["wxyz", "xyzw"] = "wxyz"


@dataclass(frozen=True)
class LeverArmConfig:
    """Camera and rangefinder origins relative to the GNSS antenna, body FRD metres."""

    camera: Vec3 = (0.35, 0.0, 0.42)
    rangefinder: Vec3 = (0.35, 0.06, 0.42)


@dataclass(frozen=True)
class RatesConfig:
    """Logging rates, Hz. The laser fires on video frames (a multiple of the frame period)."""

    gps_hz: Rate = 5.0
    attitude_hz: Rate = 25.0
    gimbal_hz: Rate = 25.0
    laser_hz: Rate = 1.0
    system_time_hz: Rate = 1.0


@dataclass(frozen=True)
class NoiseConfig:
    """Telemetry errors (standard deviations).

    gnss_drift_m / gnss_white_m: per axis (E, N, U), a first-order Gauss-Markov drift with time constant
        gnss_tau_s plus white noise (default total ~2 m per axis).
    attitude_deg / gimbal_deg: per axis, a slowly varying error (Gauss-Markov, attitude_tau_s) of the vehicle's
        and the gimbal's logged attitude (0.2 deg as the paper's flights).
    laser_m: range noise; laser_dropout: probability that a shot is missing (never at observation epochs unless
        laser_dropout_at_observations).
    vehicle_wobble_deg / vehicle_wobble_tau_s: true turbulence on the vehicle's roll, pitch, yaw (not noise).
    pixel_noise_dn: sensor noise on rendered frames (8-bit digital numbers).
    """

    gnss_drift_m: NonNegative = 1.7
    gnss_white_m: NonNegative = 1.0
    gnss_tau_s: float = 60.0
    attitude_deg: NonNegative = 0.2
    gimbal_deg: NonNegative = 0.2
    attitude_tau_s: float = 20.0
    laser_m: NonNegative = 5.0
    laser_dropout: Annotated[float, Ge(0), Lt(1)] = 0.05
    laser_dropout_at_observations: bool = False
    vehicle_wobble_deg: NonNegative = 0.6
    vehicle_wobble_tau_s: float = 1.5
    pixel_noise_dn: NonNegative = 1.5


@dataclass(frozen=True)
class LaserConfig:
    """min_range_m / max_range_m: the rangefinder's limits (outside => logged invalid).
    aim: "target" = a shot measures the distance to the target (the tracker holds the laser spot on it, as the
        paper's model assumes); "beam" = to where the optical axis meets the ground plane.
    outlier_observations: observation indices whose shot is an outlier (valid flag set, range off by
        outlier_offset_m, signs alternating), e.g. the beam catching a nearer obstacle.
    dropped_observations: observation indices whose shot is missing from the log (no return)."""

    min_range_m: float = 50.0
    max_range_m: float = 12000.0
    aim: Literal["target", "beam"] = "target"
    outlier_observations: tuple[Index, ...] = ()
    outlier_offset_m: tuple[float, ...] = (-420.0, 310.0, -650.0)
    dropped_observations: tuple[Index, ...] = ()


@dataclass(frozen=True)
class LostTargetConfig:
    """Observations whose frames do not show the target: occluded (a cloud drifts over it) or slipped (the
    gimbal loses lock and points slip_px to the side: the target leaves the image, the laser hits ground)."""

    occluded_observations: tuple[Index, ...] = ()
    slipped_observations: tuple[Index, ...] = ()
    slip_px: float = 420.0


@dataclass(frozen=True)
class VideoConfig:
    """mode: "bursts" = a triggered camera records burst_frames frames centred on each observation;
    "continuous" = every frame at fps from video start to the end.
    start_delay_s: video clock zero relative to the telemetry start (defines the clock offset).
    images_in_bag: bags only: frames as sensor_msgs/CompressedImage in the bag instead of video.mp4.
    jpeg_quality: for CompressedImage frames."""

    mode: Literal["bursts", "continuous"] = "bursts"
    burst_frames: Annotated[int, Ge(1)] = 9
    start_delay_s: float = 2.316
    images_in_bag: bool = False
    jpeg_quality: Annotated[int, Ge(1), Le(100)] = 85


@dataclass(frozen=True)
class SceneConfig:
    """The procedural ground texture: texture_px square pixels of texture_res_m metres, centred on the target;
    supersample: rendering factor before the anti-aliasing downsample; haze_km: visibility scale."""

    seed: int = 7
    texture_px: Annotated[int, Ge(256)] = 4096
    texture_res_m: Positive = 1.5
    supersample: Annotated[int, Ge(1)] = 2
    haze_km: float = 16.0


@dataclass(frozen=True)
class SynthConfig:
    """One synthetic flight; `group` names the output (defaults to the config file's stem)."""

    group: str = "example"
    description: str = ""
    seed: int = 1
    format: Literal["tlog", "ros1", "ros2-sqlite3", "ros2-mcap", "mcap", "klv"] = "tlog"
    start_time_utc: str = "2024-05-14T02:30:00Z"
    site: SiteConfig = field(default_factory=SiteConfig)
    path: PathConfig = field(default_factory=PathConfig)
    observations: ObservationConfig = field(default_factory=ObservationConfig)
    camera: CameraConfig = field(default_factory=CameraConfig)
    gimbal: GimbalConfig = field(default_factory=GimbalConfig)
    lever_arms_m: LeverArmConfig = field(default_factory=LeverArmConfig)
    rates: RatesConfig = field(default_factory=RatesConfig)
    noise: NoiseConfig = field(default_factory=NoiseConfig)
    laser: LaserConfig = field(default_factory=LaserConfig)
    lost_target: LostTargetConfig = field(default_factory=LostTargetConfig)
    video: VideoConfig = field(default_factory=VideoConfig)
    scene: SceneConfig = field(default_factory=SceneConfig)

    def __post_init__(self):
        _check(self)

    @property
    def start_time_ns(self) -> int:
        """Telemetry start, UNIX ns."""
        try:
            dt = datetime.fromisoformat(self.start_time_utc.replace("Z", "+00:00"))
        except ValueError:
            raise ConfigError(f"'start_time_utc' is not an ISO 8601 time: {self.start_time_utc!r}") from None
        if dt.tzinfo is None:
            dt = dt.replace(tzinfo=timezone.utc)
        return round(dt.timestamp()) * 1_000_000_000 + dt.microsecond * 1000

    @classmethod
    def from_dict(cls, doc: dict | None, path: str | PathLike | None = None) -> SynthConfig:
        doc = {} if doc is None else doc
        if isinstance(doc, dict) and "group" not in doc and path is not None:
            doc = {**doc, "group": Path(path).stem}
        return load_dataclass(cls, doc, source=path, style="quoted")

    @classmethod
    def load(cls, path: str | PathLike) -> SynthConfig:
        return cls.from_dict(read_yaml(path), path)

    def replace(self, **changes) -> SynthConfig:
        return dataclasses.replace(self, **changes)

    def to_dict(self) -> dict:
        d = to_plain(self)
        if not self.camera.zoom:  # a fixed lens: left out, so truth.json of flights without zoom keeps its keys
            del d["camera"]["zoom"]
        if not self.site.extra_targets:  # one target: as before many targets
            del d["site"]["extra_targets"], d["site"]["target_name"]
        return d


def _check(c: SynthConfig) -> None:
    """What the field annotations cannot say: checks across keys."""
    p, o, cam = c.path, c.observations, c.camera
    c.start_time_ns  # noqa: B018 (validates the time string)
    if not p.height_m < p.slant_distance_m:
        raise ConfigError(f"'path.height_m' ({p.height_m}) must be below 'path.slant_distance_m'")
    if p.kind == "arc":
        theta = math.asin(math.sqrt(p.slant_distance_m ** 2 - p.height_m ** 2) / p.slant_distance_m)
        max_deg = math.degrees(2 * theta)
        if not 0 < p.intersection_angle_deg < max_deg:
            raise ConfigError(f"'path.intersection_angle_deg' must be in (0, {max_deg:.1f}) for an arc at this "
                              f"height and slant distance, got {p.intersection_angle_deg}")
    elif p.kind == "straight":
        if not 0 < p.intersection_angle_deg < 170:
            raise ConfigError(f"'path.intersection_angle_deg' must be in (0, 170), got {p.intersection_angle_deg}")
    elif p.kind == "waypoints" and len(p.waypoints_enu_m) < 2:
        raise ConfigError("'path.waypoints_enu_m' must list at least two [E, N, Up] points")
    if p.kind in ("waypoints", "hover") and o.spacing_s < 1:
        raise ConfigError(f"a {p.kind} path needs 'observations.spacing_s' >= 1")
    if cam.zoom and any(cam.dist):
        raise ConfigError("'camera.zoom' needs 'camera.dist' all 0")
    if c.format == "klv" and (c.gimbal.yaw_in_vehicle_frame or any(cam.dist) or c.video.images_in_bag):
        raise ConfigError("format 'klv' (MISB ST 0601 in MPEG-TS) states the field of view only: it needs "
                          "'camera.dist' all 0, and no gimbal.yaw_in_vehicle_frame or video.images_in_bag")
    frames_per_shot = cam.fps / c.rates.laser_hz
    if abs(frames_per_shot - round(frames_per_shot)) > 1e-9:
        raise ConfigError(f"'rates.laser_hz' must divide the frame rate {cam.fps} (the laser fires on frames)")
    for name, idx in (("laser.outlier_observations", c.laser.outlier_observations),
                      ("laser.dropped_observations", c.laser.dropped_observations),
                      ("lost_target.occluded_observations", c.lost_target.occluded_observations),
                      ("lost_target.slipped_observations", c.lost_target.slipped_observations),
                      *((f"site.extra_targets.{t.name}.occluded_observations", t.occluded_observations)
                        for t in c.site.extra_targets)):
        bad = [i for i in idx if not i < o.count]
        if bad:
            raise ConfigError(f"'{name}' has indices outside 0..{o.count - 1}: {bad}")
    if c.laser.outlier_observations and not c.laser.outlier_offset_m:
        raise ConfigError("'laser.outlier_offset_m' must list at least one offset")
    if c.video.images_in_bag and c.format in ("tlog", "mcap"):
        raise ConfigError("'video.images_in_bag' needs a bag format (ros1, ros2-sqlite3, ros2-mcap)")
    names = [c.site.target_name, *[t.name for t in c.site.extra_targets]]
    if len(set(names)) != len(names):
        raise ConfigError(f"'site.extra_targets': target names must be unique, got {names}")


def with_sections(base: dict, changes: dict) -> dict:
    """A copy of the synth config dict `base` with `changes`: a dict value updates that section's keys (one level
    deep), any other value replaces the key."""
    import copy

    out = copy.deepcopy(base)
    for key, value in changes.items():
        if isinstance(value, dict):
            out.setdefault(key, {}).update(value)
        else:
            out[key] = value
    return out
