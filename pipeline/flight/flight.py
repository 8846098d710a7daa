"""A flight as one object (`Flight`), the way OpenSfM's DataSet is a reconstruction's: its config resolved against
its data, read once. It holds the logs, the frames (open until `close()` or the end of a `with` block), the
camera's intrinsics and their source, the observation plan, the geoid separation and the ENU origin; it gives
the vehicle state, the camera/rangefinder poses and the lines of sight at any telemetry time with the config's
clock offsets and lever arms. `ridgeloc run`, `ridgeloc check` and the clock estimate all work from it.

What fails to resolve (no observation frame, an origin that needs a geoid separation) is kept as the error, so
`check` can report it next to everything else; `run` asks for it (`require_plan`, `require_origin`) and stops.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

import numpy as np

from pipeline.errors import ConfigError, InputError, RidgelocError
from pipeline.flight.frames import FrameSource, open_frames, with_cut_off
from pipeline.flight_config import Camera, FlightConfig
from pipeline.geometry.frames import ellipsoid_from_amsl_m
from pipeline.geometry.lens import undistort_pixels
from pipeline.geometry.pose import FramePoses, frame_poses
from pipeline.ingest.model import FlightLog, FrameSeries, GimbalSeries
from pipeline.intrinsics import resolve_camera
from pipeline.sync.assemble import FrameStates, frame_states
from pipeline.sync.select import ObservationPlan, plan_observations

#: the `mapping:` sections each format's reader takes (`video`: a video listed among the telemetry files; the
#: video of files.video takes files.frames_csv)
_MAPPING_SECTIONS = {"tlog": ("tlog",), "dataflash": ("dataflash",), "ulog": ("ulog",), "ros1": ("ros",),
                     "ros2": ("ros",), "mcap": ("mcap", "ros"), "klv": ("klv",), "fmv": ("klv",), "srt": ("srt",),
                     "video": ("video",)}


def unused_mapping_warnings(mapping: dict | None, formats: list[str]) -> list[str]:
    """A warning per `mapping:` section that no file of the flight is read with (a `ros:` block on a tlog flight
    changes nothing, which looks like a fix that took). `formats`: those of the telemetry files."""
    used = {k for f in formats for k in _MAPPING_SECTIONS.get(f, ())}
    files = ", ".join(dict.fromkeys(formats))
    return [f"mapping.video: read only for a video listed in files.telemetry (its files: {files}); the video of "
            "files.video takes files.frames_csv, so this section changes nothing" if k == "video" else
            f"mapping.{k}: no file of this flight is read as {k} (its files: {files}), so this section changes "
            "nothing" for k in sorted(set(mapping or {}) - used)]


def camera_on_the_body(log: FlightLog, shift_ns: int = 0) -> FlightLog:
    """`camera.fixed_to_body`: the log's vehicle attitude as its gimbal (the gimbal frame is the body frame, so the
    camera mount R_optical_from_gimbal is its mounting on the airframe), its times moved by `shift_ns` (the
    attitude's clock offset less the gimbal's, so that the gimbal's offset puts it where the attitude's puts the
    attitude); a gimbal the log states is set aside, with a warning. The log unchanged without an attitude (the
    missing attitude is then reported)."""
    att = log.attitude
    if att is None:
        return log
    warnings = list(log.warnings)
    if log.gimbal is not None:
        warnings.append(f"camera.fixed_to_body: the gimbal attitude of {log.gimbal.source or 'the logs'} is not "
                        "used; the camera turns with the vehicle's attitude")
    gimbal = GimbalSeries(att.t_ns + np.int64(shift_ns), att.quat_wxyz, np.zeros(att.t_ns.size, dtype=bool),
                          source=f"{att.source} (camera fixed to the body)", clock=att.clock, sigma_deg=att.sigma_deg)
    return dataclasses.replace(log, gimbal=gimbal, warnings=warnings)


def read_flight_logs(config: FlightConfig) -> FlightLog:
    """The flight's telemetry files read into one FlightLog; InputError when it lacks position, attitude or gimbal."""
    from pipeline.ingest import read_flight
    from pipeline.ingest.mapping import check_override

    try:  # a mistake in the config's `mapping:` (a ConfigError naming no file) is the config file's: name it
        check_override(config.mapping)
        log = read_flight(list(config.files.telemetry), mapping=config.mapping)
    except ConfigError as exc:
        if exc.path is not None or config.path is None:
            raise
        raise ConfigError(str(exc), config.path) from None
    log.warnings += unused_mapping_warnings(config.mapping, log.formats)
    if config.camera.fixed_to_body:
        log = camera_on_the_body(log, config.clock.offset_ns("attitude") - config.clock.offset_ns("gimbal"))
    missing = [q for q in ("position", "attitude", "gimbal") if getattr(log, q) is None]
    if config.camera.fixed_to_body and "attitude" in missing:  # no gimbal to give: the camera turns with the body
        missing = [q if q != "attitude" else "attitude (camera.fixed_to_body: the camera turns with it)"
                   for q in missing if q != "gimbal"]
    if missing:
        supplied = [q for q in ("position", "attitude", "gimbal", "range", "frames") if getattr(log, q) is not None]
        what = f"supply only {', '.join(supplied)}" if supplied else "supply nothing ridgeloc reads"
        advice = ("a video without KLV metadata needs the flight's telemetry logs beside it (files.telemetry)"
                  if supplied == ["frames"] else
                  "give the logs that record them, or, where a log has them under other names, set `mapping:` "
                  "(`ridgeloc inspect LOG` lists what each file holds)")
        raise with_cut_off(InputError(f"the flight's files {what}: no {', '.join(missing)}; {advice}", config.path),
                           log.warnings)
    return log


