"""Weighted maximum-likelihood estimator (beyond the paper): Gauss-Newton / Levenberg-Marquardt on pixel and
range residuals weighted by each sensor's standard deviation, robust loss by IRLS, optional variance component
estimation, posterior covariance, CEP and error ellipsoid. Batched over B problems.
"""

from __future__ import annotations

import numpy as np
from scipy.special import erf, erfinv

from pipeline.solve import iterate as _iterate
from pipeline.solve.estimate import Status
from pipeline.solve.iterate import problem_scale_m
from pipeline.solve.observations import Sigma
from pipeline.solve.stacked import (
    Stacked,
    condition_numbers,
    inverse3,
    normal_equations,
    pixel_model,
    range_model,
    solve_spd,
)

ROBUST_LOSSES = (None, "huber", "cauchy")
#: tuning constants in units of the standardized residual (95 % efficiency under Gaussian noise)
HUBER_C = 1.345
CAUCHY_C = 2.3849
#: 95 % quantile of chi-square with 3 degrees of freedom, for the 95 % ellipsoid
CHI2_3_95 = 7.814727903251178
VCE_MAX_ROUNDS = 10
VCE_TOL = 0.01


def _curvature(e: np.ndarray, robust: str) -> np.ndarray:
    """Newton weights of the normal matrix: rho''(e) (0 beyond Huber's c, negative beyond Cauchy's c), floored
    at a thousandth of the IRLS weight rho'(e)/e so that the normal matrix stays regular when most residuals are
    large (a far start)."""
    if robust == "huber":
        a = np.abs(e)
        return np.where(a <= HUBER_C, 1.0, 0.001 * HUBER_C / np.where(a <= HUBER_C, 1.0, a))
    z = (e / CAUCHY_C) ** 2
    w = 1.0 / (1.0 + z)
    return np.maximum((1.0 - z) * w * w, 0.001 * w)


def _rho_and_weight(e: np.ndarray, robust: str | None):
    """Loss rho(e) and IRLS weight rho'(e)/e of standardized residuals e."""
    if robust is None:
        return 0.5 * e * e, np.ones_like(e)
    if robust == "huber":
        a = np.abs(e)
        t = np.maximum(a - HUBER_C, 0.0)  # rho = e^2/2 inside, c|e| - c^2/2 = e^2/2 - (|e| - c)^2/2 outside
        return 0.5 * (e * e - t * t), np.minimum(1.0, HUBER_C / np.maximum(a, 1e-300))
    z = (e / CAUCHY_C) ** 2
    return 0.5 * CAUCHY_C ** 2 * np.log1p(z), 1.0 / (1.0 + z)


def base_variances(st: Stacked, X0: np.ndarray, sigma: Sigma):
    """A priori variances (B, 2n+n) of the residual rows [u_1, v_1, ..., d_1, ...], from the sensor sigmas.

    pixel: sigma_px^2 + (f sigma_att)^2 + (f sigma_pos / D)^2, f the focal length of that axis (`focal_px`),
    D the platform-to-target distance at the initial estimate (the camera's lever arm is negligible at this
    scale): an attitude error turns the line of sight by
    sigma_att (f sigma_att px), a platform position error moves it sideways by sigma_pos/D radians.
    range: sigma_range^2 + sigma_pos^2, the position error's component along the line of sight.
    Unknown sigmas: pixel 1 px, range 1 m, position and attitude 0 (variance component estimation then
    scales the pixel and range groups).
    """
    s_px = 1.0 if sigma.pixel_px is None else sigma.pixel_px
    s_r = 1.0 if sigma.range_m is None else sigma.range_m
    s_pos = 0.0 if sigma.position_m is None else sigma.position_m
    s_att = 0.0 if sigma.attitude_deg is None else np.deg2rad(sigma.attitude_deg)
    fx, fy = st.focal_px()
    B, n = fx.shape
    if s_pos > 0:
        diff = X0[:, None, :] - st.platform_m
        D = np.sqrt(np.einsum("bni,bni->bn", diff, diff))
        D = np.where(np.isfinite(D) & (D > 0), D, np.inf)
        pos_rad2 = (s_pos / D) ** 2
    else:
        pos_rad2 = 0.0
    var_u = s_px ** 2 + fx ** 2 * (s_att ** 2 + pos_rad2)
    var_v = s_px ** 2 + fy ** 2 * (s_att ** 2 + pos_rad2)
    var_pix = np.stack([var_u, var_v], axis=-1).reshape(B, 2 * n)
    var_rng = np.full((B, n), s_r ** 2 + s_pos ** 2)
    var = np.concatenate([var_pix, var_rng], axis=1)
    var = np.where(var > 0, var, 1.0)  # all sigmas zero: unit weights
    return var


