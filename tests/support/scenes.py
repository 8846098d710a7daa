"""Synthetic problems on the paper's simulation geometry (section 3.1), for tests, benchmarks and the example
observations file (test support, not part of the package; `ridgeloc simulate` draws its own trials in
pipeline/simulate/scenario.py).

The platform flies a circular arc around the target at a fixed height, so that every frame sees the target at
the same slant range; the arc's extent is set so that the first and last lines of sight make the intersection
angle gamma. The camera looks at the target (target at the principal point). Noise, as in the paper: platform
position (per axis), laser range, camera attitude (per axis, a small rotation applied to the measured attitude)
and pixel extraction.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from pipeline.geometry.camera import intrinsics_matrix, look_at_rotation, project, projection_matrix
from pipeline.simulate.scenario import arc_path_m
from pipeline.solve.observations import ObservationBatch, Observations, Sigma
from pipeline.synth.noise import gauss_markov_filter

PAPER_SIGMA = Sigma(pixel_px=0.1, range_m=2.5, position_m=5.0, attitude_deg=0.2)
#: a 600 x 400 px camera (the paper's flight experiment resolution) with f = 1000 px
PAPER_K = intrinsics_matrix(1000.0, 1000.0, 300.0, 200.0)


def arc_platforms_m(n: int = 10, gamma_deg: float = 30.0, height_m: float = 2000.0, slant_m: float = 5000.0,
                    target_m=(0.0, 0.0, 0.0)) -> np.ndarray:
    """(n,3) platform positions on a horizontal arc around the target (`ridgeloc simulate`'s arc, flown the other
    way round): first and last lines of sight make gamma_deg, every one has length slant_m, height_m above the
    target."""
    return np.asarray(target_m, dtype=np.float64) + arc_path_m(n, gamma_deg, height_m, slant_m)[::-1]


def paper_batch(B: int, n: int = 10, gamma_deg: float = 30.0, sigma: Sigma | None = PAPER_SIGMA,
                seed: int | np.random.Generator = 0, height_m: float = 2000.0, slant_m: float = 5000.0,
                K: np.ndarray = PAPER_K) -> ObservationBatch:
    """B independent noisy problems on the arc geometry (sigma None or zeros: noise-free)."""
    rng = np.random.default_rng(seed)
    s = sigma if sigma is not None else Sigma(0.0, 0.0, 0.0, 0.0)
    target = np.zeros(3)
    true_pos = np.broadcast_to(arc_platforms_m(n, gamma_deg, height_m, slant_m, target), (B, n, 3))
    R_true = look_at_rotation(true_pos, target)
    P_true = projection_matrix(K, R_true, true_pos)
    pixel = project(P_true, np.broadcast_to(target, (B, n, 3)))
    pixel = pixel + rng.normal(0.0, s.pixel_px or 0.0, pixel.shape)
    meas_pos = true_pos + rng.normal(0.0, s.position_m or 0.0, true_pos.shape)
    rotvec = rng.normal(0.0, np.deg2rad(s.attitude_deg or 0.0), (B * n, 3))
    R_err = Rotation.from_rotvec(rotvec).as_matrix().reshape(B, n, 3, 3)
    P = projection_matrix(K, R_err @ R_true, meas_pos)
    rng_m = np.linalg.norm(true_pos - target, axis=-1) + rng.normal(0.0, s.range_m or 0.0, (B, n))
    return ObservationBatch(P=P, pixel=pixel, platform_m=meas_pos, range_m=rng_m,
                            sigma=sigma if sigma is not None else Sigma(), truth_m=np.zeros((B, 3)) + target)


def paper_problem(n: int = 10, gamma_deg: float = 30.0, sigma: Sigma | None = PAPER_SIGMA, seed: int = 0,
                  **kwargs) -> Observations:
    """One noisy problem on the arc geometry (see `paper_batch`)."""
    b = paper_batch(1, n, gamma_deg, sigma, seed, **kwargs)
    obs = b.problem(0)
    return Observations(P=obs.P, pixel=obs.pixel, platform_m=obs.platform_m, range_m=obs.range_m,
                        t_ns=np.arange(n, dtype=np.int64) * 1_000_000_000, sigma=b.sigma, truth_m=obs.truth_m)


def gauss_markov(rng: np.random.Generator, shape: tuple, t_s: np.ndarray, sigma: float, tau_s: float | None):
    """First-order Gauss-Markov samples (*shape, n) at evenly spaced times t_s (n,), stationary with standard
    deviation sigma and correlation exp(-|dt| / tau_s); white noise when tau_s is None."""
    w = rng.normal(0.0, sigma, (*shape, t_s.size))
    if not tau_s or t_s.size < 2:
        return w
    dt_s = np.diff(t_s)
    if not np.allclose(dt_s, dt_s[0]):
        raise ValueError("gauss_markov: the times must be evenly spaced")
    return gauss_markov_filter(w, float(dt_s[0]), tau_s, axis=-1)


def correlated_problems(B: int, n: int = 10, gamma_deg: float = 30.0, sigma: Sigma = PAPER_SIGMA,
                        dt_s: float = 1.0, attitude_tau_s: float | None = 20.0,
                        position_tau_s: float | None = 60.0, seed: int = 0, K: np.ndarray = PAPER_K,
                        attitude_white_deg: float = 0.0) -> list[Observations]:
    """B problems on the arc geometry of `paper_batch` whose attitude (rotation vector, per axis) and platform
    position (per axis) errors are Gauss-Markov processes over the frames' times (dt_s apart) with the given
    correlation times, like real telemetry, plus white attitude noise of attitude_white_deg per axis; pixel and
    range noise white. The problems' sigma is `sigma` without correlation times (add them to model the
    correlation); t_ns is set."""
    rng = np.random.default_rng(seed)
    t_s = np.arange(n) * dt_s
    target = np.zeros(3)
    true_pos = np.broadcast_to(arc_platforms_m(n, gamma_deg, target_m=target), (B, n, 3))
    R_true = look_at_rotation(true_pos, target)
    P_true = projection_matrix(K, R_true, true_pos)
    pixel = project(P_true, np.broadcast_to(target, (B, n, 3))) + rng.normal(0.0, sigma.pixel_px or 0.0, (B, n, 2))
    pos_err = gauss_markov(rng, (B, 3), t_s, sigma.position_m or 0.0, position_tau_s).transpose(0, 2, 1)
    rotvec = gauss_markov(rng, (B, 3), t_s, np.deg2rad(sigma.attitude_deg or 0.0), attitude_tau_s)
    if attitude_white_deg:
        rotvec = rotvec + rng.normal(0.0, np.deg2rad(attitude_white_deg), rotvec.shape)
    R_err = Rotation.from_rotvec(rotvec.transpose(0, 2, 1).reshape(-1, 3)).as_matrix().reshape(B, n, 3, 3)
    meas_pos = true_pos + pos_err
    P = projection_matrix(K, R_err @ R_true, meas_pos)
    rng_m = np.linalg.norm(true_pos - target, axis=-1) + rng.normal(0.0, sigma.range_m or 0.0, (B, n))
    t_ns = np.round(t_s * 1e9).astype(np.int64)
    return [Observations(P=P[b], pixel=pixel[b], platform_m=meas_pos[b], range_m=rng_m[b], t_ns=t_ns, sigma=sigma,
                         truth_m=target) for b in range(B)]
