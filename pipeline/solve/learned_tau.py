"""The telemetry errors' correlation time learned from the flight, for `mle` on one problem whose sigma gives
none (an operator's spec sheet does not).

Attitude and GNSS errors drift: first-order Gauss-Markov with a correlation time tau. `mle` first solves the
independent-error model with a boresight bias (`mle.mle`: redescending loss, fit checks); where it has timestamps
and its residuals drift from frame to frame (`fit_checks`), it then fits the generalized least squares model
(`correlated.mle_gls`) with one correlation time for the attitude and the position errors, for each tau of
TAU_GRID_S, without the rows the first solve rejected, and keeps the tau of the largest Gaussian likelihood

    log L(tau) = -1/2 (r^T C_tau^-1 r / k + m log k + log det C_tau),   k = max(r^T C_tau^-1 r / m, 1)

(r the m residuals at that tau's estimate; the profile likelihood: the same data under each model, the
covariance's size charged by log det, its overall scale k at its maximum likelihood but never below the stated
sigmas). The chosen model's estimate and covariance are the answer; its chi-square is checked again.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from pipeline.solve import correlated as _correlated
from pipeline.solve import fit_checks
from pipeline.solve.estimate import Status
from pipeline.solve.observations import Sigma
from pipeline.solve.stacked import Stacked

#: candidate correlation times (s); from frame-to-frame to about the length of a survey flight
TAU_GRID_S = (5.0, 10.0, 20.0, 40.0, 80.0, 160.0, 320.0)


def without_rejected(st: Stacked, rejected: np.ndarray) -> Stacked:
    """st (B = 1) without the pixels (u or v rejected) and ranges the first solve gave zero weight;
    rejected (n, 3) bool."""
    has_pix = st.has_pix & ~rejected[:, :2].any(axis=1)[None]
    has_range = st.has_range & ~rejected[:, 2][None]
    return dataclasses.replace(st, has_pix=has_pix, has_range=has_range)


def log_likelihood(st: Stacked, X: np.ndarray, sigma: Sigma, vf: tuple[float, float]) -> tuple[float, float, int]:
    """(log L, chi-square r^T C^-1 r, rows m) of one problem at X (3,) under sigma, the pixel and range blocks of
    C scaled by the variance factors vf; C's overall scale k >= 1 at its maximum likelihood, max(chi2 / m, 1)
    (the stated sigmas a lower bound: with sigmas stated too small, a tau is not chosen for hiding the misfit
    in the target)."""
    C = _correlated.problem_covariance(st, X, sigma)
    npix = 2 * int(np.count_nonzero(st.has_pix[0]))
    s = np.r_[np.full(npix, vf[0]), np.full(len(C) - npix, vf[1])]
    C = C * np.sqrt(np.outer(s, s))
    r = _correlated.rows_in_use(st, X)[:, 3]
    L = np.linalg.cholesky(C)
    z = np.linalg.solve(L, r)
    chi2 = float(z @ z)
    m = len(C)
    k = max(chi2 / m, 1.0)
    return -0.5 * (chi2 / k + m * np.log(k) + 2.0 * float(np.log(np.diag(L)).sum())), chi2, m


def learn_tau(st: Stacked, X0: np.ndarray, sigma: Sigma, robust: str | None, vce: bool, tol_m: float,
              max_iterations: int):
    """The GLS `mle` of one problem (B = 1, st without rejected rows) with the correlation time of the largest
    likelihood over TAU_GRID_S, from X0 (3,). Returns (tau_s, {tau: log L}, the `correlated.mle_gls` result
    tuple, chi-square, rows) or None when no tau gave an answer."""
    lls: dict[float, float] = {}
    best = None
    for tau in TAU_GRID_S:
        s = dataclasses.replace(sigma, attitude_tau_s=tau, position_tau_s=tau)
        C = _correlated.problem_covariance(st, X0, s)
        res = _correlated.mle_gls(st, X0, C, robust, vce, tol_m, max_iterations)
        X, status = res[0][0], res[2][0]
        if status in (Status.DIVERGED, Status.DEGENERATE) or not np.isfinite(X).all():
            continue
        vf = (float(res[5]["variance_factor_pixel"][0]), float(res[5]["variance_factor_range"][0]))
        ll, chi2, m = log_likelihood(st, X, s, vf)
        lls[tau] = ll
        if best is None or ll > best[0]:
            best = (ll, tau, res, chi2, m)
    if best is None:
        return None
    _, tau, res, chi2, m = best
    return tau, lls, res, chi2, m


def replace_with_learned(ex: dict, tau: float, lls: dict, chi2: float, m: int) -> dict:
    """The first solve's extras (B = 1 arrays) updated for the learned-tau answer: the fit checks of the GLS
    model (its chi-square; drift is now modelled), no bias, the chosen tau and the likelihoods."""
    out = {k: v for k, v in ex.items() if not k.startswith("bias_")}
    dof = float(m - 3)
    p = fit_checks.chi_square_p(np.array([chi2]), np.array([dof]))
    fail = bool(np.isfinite(p[0]) and p[0] < fit_checks.CHI2_ALPHA)
    out.update({"chi2": np.array([chi2]), "chi2_dof": np.array([dof]), "chi2_p": p,
                "drift_pixel": np.zeros(1, dtype=bool), "drift_range": np.zeros(1, dtype=bool),
                "consistent": np.array([not fail]), "robust_spread": np.ones((1, 2)),
                "covariance_inflation": np.array([max(chi2 / dof, 1.0) if fail and dof > 0 else 1.0]),
                "error_model_tau_s": np.array([tau]),
                "error_model_log_likelihoods": np.array([[lls.get(t, np.nan) for t in TAU_GRID_S]])})
    return out