def plan_flight_observations(config: FlightConfig, frames: FrameSeries, log: FlightLog,
                             video_offset_ns: int | None = None, keyframe=None) -> ObservationPlan:
    """Which frames are observations, with their laser shots, as the flight config's `observations:` and
    `clock:` say, or with `video_offset_ns` when given (`pipeline.sync.select.plan_observations`; needs only
    timestamps). keyframe (n,) bool: the frames' key-frame flags, when known (observations at key frames)."""
    c, sel = config.clock, config.observations
    video_offset_ns = c.offset_ns("video") if video_offset_ns is None else video_offset_ns
    return plan_observations(frames, log.range, mode=sel.mode, video_offset_ns=video_offset_ns,
                             range_offset_ns=c.offset_ns("range"), frame_tolerance_s=sel.frame_tolerance_s,
                             max_range_gap_s=sel.max_range_gap_s, frame_indices=sel.frame_indices,
                             burst_gap_s=sel.burst_gap_s, keyframe=keyframe, at_key_frames=sel.at_key_frames,
                             key_frame_tolerance_s=sel.key_frame_tolerance_s,
                             range_interpolation_gap_s=sel.range_interpolation_gap_s,
                             range_sigma_m=config.sigma.range_m)


def geoid_separation_m(config: FlightConfig, log: FlightLog) -> float | None:
    """altitude.geoid_separation_m as a number: `auto` -> the EGM2008 undulation at the first finite position."""
    value = config.altitude.geoid_separation_m
    if value != "auto":
        return value
    from pipeline.geometry.geoid import geoid_undulation_m

    pos = log.position
    ok = np.zeros(0, bool) if pos is None else np.isfinite(pos.lat_deg) & np.isfinite(pos.lon_deg)
    if not ok.any():
        raise InputError("altitude.geoid_separation_m: auto needs a position in the logs", config.path)
    i = int(np.flatnonzero(ok)[0])
    lat, lon = float(pos.lat_deg[i]), float(pos.lon_deg[i])
    return float(geoid_undulation_m(lat, lon))


def flight_origin(config: FlightConfig, log: FlightLog, separation_m: float | None) -> tuple[float, float, float]:
    """The ENU origin (lat_deg, lon_deg, ellipsoid height m): the config's, or `auto`: the first position."""
    if config.origin != "auto":
        return config.origin.as_tuple()
    pos = log.position
    alt = float(pos.alt_m[0])
    if pos.alt_datum == "amsl":
        if separation_m is None:
            raise ConfigError("altitudes are AMSL: set altitude.geoid_separation_m (a number, or auto)", config.path)
        alt = float(ellipsoid_from_amsl_m(alt, separation_m))
    return float(pos.lat_deg[0]), float(pos.lon_deg[0]), alt


