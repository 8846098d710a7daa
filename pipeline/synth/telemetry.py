"""Telemetry as the vehicle logs it: sampled at each sensor's rate from the NOISY state.

GNSS: the antenna position plus a slowly drifting error (first-order Gauss-Markov) and white noise. Vehicle and
gimbal attitude: the true rotation into the local level NED at the vehicle, times a slowly varying small error
rotation. Laser: the true range plus white noise, dropouts, and configured outliers. All int64 UNIX ns.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from pipeline.synth.config import SynthConfig
from pipeline.synth.noise import gauss_markov, sample_process
from pipeline.synth.timeline import Timeline
from pipeline.synth.trajectory import MASTER_RATE_HZ, Flight


@dataclass(frozen=True)
class Telemetry:
    """Logged series. gps_lla (n, 3) lat, lon deg, ellipsoid m; gps_vel_ned (n, 3) m/s;
    att_quat_wxyz (n, 4) body FRD -> local NED; att_rates_frd (n, 3) rad/s; gimbal_quat_wxyz (n, 4) gimbal FRD ->
    local NED (or -> vehicle-yawed level frame when gimbal_yaw_in_vehicle); gimbal_delta_yaw_rad (n,) gimbal yaw
    minus vehicle yaw; laser_* (m,) the shots that were logged (dropouts removed), laser_valid within limits."""

    gps_t_ns: np.ndarray
    gps_lla: np.ndarray
    gps_vel_ned: np.ndarray
    att_t_ns: np.ndarray
    att_quat_wxyz: np.ndarray
    att_rates_frd: np.ndarray
    gimbal_t_ns: np.ndarray
    gimbal_quat_wxyz: np.ndarray
    gimbal_delta_yaw_rad: np.ndarray
    gimbal_yaw_in_vehicle: bool
    laser_t_ns: np.ndarray
    laser_range_m: np.ndarray
    laser_valid: np.ndarray
    system_time_t_ns: np.ndarray
    boot_ns: int


@dataclass(frozen=True)
class LaserTruth:
    """Every scheduled shot: t_ns (m,), true range (m,) m, measured range, logged (not dropped), outlier."""

    t_ns: np.ndarray
    range_true_m: np.ndarray
    range_measured_m: np.ndarray
    logged: np.ndarray
    outlier: np.ndarray


def sample_times(t0_ns: int, end_ns: int, rate_hz: float, phase_ns: int = 0) -> np.ndarray:
    period = round(1e9 / rate_hz)
    return np.arange(t0_ns + phase_ns, end_ns, period, dtype=np.int64)


def true_laser_range_m(flight: Flight, t_ns: np.ndarray, beam: np.ndarray) -> np.ndarray:
    """(m,) true range at shots t_ns: to the target, or (where `beam`) to where the optical axis meets the ground."""
    st = flight.state(t_ns)
    to_target = np.linalg.norm(st.rangefinder_enu, axis=1)
    axis = st.R_enu_from_optical[:, :, 2]
    with np.errstate(divide="ignore"):
        lam = -st.rangefinder_enu[:, 2] / axis[:, 2]
    to_ground = np.where(lam > 0, lam, np.inf)
    return np.where(beam, to_ground, to_target)


def make_telemetry(cfg: SynthConfig, tl: Timeline, flight: Flight, rngs: dict) -> tuple[Telemetry, LaserTruth]:
    nz, rates = cfg.noise, cfg.rates
    grid_s = flight.grid_s
    dt = 1.0 / MASTER_RATE_HZ
    n_grid = len(grid_s)

    # GNSS (5 ms phase: receivers report on their own epochs, not on frames)
    gps_t = sample_times(tl.t0_ns, tl.end_ns, rates.gps_hz, 5_000_000)
    st = flight.state(gps_t)
    drift = gauss_markov(rngs["gnss"], n_grid, 3, nz.gnss_drift_m, nz.gnss_tau_s, dt)
    err = sample_process(grid_s, drift, tl.seconds(gps_t)) + rngs["gnss"].normal(0, nz.gnss_white_m, (len(gps_t), 3))
    gps_lla = flight.enu_to_lla(st.antenna_enu + err)
    gps_vel = st.velocity_ned + rngs["gnss"].normal(0, 0.05, (len(gps_t), 3))

    # vehicle attitude
    att_t = sample_times(tl.t0_ns, tl.end_ns, rates.attitude_hz, 2_000_000)
    st = flight.state(att_t)
    att_err = gauss_markov(rngs["attitude"], n_grid, 3, math.radians(nz.attitude_deg), nz.attitude_tau_s, dt)
    R_err = Rotation.from_rotvec(sample_process(grid_s, att_err, tl.seconds(att_t)))
    R_att = R_err * Rotation.from_matrix(st.R_ned_from_body)
    rel = (Rotation.from_matrix(st.R_ned_from_body[:-1]).inv() * Rotation.from_matrix(st.R_ned_from_body[1:]))
    rates_frd = rel.as_rotvec() / (np.diff(att_t)[:, None] / 1e9)
    rates_frd = np.vstack([rates_frd, rates_frd[-1:]])

    # gimbal attitude (earth-referenced, or yaw relative to the vehicle's true heading)
    gim_t = sample_times(tl.t0_ns, tl.end_ns, rates.gimbal_hz, 3_000_000)
    st = flight.state(gim_t)
    gim_err = gauss_markov(rngs["gimbal"], n_grid, 3, math.radians(nz.gimbal_deg), nz.attitude_tau_s, dt)
    R_gim = Rotation.from_rotvec(sample_process(grid_s, gim_err, tl.seconds(gim_t))) * \
        Rotation.from_matrix(st.R_ned_from_gimbal)
    veh_yaw = Rotation.from_matrix(st.R_ned_from_body).as_euler("ZYX")[:, 0]
    gim_yaw = R_gim.as_euler("ZYX")[:, 0]
    delta_yaw = np.angle(np.exp(1j * (gim_yaw - veh_yaw)))
    if cfg.gimbal.yaw_in_vehicle_frame:
        R_gim = Rotation.from_euler("Z", veh_yaw[:, None]).inv() * R_gim

    # laser: shots on video frames
    las_t = tl.frame_time_ns(tl.laser_frames)
    obs_shot = np.isin(tl.laser_frames, tl.obs_frames)
    beam = np.zeros(len(las_t), bool) if cfg.laser.aim == "target" else np.ones(len(las_t), bool)
    for k in cfg.lost_target.slipped_observations:
        beam |= np.abs(las_t - tl.obs_t_ns[k]) <= 600_000_000
    rng_true = true_laser_range_m(flight, las_t, beam)
    meas = rng_true + rngs["laser"].normal(0, nz.laser_m, len(las_t))
    outlier = np.zeros(len(las_t), bool)
    for i, k in enumerate(cfg.laser.outlier_observations):
        j = int(np.flatnonzero(tl.laser_frames == tl.obs_frames[k])[0])
        meas[j] = rng_true[j] + cfg.laser.outlier_offset_m[i % len(cfg.laser.outlier_offset_m)]
        outlier[j] = True
    drop = rngs["laser"].random(len(las_t)) < nz.laser_dropout
    if not nz.laser_dropout_at_observations:
        drop &= ~obs_shot
    drop |= np.isin(tl.laser_frames, tl.obs_frames[list(cfg.laser.dropped_observations)])
    logged = ~drop
    valid = np.isfinite(meas) & (meas >= cfg.laser.min_range_m) & (meas <= cfg.laser.max_range_m)

    sys_t = sample_times(tl.t0_ns, tl.end_ns, rates.system_time_hz, 1_000_000)
    boot_ns = tl.t0_ns - 412_345_000_000  # the autopilot booted ~7 min before logging started
    tel = Telemetry(
        gps_t_ns=gps_t, gps_lla=gps_lla, gps_vel_ned=gps_vel,
        att_t_ns=att_t, att_quat_wxyz=R_att.as_quat(canonical=True, scalar_first=True), att_rates_frd=rates_frd,
        gimbal_t_ns=gim_t, gimbal_quat_wxyz=R_gim.as_quat(canonical=True, scalar_first=True),
        gimbal_delta_yaw_rad=delta_yaw,
        gimbal_yaw_in_vehicle=cfg.gimbal.yaw_in_vehicle_frame,
        laser_t_ns=las_t[logged], laser_range_m=meas[logged], laser_valid=valid[logged],
        system_time_t_ns=sys_t, boot_ns=boot_ns)
    truth = LaserTruth(t_ns=las_t, range_true_m=rng_true, range_measured_m=meas, logged=logged, outlier=outlier)
    return tel, truth
