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
by it get an inflated independent variance C_ii / w_i before the whitening (`inflated_whitening`).

`mle_gls` is the estimator itself, for one problem (a batch has no timestamps): `solve("mle", obs)` calls it when
the sigma has correlation times and the frames' covariance is not diagonal; otherwise the batched `mle.mle`.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.linalg.lapack import dpotrf, dtrtrs

from pipeline.solve.estimate import Status
from pipeline.solve.iterate import DIVERGENCE_FACTOR, problem_scale_m
from pipeline.solve.mle import VCE_MAX_ROUNDS, VCE_TOL, _rho_and_weight, pixel_pair_redescending
from pipeline.solve.observations import Sigma
from pipeline.solve.stacked import Stacked, condition_numbers, inverse3, pixel_model, range_model, solve_spd


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


# ---- the estimator (one problem) ----------------------------------------------------------------------------

def rows_in_use(st: Stacked, X: np.ndarray) -> np.ndarray:
    """[J | r] (m,4) at X (3,) of one problem (B = 1): the u and v rows of the frames with a pixel (interleaved),
    then the rows of the frames with a range; r observed - predicted (px, m)."""
    Jp, rp, _ = pixel_model(st, X[None])
    Jr, rr, _ = range_model(st, X[None])
    pix = np.repeat(st.has_pix[0], 2)
    rng = st.has_range[0]
    return np.concatenate([np.concatenate([Jp[0, pix], rp[0, pix, None]], axis=1),
                           np.concatenate([Jr[0, rng], rr[0, rng, None]], axis=1)])


def problem_covariance(st: Stacked, X0: np.ndarray, sigma: Sigma) -> np.ndarray:
    """`full_covariance` (m,m) of one problem's rows in use (`rows_in_use`), with the focal lengths, the
    distances at X0 (3,) and the frames' times in seconds."""
    t_ns = st.t_ns[0]
    t_s = (t_ns - t_ns.min()).astype(np.float64) * 1e-9  # differences of int64 first: no rounding of epochs
    hp, hr = st.has_pix[0], st.has_range[0]
    fx, fy = st.focal_px()
    diff = X0 - st.platform_m[0, hp]
    D = np.sqrt((diff * diff).sum(axis=1))
    return full_covariance(t_s[hp], t_s[hr], fx[0, hp], fy[0, hp], D, sigma)


def mle_gls(st: Stacked, X0: np.ndarray, C: np.ndarray, robust: str | None, vce: bool, tol_m: float,
            max_iterations: int):
    """Generalized least squares `mle` of one problem (B = 1) from a usable start X0 (3,) with the residual
    covariance C (m,m) of `problem_covariance`, by iteratively reweighted least squares.

    Every iteration takes the robust weights w_i = rho'(z)/z (all 1 without a robust loss) of the rows' marginal
    standardized residuals z_i = r_i / sqrt(C_ii) (C_ii times the variance factor of the row's group) at the
    current estimate, applies them as inflated variances C_ii / w_i of an independent gross error
    (`inflated_whiten`), and takes the Gauss-Newton step of the whitened problem. Stops when the step is below
    tol_m (then, with variance components, re-estimates them and continues while they change). Weights on the
    whitened residuals instead would mix a gross error of one frame into the rows of the next frames and let it
    drag the estimate.

    Returns, shaped as `mle.mle` for B = 1: X (1,3), iterations (1,), status (1,) int8, cond (1,),
    covariance (1,3,3) and the extras {variance_factor_pixel, variance_factor_range, sigma0_sq, vce_rounds}.
    """
    npix, m = 2 * int(np.count_nonzero(st.has_pix[0])), len(C)
    sd = np.sqrt(np.diag(C))
    bound = DIVERGENCE_FACTOR * problem_scale_m(st, X0[None])[0]
    centre = st.platform_m[0].mean(axis=0)
    vf = np.ones(2)

    def whitened(A):
        scale = np.r_[np.full(npix, vf[0]), np.full(m - npix, vf[1])]
        z = A[:, 3] / (sd * np.sqrt(scale))
        w = np.ones(m) if robust is None else _rho_and_weight(z, robust)[1]
        if robust == "redescending":  # the pixel rows (u, v interleaved) weighted in pairs
            w[:npix] = np.repeat(pixel_pair_redescending(z[:npix:2], z[1:npix:2])[1], 2)
        return inflated_whiten(C, w, A) / np.sqrt(scale)[:, None]

    X = np.array(X0, dtype=np.float64)
    A = rows_in_use(st, X)
    status = Status.MAX_ITERATIONS
    it = vce_rounds = 0
    for _ in range(max_iterations):
        G = (Aw := whitened(A)).T @ Aw
        dX, singular = solve_spd(G[None, :3, :3], G[None, :3, 3])
        dX = dX[0]
        it += 1
        if singular[0]:
            status = Status.DEGENERATE
            break
        Xn = X + dX
        if not np.isfinite(Xn).all() or np.linalg.norm(Xn - centre) > bound:
            status = Status.DIVERGED
            break
        X = Xn
        A = rows_in_use(st, X)
        if np.linalg.norm(dX) <= tol_m:
            if vce and vce_rounds < VCE_MAX_ROUNDS:
                Aw = whitened(A)
                factors, usable = _vce_factors(Aw[:, :3], Aw[:, 3], npix)
                if (usable & (np.abs(factors - 1) > VCE_TOL)).any():
                    vf = np.where(usable, vf * factors, vf)
                    vce_rounds += 1
                    continue
            status = Status.CONVERGED
            break
    # covariance with the weights at the final estimate
    Aw = whitened(A)
    N = Aw[None, :, :3].transpose(0, 2, 1) @ Aw[None, :, :3]
    cov, singular = inverse3(N)
    cond = condition_numbers(N)
    if singular[0] and status not in (Status.DIVERGED, Status.DEGENERATE):
        status = Status.DEGENERATE
    if status in (Status.DIVERGED, Status.DEGENERATE):
        X = np.full(3, np.nan)
        cov[:] = np.nan
        if not singular[0]:
            cond[:] = np.nan
    e = Aw[:, 3]
    extras = {"variance_factor_pixel": vf[:1], "variance_factor_range": vf[1:],
              "sigma0_sq": np.array([float(e @ e) / (m - 3) if m > 3 else np.nan]),
              "vce_rounds": np.array([vce_rounds])}
    return (X[None], np.array([it]), np.array([status], dtype=np.int8), cond, cov, extras)


def _vce_factors(Jw: np.ndarray, e: np.ndarray, npix: int):
    """Helmert/Foerstner variance factors (2,) of the pixel and range groups of whitened rows Jw (m,3),
    e (m,) (the first npix are pixel rows), and which of them are usable (redundancy >= 0.5), as
    `mle._vce_factors`."""
    Ninv = inverse3((Jw.T @ Jw)[None])[0][0]
    lev = ((Jw @ Ninv) * Jw).sum(axis=1)
    out, usable = np.ones(2), np.zeros(2, dtype=bool)
    for k, sl in ((0, slice(0, npix)), (1, slice(npix, None))):
        red = float((1.0 - lev[sl]).sum())
        if red >= 0.5:
            f = float((e[sl] * e[sl]).sum()) / red
            if np.isfinite(f) and f > 0:
                out[k], usable[k] = f, True
    return out, usable