def _model(st: Stacked, X: np.ndarray):
    Jp, rp, okp = pixel_model(st, X)
    Jr, rr, okr = range_model(st, X)
    return (np.concatenate([Jp, Jr], axis=1), np.concatenate([rp, rr], axis=1),
            np.concatenate([okp, okr], axis=1))


def mle(st: Stacked, X0: np.ndarray, sigma: Sigma, robust: str | None, vce: bool, tol_m: float,
        max_iterations: int, init_status: np.ndarray | None = None):
    """Returns X (B,3), iterations (B,), status (B,) int8, cond (B,) of the weighted design W^1/2 J,
    covariance (B,3,3) m^2, and extras {variance_factor_pixel, variance_factor_range, sigma0_sq, vce_rounds}.
    """
    B = st.size
    npix = 2 * st.n
    X = np.array(X0, dtype=np.float64, copy=True)
    finite0 = np.isfinite(X).all(axis=1)
    status = np.full(B, Status.MAX_ITERATIONS, dtype=np.int8)
    if init_status is not None:
        bad = np.isin(init_status, (Status.DIVERGED, Status.DEGENERATE)) | ~finite0
        status[bad] = np.where(init_status[bad] == Status.DIVERGED, Status.DIVERGED, Status.DEGENERATE)
    else:
        bad = ~finite0
        status[bad] = Status.DEGENERATE
    X[bad] = 0.0
    var0 = base_variances(st, X, sigma)
    group = np.zeros(var0.shape[1], dtype=np.int64)
    group[npix:] = 1
    vf = np.ones((B, 2))  # variance factors of the pixel and range groups
    J, r, ok = _model(st, X)
    okf = ok.astype(np.float64)

    iterations = np.zeros(B, dtype=np.int64)
    lam = np.zeros(B)
    newton_ok = np.ones(B, dtype=bool)
    vce_rounds = np.zeros(B, dtype=np.int64)
    centre = st.platform_m.mean(axis=1)
    bound = _iterate.DIVERGENCE_FACTOR * problem_scale_m(st, np.where(finite0[:, None], X0, centre))

    def costs(var, vfac, rr, okk):
        e = rr / np.sqrt(var * vfac[:, group])
        rho, w = _rho_and_weight(e, robust)
        return (rho * okk).sum(axis=1), w

    cost, _ = costs(var0, vf, r, okf)
    active = ~bad
    for _ in range(max_iterations):
        idx = np.flatnonzero(active)
        if idx.size == 0:
            break
        sub = st if idx.size == B else st.take(idx)
        var_i = var0[idx] * vf[idx][:, group]
        e = r[idx] / np.sqrt(var_i)
        _, wr = _rho_and_weight(e, robust)
        w = okf[idx] / var_i
        N, g = normal_equations(J[idx], r[idx], w * wr)
        if robust is not None:  # Newton: the loss's curvature in the normal matrix, unless it just failed
            Nh, _ = normal_equations(J[idx], r[idx], w * _curvature(e, robust))
            N = np.where(newton_ok[idx][:, None, None], Nh, N)
        lam_i = lam[idx]
        Nd = N + lam_i[:, None, None] * (np.einsum("bii->bi", N)[:, :, None] * np.eye(3))
        dX, singular = solve_spd(Nd, g)
        iterations[idx] += 1
        Xn = X[idx] + np.where(singular[:, None], 0.0, dX)
        finite = np.isfinite(Xn).all(axis=1)
        exploded = ~finite | (np.linalg.norm(Xn - centre[idx], axis=1) > bound[idx])
        Xn = np.where(exploded[:, None], X[idx], Xn)
        Jn, rn, okn = _model(sub, Xn)
        okn = okn.astype(np.float64)
        cost_n, _ = costs(var0[idx], vf[idx], rn, okn)
        old = cost[idx]
        accept = ~singular & ~exploded & (cost_n <= old * (1 + 1e-12) + 1e-300)
        step_norm = np.where(singular, np.inf, np.linalg.norm(dX, axis=1))
        # accept: move and relax damping; reject: stay and damp harder
        a_idx = idx[accept]
        X[a_idx] = Xn[accept]
        J[a_idx], r[a_idx], okf[a_idx] = Jn[accept], rn[accept], okn[accept]
        cost[a_idx] = cost_n[accept]
        lam[a_idx] = np.where(lam[a_idx] / 10 < 1e-9, 0.0, lam[a_idx] / 10)
        rej = idx[~accept]
        # a rejected Newton step is retried as the IRLS step (a descent step) before damping
        fallback = rej[newton_ok[rej]] if robust is not None else rej[:0]
        newton_ok[idx[accept]] = True
        newton_ok[fallback] = False
        rej = rej[~np.isin(rej, fallback)]
        lam[rej] = np.where(lam[rej] == 0, 1e-4, lam[rej] * 10)
        small = step_norm <= tol_m
        inner_done = small & ~singular & ~exploded
        st_idx = status[idx]
        st_idx[singular & ~small] = Status.DEGENERATE
        st_idx[exploded & ~singular] = Status.DIVERGED
        still = ~(singular & ~small) & ~(exploded & ~singular) & ~inner_done
        # damping that cannot help any more: the minimum along every direction is reached
        stuck = ~accept & (lam[idx] > 1e12)
        inner_done |= stuck & still
        still &= ~stuck
        if vce and inner_done.any():
            d_idx = idx[inner_done]
            factors, usable = _vce_factors(st.take(d_idx), J[d_idx], r[d_idx], okf[d_idx], var0[d_idx] *
                                           vf[d_idx][:, group], group, robust)
            more = (np.abs(factors - 1) > VCE_TOL) & usable
            again = more.any(axis=1) & (vce_rounds[d_idx] < VCE_MAX_ROUNDS)
            vf[d_idx] = np.where(usable & again[:, None], vf[d_idx] * factors, vf[d_idx])
            vce_rounds[d_idx] += again
            rd = d_idx[again]
            if rd.size:
                cost[rd], _ = costs(var0[rd], vf[rd], r[rd], okf[rd])
                lam[rd] = 0.0
            keep = np.zeros(idx.size, dtype=bool)
            keep[np.flatnonzero(inner_done)[again]] = True
            inner_done &= ~keep
            still |= keep
        st_idx[inner_done] = Status.CONVERGED
        status[idx] = st_idx
        active[idx] = still
    failed = (status == Status.DIVERGED) | (status == Status.DEGENERATE)
    # covariance and condition number at the final iterate with the final weights
    var_f = var0 * vf[:, group]
    e = r / np.sqrt(var_f)
    _, wr = _rho_and_weight(e, robust)
    w = okf * wr / var_f
    N, _ = normal_equations(J, r, w)
    cov, singular = _inverse_spd(N)
    cond = condition_numbers(N)
    bad_cond = singular  # the Jacobi-scaled criterion of the iteration: cond of the scaled design ~> 1e10
    status[bad_cond & ~failed] = Status.DEGENERATE
    failed = (status == Status.DIVERGED) | (status == Status.DEGENERATE)
    X[failed] = np.nan
    cov[failed] = np.nan
    cond[failed & ~bad_cond] = np.nan
    m = okf.sum(axis=1)
    with np.errstate(divide="ignore", invalid="ignore"):
        sigma0_sq = np.where(m > 3, (w * r * r).sum(axis=1) / (m - 3), np.nan)
    extras = {"variance_factor_pixel": vf[:, 0], "variance_factor_range": vf[:, 1], "sigma0_sq": sigma0_sq,
              "vce_rounds": vce_rounds}
    return X, iterations, status, cond, cov, extras


