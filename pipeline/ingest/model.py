"""The one time-series model every reader produces.

Columnar numpy arrays, int64 nanosecond timestamps (`t_ns`, sorted ascending, on the time base named by
`clock`), SI units, frames in the names:
- positions are WGS84 latitude/longitude in degrees with the altitude datum stated (`alt_datum`);
- vehicle attitude is a unit quaternion (w, x, y, z) rotating body FRD vectors into the LOCAL LEVEL NED frame
  at the vehicle's own position (what autopilots log; see FIELD_NOTES.md);
- gimbal attitude is a unit quaternion (w, x, y, z) rotating the gimbal (camera-mount) FRD frame into local
  NED, where roll and pitch are earth-referenced and yaw is earth-referenced or relative to the vehicle's
  heading as `yaw_in_vehicle_frame` says, per sample;
- ranges are metres with a `valid` flag (out-of-range and invalid samples are kept but flagged, never used).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from pipeline.errors import InputError

ALT_DATUMS = ("amsl", "ellipsoid", "relative", "missing")  # "missing": a horizontal track, altitudes NaN
CLOCKS = ("unix", "boot", "video", "unknown")


def _check_series(name: str, t_ns: np.ndarray, **columns: np.ndarray) -> None:
    if t_ns.dtype != np.int64 or t_ns.ndim != 1:
        raise InputError(f"{name}: t_ns must be a 1-D int64 array")
    for col, arr in columns.items():
        if arr.shape[0] != t_ns.shape[0]:
            raise InputError(f"{name}: column '{col}' has {arr.shape[0]} rows, t_ns has {t_ns.shape[0]}")
    if t_ns.size > 1 and (np.diff(t_ns) < 0).any():
        raise InputError(f"{name}: t_ns is not sorted")


@dataclass(frozen=True)
class PositionSeries:
    """Platform position: t_ns (n,), lat_deg (n,), lon_deg (n,), alt_m (n,) on `alt_datum`. sigma_m: the standard
    deviation per axis the source states for its fixes (ROS NavSatFix covariance), None where it states none."""

    t_ns: np.ndarray
    lat_deg: np.ndarray
    lon_deg: np.ndarray
    alt_m: np.ndarray
    alt_datum: str
    source: str = ""
    clock: str = "unknown"
    sigma_m: float | None = None

    def __post_init__(self):
        if self.alt_datum not in ALT_DATUMS:
            raise InputError(f"position series {self.source!r}: unknown altitude datum {self.alt_datum!r}")
        _check_series(f"position series {self.source!r}", self.t_ns, lat=self.lat_deg, lon=self.lon_deg,
                      alt=self.alt_m)


@dataclass(frozen=True)
class AttitudeSeries:
    """Vehicle attitude: t_ns (n,), quat_wxyz (n, 4) rotating body FRD -> local level NED. sigma_deg: the
    standard deviation per axis the source states (ROS Imu orientation covariance), None where it states none."""

    t_ns: np.ndarray
    quat_wxyz: np.ndarray
    source: str = ""
    clock: str = "unknown"
    sigma_deg: float | None = None

    def __post_init__(self):
        _check_series(f"attitude series {self.source!r}", self.t_ns, quat=self.quat_wxyz)


@dataclass(frozen=True)
class GimbalSeries:
    """Gimbal attitude: t_ns (n,), quat_wxyz (n, 4) rotating gimbal FRD -> local level NED (yaw possibly
    relative to the vehicle heading: yaw_in_vehicle_frame (n,) bool). sigma_deg as AttitudeSeries'."""

    t_ns: np.ndarray
    quat_wxyz: np.ndarray
    yaw_in_vehicle_frame: np.ndarray
    source: str = ""
    clock: str = "unknown"
    sigma_deg: float | None = None

    def __post_init__(self):
        _check_series(f"gimbal series {self.source!r}", self.t_ns, quat=self.quat_wxyz,
                      yaw_flag=self.yaw_in_vehicle_frame)


@dataclass(frozen=True)
class RangeSeries:
    """Laser range: t_ns (n,), range_m (n,), valid (n,) bool (False: out of range / invalid, do not use)."""

    t_ns: np.ndarray
    range_m: np.ndarray
    valid: np.ndarray
    source: str = ""
    clock: str = "unknown"

    def __post_init__(self):
        _check_series(f"range series {self.source!r}", self.t_ns, range=self.range_m, valid=self.valid)


