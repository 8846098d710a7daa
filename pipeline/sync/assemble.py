"""Vehicle state at the observation times, and the synchronized `Observations`."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pipeline.errors import ConfigError, InputError
from pipeline.geometry.frames import ellipsoid_from_amsl_m
from pipeline.geometry.lens import undistort_pixels
from pipeline.geometry.pose import FramePoses
from pipeline.ingest.model import FlightLog
from pipeline.solve.observations import Observations, Sigma
from pipeline.sync.interpolate import interpolate_linear, interpolate_rotations, nearest_within


@dataclass(frozen=True)
class FrameStates:
    """Vehicle state at m query times: lat_deg, lon_deg, alt_m (ellipsoid) (m,), body_quat_wxyz and
    gimbal_quat_wxyz (m, 4), yaw_in_vehicle_frame (m,) bool, inside (m,) bool (all sources cover the time)."""

    t_ns: np.ndarray
    lat_deg: np.ndarray
    lon_deg: np.ndarray
    alt_m: np.ndarray
    body_quat_wxyz: np.ndarray
    gimbal_quat_wxyz: np.ndarray
    yaw_in_vehicle_frame: np.ndarray
    inside: np.ndarray


def _on_telemetry_clock(series, log: FlightLog, offset_ns: int) -> np.ndarray:
    t = np.asarray(series.t_ns, dtype=np.int64)
    if getattr(series, "clock", "unix") == "boot" and log.clock_links:
        from pipeline.ingest.clocks import series_to_clock  # maps boot time through SYSTEM_TIME-like links

        t = np.asarray(series_to_clock(series, log.clock_links, "unix").t_ns, dtype=np.int64)
    return t + int(offset_ns)


def frame_states(log: FlightLog, t_ns: np.ndarray, *, position_offset_ns: int = 0, attitude_offset_ns: int = 0,
                 gimbal_offset_ns: int = 0, geoid_separation_m: float | None = None) -> FrameStates:
    """Interpolate position (linear), vehicle and gimbal attitude (Slerp) at t_ns (telemetry clock)."""
    missing = [k for k in ("position", "attitude", "gimbal") if getattr(log, k) is None]
    if missing:
        raise InputError(f"the flight lacks {', '.join(missing)} (see `ridgeloc inspect` and the mapping)", log.path)
    t = np.asarray(t_ns, dtype=np.int64)
    pos = log.position
    alt = np.asarray(pos.alt_m, dtype=np.float64)
    if pos.alt_datum == "amsl":
        if geoid_separation_m is None:
            raise ConfigError("the positions' altitudes are AMSL: set altitude.geoid_separation_m (ellipsoid height "
                              "minus AMSL height at the flight area)")
        alt = ellipsoid_from_amsl_m(alt, geoid_separation_m)
    elif pos.alt_datum == "relative":
        raise ConfigError("the positions' heights are above the take-off point; ridgeloc needs AMSL or ellipsoid "
                          "heights: give the take-off point's altitude (a DJI SRT's: mapping srt.takeoff_altitude_m "
                          "with srt.abs_datum)")
    elif pos.alt_datum != "ellipsoid":
        raise ConfigError(f"positions have altitude datum {pos.alt_datum!r}; ridgeloc needs AMSL or ellipsoid heights")
    t_pos = _on_telemetry_clock(pos, log, position_offset_ns)
    lla, in_pos = interpolate_linear(t_pos, np.c_[pos.lat_deg, pos.lon_deg, alt], t)
    body, in_att = interpolate_rotations(_on_telemetry_clock(log.attitude, log, attitude_offset_ns),
                                         log.attitude.quat_wxyz, t)
    t_g = _on_telemetry_clock(log.gimbal, log, gimbal_offset_ns)
    gimbal, in_gim = interpolate_rotations(t_g, log.gimbal.quat_wxyz, t)
    j = nearest_within(t_g, t, np.iinfo(np.int64).max // 4)
    flag = np.asarray(log.gimbal.yaw_in_vehicle_frame, dtype=bool)[np.maximum(j, 0)]
    return FrameStates(t_ns=t, lat_deg=lla[:, 0], lon_deg=lla[:, 1], alt_m=lla[:, 2], body_quat_wxyz=body,
                       gimbal_quat_wxyz=gimbal, yaw_in_vehicle_frame=flag, inside=in_pos & in_att & in_gim)


def assemble_observations(poses: FramePoses, t_ns: np.ndarray, pixel_px: np.ndarray, range_m: np.ndarray, *,
                          K: np.ndarray, dist, sigma: Sigma | None = None, truth_m=None) -> Observations:
    """The synchronized observations of n frames with known poses (`pipeline.flight.Flight.poses`).

    t_ns (n,) telemetry times; K: (3, 3), or (n, 3, 3) per frame. pixel_px (n, 2) are image pixels as tracked
    (distorted; NaN where the target was lost): they are undistorted so that P = K [R | t] is an exact pinhole
    model. range_m (n,) (NaN where none). The platform position is the rangefinder's origin."""
    K = np.asarray(K, dtype=np.float64)
    pix = undistort_pixels(np.asarray(pixel_px, dtype=np.float64), K, dist)
    return Observations(P=poses.projection_matrices(K), pixel=pix, platform_m=poses.laser_m,
                        range_m=np.asarray(range_m, dtype=np.float64), t_ns=np.asarray(t_ns, dtype=np.int64),
                        sigma=sigma or Sigma(), truth_m=truth_m)