def _inverse_spd(N: np.ndarray):
    inv, singular = inverse3(N)
    return 0.5 * (inv + np.swapaxes(inv, 1, 2)), singular


def _vce_factors(st: Stacked, J, r, okf, var, group, robust):
    """Helmert/Foerstner variance component factors (b, 2) = (sum_g w r^2) / r_g with the redundancy numbers
    r_g = sum_g (1 - w_i J_i N^-1 J_i^T), and a (b, 2) flag 'usable' (redundancy of the group >= 0.5)."""
    e = r / np.sqrt(var)
    _, wr = _rho_and_weight(e, robust)
    w = okf * wr / var
    N, _ = normal_equations(J, r, w)
    Ninv, _ = _inverse_spd(N)
    lev = w * np.einsum("bmi,bij,bmj->bm", J, Ninv, J)
    out = np.ones((J.shape[0], 2))
    usable = np.zeros((J.shape[0], 2), dtype=bool)
    for g in (0, 1):
        sel = (group == g)[None, :] & (okf > 0)
        red = np.where(sel, 1.0 - lev, 0.0).sum(axis=1)
        q = np.where(sel, w * r * r, 0.0).sum(axis=1)
        usable[:, g] = red >= 0.5
        with np.errstate(divide="ignore", invalid="ignore"):
            out[:, g] = np.where(usable[:, g], q / red, 1.0)
        usable[:, g] &= np.isfinite(out[:, g]) & (out[:, g] > 0)
        out[:, g] = np.where(usable[:, g], out[:, g], 1.0)
    return out, usable


