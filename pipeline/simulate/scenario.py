"""Simulated trials of the paper's experiment (section 3.1): true geometry, then noise "as it happens".

The target is at the world origin (ENU metres, z up). The true camera at each platform position looks at the
target (plus optional pointing jitter). What a sensor measures comes from the TRUE pose: the pixel is the target
projected through the true camera plus pixel noise, the range is the true distance plus range noise. What the
estimators are told about the pose is NOISY: the platform position plus position noise (also the laser origin
they use) and the true attitude composed with a small random rotation. All B trials of one intersection angle
are drawn at once as (B, n, ...) arrays.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from pipeline.geometry import rays
from pipeline.geometry.camera import intrinsics_matrix, look_at_rotation, project, projection_matrix
from pipeline.simulate.config import CameraConfig, GeometryConfig, NoiseConfig, SimulationConfig
from pipeline.solve.observations import ObservationBatch, Sigma

TARGET_M = np.zeros(3)


def arc_path_m(n: int, intersection_angle_deg: float, height_m: float, slant_m: float) -> np.ndarray:
    """(n, 3) platform positions on a horizontal arc around the origin, every one slant_m from it and height_m
    above it, evenly spaced in azimuth so that the first and last lines of sight make the intersection angle."""
    gamma = math.radians(intersection_angle_deg)
    h, d = height_m, slant_m
    r = math.sqrt(d * d - h * h)  # horizontal distance at the nominal observation angle
    # LOS to azimuth phi: (-r sin phi, r cos phi, -h)/d, so cos(gamma) = (r^2 cos(dphi) + h^2) / d^2.
    dphi = math.acos((d * d * math.cos(gamma) - h * h) / (r * r))
    phi = np.linspace(-dphi / 2, dphi / 2, n)
    return np.stack([r * np.sin(phi), -r * np.cos(phi), np.full(n, h)], axis=1)


def platform_path_m(g: GeometryConfig, intersection_angle_deg: float) -> np.ndarray:
    """(n, 3) true platform positions whose first and last lines of sight to the target (the origin) make
    `intersection_angle_deg`, evenly spaced along the path (arc: in azimuth; straight: in distance)."""
    if g.path == "arc":
        return arc_path_m(g.n_observations, intersection_angle_deg, g.height_m, g.slant_distance_m)
    # Straight level line y = -r, z = h: end points at x = +-a with cos(gamma) = (d^2 - a^2) / (d^2 + a^2).
    d = g.slant_distance_m
    r = math.sqrt(d * d - g.height_m ** 2)
    a = d * math.tan(math.radians(intersection_angle_deg) / 2)
    x = np.linspace(-a, a, g.n_observations)
    return np.stack([x, np.full(g.n_observations, -r), np.full(g.n_observations, g.height_m)], axis=1)


def intersection_angle_deg(platform_m: np.ndarray, target_m: np.ndarray = TARGET_M) -> float:
    """Angle between the first and last lines of sight (the paper's gamma), degrees."""
    return rays.intersection_angle_deg(platform_m, target_m)


def observation_angle_deg(g: GeometryConfig) -> float:
    """Angle between the line of sight and the vertical at the nominal slant distance (the paper's theta)."""
    return math.degrees(math.acos(g.height_m / g.slant_distance_m))


def camera_matrix(c: CameraConfig) -> np.ndarray:
    return intrinsics_matrix(c.focal_length_px, c.focal_length_px, c.image_width_px / 2, c.image_height_px / 2)


def _small_rotations(rotvec_rad: np.ndarray) -> np.ndarray:
    """(..., 3, 3) rotation matrices of (..., 3) rotation vectors."""
    shape = rotvec_rad.shape[:-1]
    return Rotation.from_rotvec(rotvec_rad.reshape(-1, 3)).as_matrix().reshape(*shape, 3, 3)


@dataclass(frozen=True)
class Trials:
    """B simulated problems of one intersection angle.

    batch: what the estimators see (noisy P and platform, measured pixels and ranges), with truth_m (B, 3).
    platform_true_m: (n, 3) true platform positions (the same in every trial).
    R_true: (B, n, 3, 3) true camera attitudes (R_cam_from_world); identical across B without jitter.
    P_true: (B, n, 3, 4) true projection matrices.
    attitude_error_rad: (B, n, 3) rotation vectors composed with the true attitudes (camera frame).
    intersection_angle_deg: measured from the true lines of sight of the first and last frames.
    """

    batch: ObservationBatch
    platform_true_m: np.ndarray
    R_true: np.ndarray
    P_true: np.ndarray
    attitude_error_rad: np.ndarray
    intersection_angle_deg: float


def attitude_errors_rad(noise: NoiseConfig, z: np.ndarray) -> np.ndarray:
    """(B, n, 3) attitude error rotation vectors from (B, n, 3) standard normal draws z."""
    sigma = math.radians(noise.attitude_deg)
    if noise.attitude_model == "independent":
        return sigma * z
    if noise.attitude_model == "accumulating":
        return sigma * np.cumsum(z, axis=1)
    return sigma * np.broadcast_to(z[:, :1], z.shape).copy()  # constant: one bias per trial


def mle_sigma(cfg: SimulationConfig) -> Sigma:
    """The a-priori standard deviations handed to the estimators (the MLE uses them; 'estimated' = none)."""
    if cfg.solver.mle_sigma == "estimated":
        return Sigma()
    nz = cfg.noise
    return Sigma(pixel_px=nz.pixel_px, range_m=nz.range_m, position_m=nz.platform_position_m,
                 attitude_deg=nz.attitude_deg)


def trial_rng(seed: int, intersection_angle_deg: float) -> np.random.Generator:
    """The random stream of one angle: it depends only on the seed and the angle, not on which other angles or
    methods run, so every estimator sees the same trials and configs can be compared trial by trial."""
    return np.random.default_rng(np.random.SeedSequence([seed, round(intersection_angle_deg * 1e6)]))


def generate(cfg: SimulationConfig, angle_deg: float, trials: int | None = None,
             rng: np.random.Generator | None = None) -> Trials:
    """Draw `trials` (default cfg.trials) noisy problems at one intersection angle."""
    B = cfg.trials if trials is None else trials
    rng = trial_rng(cfg.seed, angle_deg) if rng is None else rng
    g, nz = cfg.geometry, cfg.noise
    n = g.n_observations
    centres = platform_path_m(g, angle_deg)
    K = camera_matrix(cfg.camera)

    # Standard normal draws in a fixed order and shape, whatever the noise model, so that configs differing
    # only in a noise setting see the same underlying random numbers.
    z_position = rng.standard_normal((B, n, 3))
    z_attitude = rng.standard_normal((B, n, 3))
    z_pixel = rng.standard_normal((B, n, 2))
    z_range = rng.standard_normal((B, n))
    z_jitter = rng.standard_normal((B, n, 2))

    R_look = look_at_rotation(centres, TARGET_M)  # (n, 3, 3)
    if cfg.camera.pointing_jitter_deg > 0:
        jitter = np.concatenate([z_jitter, np.zeros((B, n, 1))], axis=-1) * math.radians(cfg.camera.pointing_jitter_deg)
        R_true = _small_rotations(jitter) @ R_look
    else:
        R_true = np.broadcast_to(R_look, (B, n, 3, 3))
    P_true = projection_matrix(K, R_true, centres)
    target = np.broadcast_to(TARGET_M, (B, n, 3))
    pixel = project(P_true, target) + nz.pixel_px * z_pixel
    range_m = np.broadcast_to(np.linalg.norm(centres - TARGET_M, axis=1), (B, n)) + nz.range_m * z_range

    platform_seen = centres + nz.platform_position_m * z_position
    att = attitude_errors_rad(nz, z_attitude)
    R_seen = _small_rotations(att) @ R_true
    P_seen = projection_matrix(K, R_seen, platform_seen)

    batch = ObservationBatch(P=P_seen, pixel=pixel, platform_m=platform_seen, range_m=range_m,
                             sigma=mle_sigma(cfg), truth_m=np.broadcast_to(TARGET_M, (B, 3)).copy())
    return Trials(batch=batch, platform_true_m=centres, R_true=np.asarray(R_true), P_true=P_true,
                  attitude_error_rad=att, intersection_angle_deg=intersection_angle_deg(centres))
