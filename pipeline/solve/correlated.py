"""Time-correlated telemetry errors for `mle` (generalized least squares), one problem.

Attitude and platform position errors of real telemetry drift slowly (first-order Gauss-Markov processes:
an IMU/AHRS attitude error with a correlation time of tens of seconds, a GNSS position error of a minute or
more), while the frames of one flight are a few seconds apart. Treating them as independent from frame to
frame overstates the information in the data and makes the covariance too small. With the correlation times
`Sigma.attitude_tau_s` and `Sigma.position_tau_s` the residual covariance, per image axis (u, v) over the
frames with a pixel and over the frames with a range, is

    C_u[i, j] = pixel_px^2 delta_ij + fx_i fx_j (att^2 exp(-|t_i - t_j| / tau_att)
                                                 + pos^2 / (D_i D_j) exp(-|t_i - t_j| / tau_pos))
    C_d[i, j] = range_m^2 delta_ij + pos^2 exp(-|t_i - t_j| / tau_pos)

(likewise C_v with fy; a tau of None or 0 leaves that part on the diagonal, which is then exactly the
independent model of `mle.base_variances`). u, v and range rows stay mutually uncorrelated, as in the
independent model. The residuals and the Jacobian are whitened by W = L^-1, C = L L^T (Cholesky), after
which the problem has unit variances and the estimator runs unchanged; with a robust loss, rows down-weighted
by it get an inflated independent variance C_ii / w_i before the whitening (`inflated_whitening`, used by
`single._mle_correlated_robust`).
"""

from __future__ import annotations

import math

import numpy as np
from scipy.linalg.lapack import dpotrf, dtrtrs

from pipeline.solve.observations import Sigma


def _kernel(t_s: np.ndarray, tau_s: float | None) -> np.ndarray:
    """(k,k) correlation exp(-|t_i - t_j| / tau); the identity when tau is None or 0."""
    if not tau_s:
        return np.eye(t_s.size)
    return np.exp(-np.abs(t_s[:, None] - t_s[None, :]) / tau_s)


def _cholesky_lower(C: np.ndarray) -> np.ndarray:
    """L (lower) with C = L L^T, by LAPACK directly (small matrices: the scipy wrappers' checks cost more than
    the factorization); a tiny diagonal load when C is singular (frames at equal times with no white part)."""
    L, info = dpotrf(C, lower=1, clean=1)
    if info != 0:
        L, info = dpotrf(C + 1e-12 * np.trace(C) / len(C) * np.eye(len(C)), lower=1, clean=1)
        if info != 0:
            raise np.linalg.LinAlgError("the residual covariance is not positive definite")
    return L


def _solve_lower(L: np.ndarray, B: np.ndarray) -> np.ndarray:
    """L^-1 B for lower-triangular L."""
    X, info = dtrtrs(L, B, lower=1)
    if info != 0:  # pragma: no cover - L from _cholesky_lower has a positive diagonal
        raise np.linalg.LinAlgError("singular triangular factor")
    return X


def _inverse_cholesky(C: np.ndarray) -> np.ndarray:
    """W = L^-1 for C = L L^T (lower)."""
    if C.size == 0:
        return C
    return _solve_lower(_cholesky_lower(C), np.eye(len(C)))


def covariance_blocks(t_pix_s, t_rng_s, fx, fy, D_pix_m, sigma: Sigma):
    """The residual covariances C_u, C_v (k,k) px^2 over the k frames with a pixel and C_d (l,l) m^2 over the
    l frames with a range (module docstring). Unknown pixel / range sigmas count as 1 px / 1 m (variance
    component estimation then scales them), like `mle.base_variances`."""
    s_px = 1.0 if sigma.pixel_px is None else sigma.pixel_px
    s_r = 1.0 if sigma.range_m is None else sigma.range_m
    s_pos = 0.0 if sigma.position_m is None else sigma.position_m
    s_att = 0.0 if sigma.attitude_deg is None else math.radians(sigma.attitude_deg)
    k = len(t_pix_s)
    ang = s_att ** 2 * _kernel(t_pix_s, sigma.attitude_tau_s)
    if s_pos > 0:
        inv_d = np.where(np.isfinite(D_pix_m) & (D_pix_m > 0), 1.0 / np.where(D_pix_m > 0, D_pix_m, 1.0), 0.0)
        ang = ang + s_pos ** 2 * np.outer(inv_d, inv_d) * _kernel(t_pix_s, sigma.position_tau_s)
    white = s_px ** 2 * np.eye(k)
    C_u = white + np.outer(fx, fx) * ang
    C_v = white + np.outer(fy, fy) * ang
    C_d = s_r ** 2 * np.eye(len(t_rng_s)) + s_pos ** 2 * _kernel(t_rng_s, sigma.position_tau_s)
    return C_u, C_v, C_d


def full_covariance(t_pix_s, t_rng_s, fx, fy, D_pix_m, sigma: Sigma) -> np.ndarray:
    """C (m,m), m = 2k + l, of the residual rows [u_1, v_1, ..., u_k, v_k, d_1, ..., d_l] of `mle`."""
    C_u, C_v, C_d = covariance_blocks(t_pix_s, t_rng_s, fx, fy, D_pix_m, sigma)
    k, m = len(t_pix_s), 2 * len(t_pix_s) + len(t_rng_s)
    C = np.zeros((m, m))
    C[0:2 * k:2, 0:2 * k:2] = C_u
    C[1:2 * k:2, 1:2 * k:2] = C_v
    C[2 * k:, 2 * k:] = C_d
    return C


def inflated_whitening(C: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """W = L^-1 of the robustly reweighted covariance C + diag(C_ii (1/w_i - 1)) (weights w in (0, 1]): a row
    with weight w is treated as carrying an extra independent error that makes its variance C_ii / w (a gross
    error in that one observation), its correlations with the others unchanged in covariance."""
    return _inverse_cholesky(_inflated(C, weights))


def inflated_whiten(C: np.ndarray, weights: np.ndarray, A: np.ndarray) -> np.ndarray:
    """`inflated_whitening`(C, weights) @ A, by one triangular solve."""
    return _solve_lower(_cholesky_lower(_inflated(C, weights)), A)


def _inflated(C: np.ndarray, weights: np.ndarray) -> np.ndarray:
    Cw = C.copy()
    d = np.einsum("ii->i", Cw)  # a view of the diagonal
    d *= 1.0 / weights
    return Cw
