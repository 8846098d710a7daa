"""The true flight: the camera's path around the target, the vehicle's attitude, and the gimbal's pointing.

Working frame: ENU metres at the target (`enu` below, z up; the ground is its z = 0 plane, the plane tangent to
the ellipsoid at the target, which departs from the ellipsoid by at most 0.31 m within 2 km, the visible footprint).
Attitudes are built in the vehicle's own local level frame (NED at its position) as an autopilot has them and
carried into the target ENU frame through ECEF, so the logged attitudes are correct relative to the local level
at the vehicle (the two frames differ by ~0.8 mrad at 5 km).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pymap3d
from scipy.interpolate import make_interp_spline
from scipy.spatial.transform import Rotation

from pipeline.errors import ConfigError
from pipeline.geometry.camera import look_at_rotation
from pipeline.geometry.frames import R_ENU_FROM_NED, lla_from_enu
from pipeline.geometry.pose import R_OPTICAL_FROM_GIMBAL_DEFAULT as R_OPTICAL_FROM_GIMBAL
from pipeline.synth.config import SynthConfig
from pipeline.synth.noise import sample_process, smooth_gauss_markov

GRAVITY_MPS2 = 9.80665
MASTER_RATE_HZ = 100.0  # random processes are drawn on this grid and interpolated to sample times


def R_ecef_from_enu(lat_deg, lon_deg) -> np.ndarray:
    """(..., 3, 3) rotation taking ENU vectors at (lat, lon) into ECEF (columns east, north, up), via pymap3d."""
    lat, lon = np.broadcast_arrays(np.asarray(lat_deg, dtype=np.float64), np.asarray(lon_deg, dtype=np.float64))
    cols = [np.stack(pymap3d.enu2uvw(b[0], b[1], b[2], lat, lon), axis=-1) for b in np.eye(3)]
    return np.stack(cols, axis=-1)


class CameraPath:
    """Camera centre in target ENU as a function of time; `span_m` is the path length between the first and the
    last observation. Constructed from the config and the observation times (seconds since telemetry start)."""

    def __init__(self, cfg: SynthConfig, t_first_s: float, t_last_s: float):
        p = cfg.path
        self.kind = p.kind
        self.t_first_s, self.t_last_s = t_first_s, t_last_s
        horiz = math.sqrt(p.slant_distance_m ** 2 - p.height_m ** 2)
        self.radius_m, self.height_m = horiz, p.height_m
        self.psi0 = math.radians(p.start_azimuth_deg)
        self.sign = 1.0 if p.direction == "cw" else -1.0
        gamma = math.radians(p.intersection_angle_deg)
        if p.kind == "arc":
            # unit lines of sight at equal elevation: cos(gamma) = sin^2(th) cos(dpsi) + cos^2(th)
            s2 = (horiz / p.slant_distance_m) ** 2
            self.dpsi = math.acos((math.cos(gamma) - (1.0 - s2)) / s2)
            self.span_m = horiz * self.dpsi
        elif p.kind == "straight":
            self.half_m = p.slant_distance_m * math.tan(gamma / 2.0)
            self.span_m = 2.0 * self.half_m
        elif p.kind == "hover":
            self.span_m = 0.0
        else:
            self._init_waypoints(np.asarray(p.waypoints_enu_m, dtype=np.float64), p.speed_mps)

    def _init_waypoints(self, wp: np.ndarray, speed_mps: float) -> None:
        chord = np.r_[0.0, np.cumsum(np.linalg.norm(np.diff(wp, axis=0), axis=1))]
        if (np.diff(chord) <= 0).any():
            raise ConfigError("'path.waypoints_enu_m' has repeated points")
        self.curve = make_interp_spline(chord, wp, k=min(3, len(wp) - 1), bc_type=None)
        u = np.linspace(0.0, chord[-1], 20001)
        pts = self.curve(u)
        arclen = np.r_[0.0, np.cumsum(np.linalg.norm(np.diff(pts, axis=0), axis=1))]
        self.u_of_s = (arclen, u)
        self.speed_mps = speed_mps
        self.length_m = arclen[-1]
        self.span_m = speed_mps * (self.t_last_s - self.t_first_s)

    def position(self, t_s) -> np.ndarray:
        """(n, 3) camera centre in target ENU metres at times t_s (n,) seconds since telemetry start."""
        t = np.asarray(t_s, dtype=np.float64)
        s = (t - self.t_first_s) / (self.t_last_s - self.t_first_s)
        if self.kind == "arc":
            psi = self.psi0 + self.sign * self.dpsi * s
            return np.stack([self.radius_m * np.sin(psi), self.radius_m * np.cos(psi),
                             np.full_like(psi, self.height_m)], axis=-1)
        if self.kind == "hover":
            at = np.array([self.radius_m * math.sin(self.psi0), self.radius_m * math.cos(self.psi0), self.height_m])
            return np.broadcast_to(at, (t.size, 3)).copy()
        if self.kind == "straight":
            mid = np.array([self.radius_m * math.sin(self.psi0), self.radius_m * math.cos(self.psi0), self.height_m])
            d = self.sign * np.array([math.cos(self.psi0), -math.sin(self.psi0), 0.0])
            return mid + (self.half_m * (2.0 * s - 1.0))[:, None] * d
        dist = self.speed_mps * t
        if dist.max() > self.length_m:
            raise ConfigError(f"the waypoints path ({self.length_m:.0f} m) is too short for the flight "
                              f"({dist.max():.0f} m at {self.speed_mps} m/s)")
        arclen, u = self.u_of_s
        return self.curve(np.interp(dist, arclen, u))


@dataclass(frozen=True)
class TrueState:
    """The true state at n sample times. Positions in target ENU metres; rotations (n, 3, 3).

    camera_enu, rangefinder_enu, antenna_enu (n, 3); antenna_lla (n, 3) (lat, lon deg, ellipsoid m);
    R_enu_from_body, R_enu_from_optical: into target ENU; R_ned_from_body, R_ned_from_gimbal: into the local
    level NED at the vehicle (what the autopilot logs); velocity_ned (n, 3) m/s at the vehicle; yaw_rad (n,)."""

    t_ns: np.ndarray
    camera_enu: np.ndarray
    rangefinder_enu: np.ndarray
    antenna_enu: np.ndarray
    antenna_lla: np.ndarray
    R_enu_from_body: np.ndarray
    R_enu_from_optical: np.ndarray
    R_ned_from_body: np.ndarray
    R_ned_from_gimbal: np.ndarray
    velocity_ned: np.ndarray
    yaw_rad: np.ndarray


class Flight:
    """The true flight, evaluable at any telemetry time. Random but smooth parts (turbulence, tracker jitter,
    gimbal slips) are drawn once on a 100 Hz grid from `rng` and interpolated."""

    def __init__(self, cfg: SynthConfig, t0_ns: int, end_ns: int, obs_t_ns: np.ndarray, rng_wobble, rng_jitter):
        self.cfg = cfg
        self.t0_ns = t0_ns
        self.target_lla = (cfg.site.lat_deg, cfg.site.lon_deg, cfg.site.alt_m)
        self.R_ecef_from_enu_t = R_ecef_from_enu(cfg.site.lat_deg, cfg.site.lon_deg)
        obs_s = (obs_t_ns - t0_ns) / 1e9
        self.path = CameraPath(cfg, float(obs_s[0]), float(obs_s[-1]))
        dur_s = (end_ns - t0_ns) / 1e9
        self.grid_s = np.arange(0.0, dur_s + 1.0, 1.0 / MASTER_RATE_HZ)
        dt = 1.0 / MASTER_RATE_HZ
        nz, g = cfg.noise, cfg.gimbal
        self.wobble_rad = smooth_gauss_markov(rng_wobble, len(self.grid_s), 3, math.radians(nz.vehicle_wobble_deg),
                                              nz.vehicle_wobble_tau_s, 0.3, dt)
        jit = smooth_gauss_markov(rng_jitter, len(self.grid_s), 2, g.jitter_px, g.jitter_tau_s, 0.3, dt)
        slip = np.zeros(len(self.grid_s))
        for k in cfg.lost_target.slipped_observations:  # the gimbal loses lock for ~1.2 s around the observation
            slip[np.abs(self.grid_s - obs_s[k]) <= 0.6] = cfg.lost_target.slip_px
        jit[:, 0] += slip
        self.jitter_px = jit

    def enu_to_lla(self, enu: np.ndarray) -> np.ndarray:
        return lla_from_enu(enu, self.target_lla)

    def state(self, t_ns) -> TrueState:
        """The true state at telemetry times t_ns (n,) int64 UNIX ns."""
        cfg = self.cfg
        t_ns = np.asarray(t_ns, dtype=np.int64)
        t_s = (t_ns - self.t0_ns) / 1e9
        h = 0.05
        cam = self.path.position(t_s)
        vel_enu = (self.path.position(t_s + h) - self.path.position(t_s - h)) / (2 * h)
        acc_enu = (self.path.position(t_s + h) - 2 * cam + self.path.position(t_s - h)) / h ** 2
        lla = self.enu_to_lla(cam)
        R_ecef_from_enu_v = R_ecef_from_enu(lla[:, 0], lla[:, 1])
        R_ecef_from_ned_v = R_ecef_from_enu_v @ R_ENU_FROM_NED
        R_enu_t_from_ned_v = self.R_ecef_from_enu_t.T @ R_ecef_from_ned_v
        R_ned_v_from_enu_t = np.swapaxes(R_enu_t_from_ned_v, -1, -2)
        v_ned = np.einsum("nij,nj->ni", R_ned_v_from_enu_t, vel_enu)
        a_ned = np.einsum("nij,nj->ni", R_ned_v_from_enu_t, acc_enu)
        # heading along the velocity; hovering (below 0.1 m/s), towards the target
        to_target = np.einsum("nij,nj->ni", R_ned_v_from_enu_t, -cam)
        moving = np.hypot(v_ned[:, 0], v_ned[:, 1]) > 0.1
        yaw = np.where(moving, np.arctan2(v_ned[:, 1], v_ned[:, 0]), np.arctan2(to_target[:, 1], to_target[:, 0]))
        right = np.stack([-np.sin(yaw), np.cos(yaw), np.zeros_like(yaw)], axis=-1)
        roll = np.arctan2(np.einsum("ni,ni->n", a_ned, right), GRAVITY_MPS2)  # coordinated turn
        climb = np.arctan2(-v_ned[:, 2], np.hypot(v_ned[:, 0], v_ned[:, 1]))
        pitch = math.radians(cfg.path.pitch_deg) + climb
        w = sample_process(self.grid_s, self.wobble_rad, t_s)
        ypr = np.stack([yaw + w[:, 2], pitch + w[:, 1], roll + w[:, 0]], axis=-1)
        R_ned_from_body = Rotation.from_euler("ZYX", ypr).as_matrix()
        R_enu_from_body = R_enu_t_from_ned_v @ R_ned_from_body
        lever_cam = np.asarray(cfg.lever_arms_m.camera)
        lever_rf = np.asarray(cfg.lever_arms_m.rangefinder)
        antenna = cam - R_enu_from_body @ lever_cam
        rangefinder = antenna + R_enu_from_body @ lever_rf
        # the gimbal: optical axis at the target, image rows level with the vehicle's local horizon, then the
        # tracker's error as a small rotation putting the target at (jx, jy) px from the principal point
        up_v = R_enu_t_from_ned_v @ np.array([0.0, 0.0, -1.0])
        R_cam_from_enu = look_at_rotation(cam, np.zeros(3), up_v)
        jit = sample_process(self.grid_s, self.jitter_px, t_s)
        rotvec = np.stack([-np.arctan(jit[:, 1] / cfg.camera.fy_px), np.arctan(jit[:, 0] / cfg.camera.fx_px),
                           np.zeros(len(t_s))], axis=-1)
        R_cam_from_enu = Rotation.from_rotvec(rotvec).as_matrix() @ R_cam_from_enu
        R_enu_from_optical = np.swapaxes(R_cam_from_enu, -1, -2)
        R_ned_from_gimbal = R_ned_v_from_enu_t @ R_enu_from_optical @ R_OPTICAL_FROM_GIMBAL
        return TrueState(t_ns=t_ns, camera_enu=cam, rangefinder_enu=rangefinder, antenna_enu=antenna,
                         antenna_lla=self.enu_to_lla(antenna), R_enu_from_body=R_enu_from_body,
                         R_enu_from_optical=R_enu_from_optical, R_ned_from_body=R_ned_from_body,
                         R_ned_from_gimbal=R_ned_from_gimbal, velocity_ned=v_ned, yaw_rad=yaw)


def observation_spacing_s(cfg: SynthConfig) -> int:
    """Whole seconds between observations: configured, or the nominal speed's spacing rounded (>= 1 s)."""
    if cfg.observations.spacing_s > 0:
        return cfg.observations.spacing_s
    probe = CameraPath(cfg, 0.0, 1.0)
    per_m = probe.span_m / (cfg.observations.count - 1)
    step = max(1, round(per_m / cfg.path.speed_mps))
    laser_period = 1.0 / cfg.rates.laser_hz
    return int(max(laser_period, round(step / laser_period) * laser_period))