@dataclass(frozen=True)
class FrameSeries:
    """Video frames available for decoding: t_ns (n,) presentation times, index (n,) frame number within
    `source` (a video path, or a bag topic). Pixels are decoded on demand by the reader that made it."""

    t_ns: np.ndarray
    index: np.ndarray
    source: str = ""
    clock: str = "video"
    width_px: int = 0
    height_px: int = 0

    def __post_init__(self):
        _check_series(f"frame series {self.source!r}", self.t_ns, index=self.index)


@dataclass(frozen=True)
class FieldOfViewSeries:
    """Camera field of view as the payload reports it (zoom lenses, MISB KLV tags 16/17, DJI SRT focal length):
    t_ns (n,), hfov_deg (n,) across the image width, vfov_deg (n,) across the height (NaN where the source does
    not state it). Where a flight config gives no calibration, these give the intrinsics of each frame."""

    t_ns: np.ndarray
    hfov_deg: np.ndarray
    vfov_deg: np.ndarray
    source: str = ""
    clock: str = "unknown"

    def __post_init__(self):
        _check_series(f"field-of-view series {self.source!r}", self.t_ns, hfov=self.hfov_deg, vfov=self.vfov_deg)


@dataclass(frozen=True)
class ClockLink:
    """Pairs of simultaneous readings of two clocks (e.g. SYSTEM_TIME: boot ms and UNIX us), to map one
    time base onto the other: a_ns (n,) on clock `a`, b_ns (n,) on clock `b`."""

    a: str
    b: str
    a_ns: np.ndarray
    b_ns: np.ndarray


@dataclass(frozen=True)
class CameraEventSeries:
    """Camera trigger / capture feedback: t_ns (n,) capture times, index (n,) image number from the log (-1 if
    the message carries none)."""

    t_ns: np.ndarray
    index: np.ndarray
    source: str = ""
    clock: str = "unknown"

    def __post_init__(self):
        _check_series(f"camera event series {self.source!r}", self.t_ns, index=self.index)


@dataclass(frozen=True)
class CameraInfo:
    """Intrinsics as a log states them (ROS CameraInfo): K (3, 3) px, D distortion coefficients in the order of
    `distortion_model` (OpenCV k1, k2, p1, p2, k3 for plumb_bob), P (3, 4) px, image size in px."""

    width_px: int
    height_px: int
    K: np.ndarray
    D: np.ndarray
    P: np.ndarray
    distortion_model: str = ""
    source: str = ""


@dataclass(frozen=True)
class StreamInfo:
    """One stream of a log as `ridgeloc inspect` shows it."""

    name: str  # topic or message type
    msg_type: str
    count: int
    t_first_ns: int | None
    t_last_ns: int | None
    supplies: tuple[str, ...] = ()  # model quantities it can supply: position, attitude, gimbal, range, frames


@dataclass
class FlightLog:
    """Everything read from one or more files of a flight. Missing quantities are None."""

    path: str
    position: PositionSeries | None = None
    attitude: AttitudeSeries | None = None
    gimbal: GimbalSeries | None = None
    range: RangeSeries | None = None
    frames: FrameSeries | None = None
    clock_links: list[ClockLink] = field(default_factory=list)
    streams: list[StreamInfo] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)
    camera_events: CameraEventSeries | None = None
    camera_info: CameraInfo | None = None
    field_of_view: FieldOfViewSeries | None = None
    formats: list[str] = field(default_factory=list)  # reader format of each file read ("tlog", "ros1", ...)
    frame_centre: PositionSeries | None = None  # where the payload says its optical axis meets the ground (KLV)
    payload_target: PositionSeries | None = None  # the payload's own target location (KLV tags 40-42)
    klv_tables: dict = field(default_factory=dict)  # file -> its decoded KLV packets (klv.KlvTable), kept for checks
    # full-motion video file -> its demux index (video.DemuxIndex without the data packets): the frame reader's,
    # so the file is demuxed once
    video_indexes: dict = field(default_factory=dict)

    def missing_for_localization(self) -> list[str]:
        """Quantities localization needs that this log does not supply."""
        needed = {"position": self.position, "attitude": self.attitude, "gimbal": self.gimbal,
                  "range": self.range, "frames": self.frames}
        out = [k for k, v in needed.items() if v is None]
        if self.position is not None and self.position.alt_datum == "missing":
            out.append("altitude")
        return out