# ---- accuracy summaries from the covariance ----------------------------------------------------------------

_Q_GRID = np.linspace(0.0, 1.0, 257)
_GL_X, _GL_W = np.polynomial.legendre.leggauss(64)
_GL_T = 0.5 * np.pi * _GL_X
_CEP_TABLES: dict[float, np.ndarray] = {}


def _prob_within(rho: np.ndarray, q: np.ndarray) -> np.ndarray:
    """P(|e| <= rho) for e ~ N(0, diag(1, q^2)), elementwise over rho, q (q <= 1).

    Conditioning on the major component z1 = rho sin t: P = int_{-pi/2}^{pi/2} phi(rho sin t)
    erf(rho cos t / (sqrt(2) q)) rho cos t dt, by 64-point Gauss-Legendre (smooth integrand; the steep erf at
    the ends is damped by cos t).
    """
    t, w = _GL_T, _GL_W
    rho = rho[:, None]
    qq = np.maximum(q, 1e-12)[:, None]
    z1 = rho * np.sin(t)
    f = np.exp(-0.5 * z1 * z1) / np.sqrt(2 * np.pi) * erf(rho * np.cos(t) / (np.sqrt(2) * qq)) * rho * np.cos(t)
    return 0.5 * np.pi * (f * w).sum(axis=1)


def _cep_table(p: float) -> np.ndarray:
    """rho_p(q) on _Q_GRID: the radius, in units of the major standard deviation, holding probability p."""
    table = _CEP_TABLES.get(p)
    if table is None:
        lo = np.full(_Q_GRID.shape, np.sqrt(2.0) * erfinv(p))  # the 1-D quantile: q = 0
        hi = np.full(_Q_GRID.shape, np.sqrt(-2.0 * np.log1p(-p)))  # the circular one: q = 1
        lo, hi = lo * (1 - 1e-9), hi * (1 + 1e-9)
        for _ in range(44):  # the bracket is within a factor 2.3: 2^-44 relative
            mid = 0.5 * (lo + hi)
            below = _prob_within(mid, _Q_GRID) < p
            lo, hi = np.where(below, mid, lo), np.where(below, hi, mid)
        table = _CEP_TABLES[p] = 0.5 * (lo + hi)
    return table


def cep_m(cov_xy: np.ndarray, p: float) -> np.ndarray:
    """(B,) radius of the circle around the estimate that holds probability p of the horizontal error, for
    (B,2,2) covariances of a zero-mean 2D Gaussian.

    With principal standard deviations s1 >= s2 (closed-form 2x2 eigenvalues) the radius is s1 rho_p(s2/s1);
    rho_p is tabulated once per p on 257 ratios (exact integral `_prob_within`, bisection) and interpolated
    linearly (relative error < 1e-5 against a 1025-point table).
    """
    a, b, c = cov_xy[:, 0, 0], cov_xy[:, 0, 1], cov_xy[:, 1, 1]
    mean = 0.5 * (a + c)
    half = np.sqrt(0.25 * (a - c) ** 2 + b * b)
    s1 = np.sqrt(np.maximum(mean + half, 0.0))
    s2 = np.sqrt(np.maximum(mean - half, 0.0))
    ok = np.isfinite(s1) & (s1 > 0)
    q = np.where(ok, s2 / np.where(ok, s1, 1.0), 1.0)
    return np.where(ok, s1 * np.interp(q, _Q_GRID, _cep_table(float(p))), np.nan)


def ellipsoid(cov: np.ndarray):
    """(B,3) 1-sigma semi-axes (m, ascending), (B,3,3) axes as columns, from (B,3,3) covariances;
    the 95 % semi-axes are sqrt(CHI2_3_95) times the 1-sigma ones."""
    good = np.isfinite(cov).all(axis=(1, 2))
    safe = np.where(good[:, None, None], cov, np.eye(3))
    ev, vec = np.linalg.eigh(safe)
    axes = np.sqrt(np.maximum(ev, 0.0))
    axes[~good] = np.nan
    vec[~good] = np.nan
    return axes, vec