@dataclass
class Flight:
    """A flight config resolved against its data (see the module docstring). `plan` is None when no frame is an
    observation (`plan_error` says why); `origin` and `separation_m` None when they cannot be resolved
    (`origin_error`). `log.frames` is the frame index whatever the frames came from."""

    config: FlightConfig
    log: FlightLog
    source: FrameSource
    camera: Camera
    camera_source: str
    plan: ObservationPlan | None
    plan_error: RidgelocError | None
    separation_m: float | None
    origin: tuple[float, float, float] | None
    origin_error: RidgelocError | None
    notes: list[str] = field(default_factory=list)
    # the configured poses of the times asked so far (times (m,), poses of the inside ones, inside (m,)): every
    # target of a flight asks for the same observation times
    _poses_memo: tuple | None = field(default=None, repr=False, compare=False)

    @classmethod
    def open(cls, config: FlightConfig) -> Flight:
        """Read the logs and the frame index (no pixels decoded) and resolve every role; raises RidgelocError for
        what makes the flight unreadable. The frame reader stays open: use the flight in a `with` block. A photo
        flight (files.photos) is refused: `pipeline.locate` reads it."""
        if config.files.photos:
            raise ConfigError("a photo flight (files.photos), not a video flight: use `ridgeloc locate` or "
                              "`ridgeloc run`", config.path)
        log = read_flight_logs(config)
        source = open_frames(config, log)
        try:
            if log.frames is None:
                log = dataclasses.replace(log, frames=source.frames)
            camera, camera_source = resolve_camera(config, log)
            plan, plan_error = None, None
            try:
                plan = plan_flight_observations(config, source.frames, log, keyframe=source.keyframe)
            except InputError as exc:  # frames missing from a cut-off video: say that it looks cut off
                plan_error = with_cut_off(exc, [*log.warnings, *source.warnings])
            separation, origin, origin_error = None, None, None
            try:
                separation = geoid_separation_m(config, log)
                origin = flight_origin(config, log, separation)
            except RidgelocError as exc:
                origin_error = exc
        except BaseException:
            source.close()
            raise
        return cls(config, log, source, camera, camera_source, plan, plan_error, separation, origin, origin_error,
                   [*log.warnings, *source.warnings])

    # ---- the frames -------------------------------------------------------------------------------------------

    @property
    def frames(self) -> FrameSeries:
        return self.source.frames

    @property
    def decoder(self):
        """decoder(indices) -> {index: gray image}, timed (`pipeline.flight.frames.TimedDecoder`)."""
        return self.source.decoder

    def close(self) -> None:
        self.source.close()

    def __enter__(self) -> Flight:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    # ---- what run needs resolved ------------------------------------------------------------------------------

    def require_plan(self) -> ObservationPlan:
        if self.plan is None:
            raise self.plan_error
        return self.plan

    def require_origin(self) -> tuple[float, float, float]:
        if self.origin is None:
            raise self.origin_error
        return self.origin

    def plan_at(self, video_offset_ns: int) -> ObservationPlan:
        """The observation plan with the video clock `video_offset_ns` (an estimated offset) instead of the
        configured one."""
        return plan_flight_observations(self.config, self.frames, self.log, video_offset_ns, self.source.keyframe)

    # ---- state, poses and lines of sight at telemetry times ---------------------------------------------------

    def telemetry_span_ns(self) -> tuple[int, int] | None:
        """The interval (telemetry clock, ns) that position, attitude and gimbal all cover, with their offsets."""
        c = self.config.clock
        lo, hi = -(2**62), 2**62
        for role in ("position", "attitude", "gimbal"):
            s = getattr(self.log, role)
            off = c.offset_ns(role)
            lo, hi = max(lo, int(s.t_ns[0]) + off), min(hi, int(s.t_ns[-1]) + off)
        return (lo, hi) if lo <= hi else None

    def states(self, t_ns: np.ndarray, log: FlightLog | None = None) -> FrameStates:
        """The vehicle state at telemetry times t_ns (m,), each source shifted by its configured clock offset;
        `log` replaces the flight's (a smoothed or reinterpreted copy)."""
        c = self.config.clock
        return frame_states(log or self.log, t_ns, position_offset_ns=c.offset_ns("position"),
                            attitude_offset_ns=c.offset_ns("attitude"), gimbal_offset_ns=c.offset_ns("gimbal"),
                            geoid_separation_m=self.separation_m)

    def poses(self, t_ns: np.ndarray, *, log: FlightLog | None = None,
              R_optical_from_gimbal: np.ndarray | None = None) -> tuple[FramePoses | None, np.ndarray]:
        """(poses of the times the telemetry covers, that mask `inside` (m,)): camera and rangefinder poses at
        telemetry times t_ns (m,) in ENU at the origin, with the config's clock offsets, mount
        (`R_optical_from_gimbal` replaces it) and lever arms. Poses None when no time is inside. The configured
        poses are computed once per time: times asked before are taken from the earlier answer (row for row the
        same numbers)."""
        configured = log is None and R_optical_from_gimbal is None
        if configured and self._poses_memo is not None:
            got = self._poses_from_memo(np.asarray(t_ns, dtype=np.int64))
            if got is not None:
                return got
        st = self.states(t_ns, log)
        if not st.inside.any():
            return None, st.inside
        k = st.inside
        M = self.camera.R_optical_from_gimbal if R_optical_from_gimbal is None else R_optical_from_gimbal
        arms = self.config.lever_arms_m
        poses = frame_poses(st.lat_deg[k], st.lon_deg[k], st.alt_m[k], st.body_quat_wxyz[k], st.gimbal_quat_wxyz[k],
                            st.yaw_in_vehicle_frame[k], self.require_origin(),
                            R_optical_from_gimbal=np.asarray(M, dtype=float), lever_camera_m=arms.camera,
                            lever_rangefinder_m=arms.rangefinder)
        if configured:
            self._remember_poses(np.asarray(t_ns, dtype=np.int64), poses, st.inside)
        return poses, st.inside

    def _remember_poses(self, t_ns: np.ndarray, poses: FramePoses, inside: np.ndarray) -> None:
        """Keep the times' poses, merged with those kept before (the times in first-asked order)."""
        if self._poses_memo is None:
            self._poses_memo = (t_ns.copy(), poses, inside.copy())
            return
        t0, p0, in0 = self._poses_memo
        new = ~np.isin(t_ns, t0)
        if not new.any():
            return
        t1, in1 = t_ns[new], inside[new]
        p1 = poses.subset(new[inside])
        cat = np.concatenate
        merged = FramePoses(p0.origin_lla, *(cat([getattr(p0, f), getattr(p1, f)]) for f in (
            "R_enu0_from_optical", "camera_m", "laser_m", "antenna_m")))
        self._poses_memo = (cat([t0, t1]), merged, cat([in0, in1]))

    def _poses_from_memo(self, t_ns: np.ndarray) -> tuple[FramePoses | None, np.ndarray] | None:
        """(poses, inside) of times all kept before, else None."""
        t0, p0, in0 = self._poses_memo
        if len(t0) == 0:
            return None
        order = np.argsort(t0, kind="stable")
        rows = order[np.clip(np.searchsorted(t0, t_ns, sorter=order), 0, len(t0) - 1)]
        if not np.array_equal(t0[rows], t_ns):
            return None
        inside = in0[rows]
        if not inside.any():
            return None, inside
        row_of_pose = np.cumsum(in0) - 1  # a kept time's row among the kept poses (inside times only)
        return p0.subset(row_of_pose[rows[inside]]), inside

    def rays(self, t_ns: np.ndarray, pixel_px: np.ndarray | None = None, *, log: FlightLog | None = None,
             R_optical_from_gimbal: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(origins (m, 3), unit directions (m, 3), inside (m,)) of the lines of sight at telemetry times t_ns:
        through pixel_px (m, 2) as tracked (distorted; NaN rows give NaN rays), or the optical axis when None.
        Origins are the rangefinder's; rows outside the telemetry, or all rows when there is no origin, are NaN."""
        m = len(t_ns)
        origins, dirs = np.full((m, 3), np.nan), np.full((m, 3), np.nan)
        if self.origin is None:
            return origins, dirs, self.states(t_ns, log).inside
        poses, k = self.poses(t_ns, log=log, R_optical_from_gimbal=R_optical_from_gimbal)
        if poses is None:
            return origins, dirs, k
        cam = self.camera
        if pixel_px is None:
            d = poses.optical_axis_enu()
        else:
            px = undistort_pixels(np.asarray(pixel_px, dtype=float)[k], cam.K, cam.dist)
            v = np.c_[px, np.ones(len(px))] @ np.linalg.inv(cam.K).T
            d = np.einsum("nij,nj->ni", poses.R_enu0_from_optical, v)
        origins[k], dirs[k] = poses.laser_m, d / np.linalg.norm(d, axis=1, keepdims=True)
        return origins, dirs, k
