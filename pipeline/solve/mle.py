"""Weighted maximum-likelihood estimator (beyond the paper): Gauss-Newton / Levenberg-Marquardt on pixel and
range residuals weighted by each sensor's standard deviation, robust loss by IRLS, optional variance component
estimation, posterior covariance, CEP and error ellipsoid. Batched over B problems.
"""

from __future__ import annotations

import numpy as np
from scipy.special import erf, erfinv

from pipeline.solve import iterate as _iterate
from pipeline.solve.estimate import Status
from pipeline.solve.iterate import problem_scale_m, start_status
from pipeline.solve.observations import Sigma
from pipeline.solve.stacked import SINGULAR_DET, Stacked, condition_numbers, inverse3

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


class _Planes:
    """B problems as contiguous (n,b) planes for the batched kernel: M entries Mc (3,3,n,b), p4c (3,n,b), the
    pixel planes (2,n,b), platform planes sc (3,n,b), ranges (n,b), the masks, and the inverse standard
    deviations isd (3,n,b) of the u, v and range rows (1/sqrt of `base_variances` times the variance factors).
    Numpy is slow on tiny trailing axes; with the problems on the last axis every operation, per-problem
    values (b,) broadcast included, is one contiguous pass over n x b numbers."""

    __slots__ = ("Mc", "has_pix", "has_range", "isd", "p4c", "pixc", "rng", "sc")

    def __init__(self, Mc, p4c, pixc, sc, rng, has_pix, has_range, isd):
        self.Mc, self.p4c, self.pixc, self.sc, self.rng = Mc, p4c, pixc, sc, rng
        self.has_pix, self.has_range, self.isd = has_pix, has_range, isd

    @classmethod
    def from_stacked(cls, st: Stacked, var: np.ndarray) -> _Planes:
        B, n = st.has_pix.shape
        isd = np.empty((3, n, B))
        np.divide(1.0, np.sqrt(var[:, :2 * n].reshape(B, n, 2).transpose(2, 1, 0)), out=isd[:2])
        np.divide(1.0, np.sqrt(var[:, 2 * n:].T), out=isd[2])
        c = np.ascontiguousarray
        return cls(c(st.M.transpose(2, 3, 1, 0)), c(st.p4.transpose(2, 1, 0)), c(st.pix.transpose(2, 1, 0)),
                   c(st.platform_m.transpose(2, 1, 0)), c(st.range_m.T), c(st.has_pix.T), c(st.has_range.T), isd)

    def take(self, idx: np.ndarray) -> _Planes:
        return _Planes(self.Mc[..., idx], self.p4c[..., idx], self.pixc[..., idx], self.sc[..., idx],
                       self.rng[:, idx], self.has_pix[:, idx], self.has_range[:, idx], self.isd[..., idx])


def _evaluate(pl: _Planes, X: np.ndarray):
    """Standardized Jacobian J (3,3,n,b) (J[c, k] = d row / d X_c over the row's sigma, rows k = u, v, range of
    each frame) and residuals E (3,n,b) at X (b,3); unusable rows (missing, q3 = 0, X on a platform) are zero;
    and their mask ok (3,n,b). The arithmetic of `stacked.pixel_model` and `range_model`, on contiguous planes."""
    n, b = pl.has_pix.shape
    J = np.empty((3, 3, n, b))
    E = np.empty((3, n, b))
    ok = np.empty((3, n, b), dtype=bool)
    Mc, isd = pl.Mc, pl.isd
    Xp = X.T[:, None, :]  # (3,1,b): broadcasts over the frames
    q = Mc[:, 0] * Xp[0] + Mc[:, 1] * Xp[1] + Mc[:, 2] * Xp[2] + pl.p4c  # (3,n,b)
    okp = np.logical_and(pl.has_pix, q[2] != 0, out=ok[0])
    ok[1] = okp
    iw = 1.0 / np.where(okp, q[2], np.inf)  # 1/q3, 0 on unusable rows
    uv = q[:2] * iw
    s = iw * isd[:2]
    for c in range(3):  # per coordinate, so that the temporaries stay (2,n,b) planes (in cache)
        np.multiply(Mc[:2, c] - uv * Mc[2, c], s, out=J[c, :2])
    np.multiply(pl.pixc - uv, np.where(okp, isd[:2], 0.0), out=E[:2])
    d = Xp - pl.sc
    dist = np.sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2])
    okr = np.logical_and(pl.has_range, dist > 0, out=ok[2])
    np.multiply(d, isd[2] / np.where(okr, dist, np.inf), out=J[:, 2])
    np.multiply(pl.rng - dist, np.where(okr, isd[2], 0.0), out=E[2])
    return J, E, ok


def _sum_rows(A: np.ndarray) -> np.ndarray:
    """(b,) sums over the rows (k, frame) of (3,n,b) planes."""
    return A.reshape(-1, A.shape[-1]).sum(axis=0)


def _dot_rows(A: np.ndarray, Bm: np.ndarray) -> np.ndarray:
    """(b,) sum over the rows of A * B, (3,n,b) planes."""
    return np.einsum("ij,ij->j", A.reshape(-1, A.shape[-1]), Bm.reshape(-1, Bm.shape[-1]))


def _cost_weights(E: np.ndarray, robust: str | None):
    """sum rho(e) (b,) and the IRLS weights rho'(e)/e (3,n,b) (None for the squared loss) of standardized E."""
    if robust is None:
        return 0.5 * _dot_rows(E, E), None
    if robust == "huber":  # rho = 0.5 w e^2 + 0.5 c (|e| - c)^+ with w = c / max(|e|, c)
        mx = np.maximum(np.abs(E), HUBER_C)
        w = HUBER_C / mx
        return 0.5 * (_dot_rows(w * E, E) + HUBER_C * _sum_rows(mx - HUBER_C)), w
    rho, w = _rho_and_weight(E, robust)
    return _sum_rows(rho), w


def _normal(J: np.ndarray, E: np.ndarray, w, wn=None):
    """The six entries N00 N01 N02 N11 N12 N22 (b,) of J^T diag(wn) J (wn defaults to w; None = 1) and the three
    of g = J^T diag(w) E."""
    b = E.shape[-1]
    WE = E if w is None else w * E
    Jr = J.reshape(3, -1, b)
    g = np.einsum("crb,rb->cb", Jr, WE.reshape(-1, b))
    wn = w if wn is None else wn
    CJ = Jr if wn is None else (J * wn).reshape(3, -1, b)
    N = np.einsum("crb,drb->cdb", CJ, Jr)  # one call: as fast as six row sums on large batches, cheaper on small
    return [N[0, 0], N[0, 1], N[0, 2], N[1, 1], N[1, 2], N[2, 2]], g


def _solve3(N, g, lam=None):
    """Closed-form solution (b,3) of (N + lam diag N) x = g from the six entries, the `stacked.solve_spd`
    singular flag (b,) and the cofactors and determinant (for the inverse)."""
    a, b, c, d, f, i = N
    if lam is not None:
        a, d, i = a + lam * a, d + lam * d, i + lam * i
    A0, B0, C0 = d * i - f * f, c * f - b * i, b * f - c * d
    det = a * A0 + b * B0 + c * C0
    singular = ~((a > 0) & (d > 0) & (i > 0) & (det / (a * d * i) > SINGULAR_DET))
    D0, E0, F0 = a * i - c * c, b * c - a * f, a * d - b * b
    g0, g1, g2 = g
    x = np.stack([(A0 * g0 + B0 * g1 + C0 * g2), (B0 * g0 + D0 * g1 + E0 * g2), (C0 * g0 + E0 * g1 + F0 * g2)],
                 axis=1) / det[:, None]
    return x, singular, (A0, B0, C0, D0, E0, F0), det


def mle(st: Stacked, X0: np.ndarray, sigma: Sigma, robust: str | None, vce: bool, tol_m: float,
        max_iterations: int, init_status: np.ndarray | None = None):
    """Returns X (B,3), iterations (B,), status (B,) int8, cond (B,) of the weighted design W^1/2 J,
    covariance (B,3,3) m^2, and extras {variance_factor_pixel, variance_factor_range, sigma0_sq, vce_rounds}.

    Works on planes (`_Planes`): the normal equations as six (B,) entries, the 3x3 steps in closed form.
    Converged problems are frozen once fewer than all are active.
    """
    B = st.size
    X = np.array(X0, dtype=np.float64, copy=True)
    status, bad = start_status(X, init_status)
    X[bad] = 0.0
    pl = _Planes.from_stacked(st, base_variances(st, X, sigma))
    vf = np.ones((B, 2))  # variance factors of the pixel and range groups
    J, E, ok = _evaluate(pl, X)
    cost, wr = _cost_weights(E, robust)

    iterations = np.zeros(B, dtype=np.int64)
    lam = np.zeros(B)
    newton_ok = np.ones(B, dtype=bool)
    vce_rounds = np.zeros(B, dtype=np.int64)
    centre = st.platform_m.mean(axis=1)
    finite0 = np.isfinite(X0).all(axis=1)
    bound = _iterate.DIVERGENCE_FACTOR * problem_scale_m(st, np.where(finite0[:, None], X0, centre))
    active = ~bad
    for _ in range(max_iterations):
        idx = np.flatnonzero(active)
        if idx.size == 0:
            break
        full = idx.size == B
        Ji, Ei = (J, E) if full else (J[..., idx], E[..., idx])
        wi = wr if (full or wr is None) else wr[..., idx]
        if robust is None:
            N, g = _normal(Ji, Ei, None)
        else:  # Newton: the loss's curvature in the normal matrix, unless it just failed
            curv = _curvature(Ei, robust)
            nok = newton_ok if full else newton_ok[idx]
            N, g = _normal(Ji, Ei, wi, np.where(nok, curv, wi))
        lam_i = lam if full else lam[idx]
        dX, singular, _, _ = _solve3(N, g, lam_i)
        iterations[idx] += 1
        Xi = X if full else X[idx]
        Xn = Xi + np.where(singular[:, None], 0.0, dX)
        finite = np.isfinite(Xn).all(axis=1)
        cen = centre if full else centre[idx]
        exploded = ~finite | (np.sqrt(((Xn - cen) ** 2).sum(axis=1)) > (bound if full else bound[idx]))
        Xn = np.where(exploded[:, None], Xi, Xn)
        Jn, En, okn = _evaluate(pl if full else pl.take(idx), Xn)
        cost_n, wr_n = _cost_weights(En, robust)
        old = cost[idx]
        accept = ~singular & ~exploded & (cost_n <= old * (1 + 1e-12) + 1e-300)
        step_norm = np.where(singular, np.inf, np.sqrt((dX * dX).sum(axis=1)))
        # accept: move and relax damping; reject: stay and damp harder
        a_idx = idx[accept]
        X[a_idx] = Xn[accept]
        if full and a_idx.size == B:  # every problem moved: take the new arrays as they are
            J, E, ok, wr = Jn, En, okn, wr_n
        elif a_idx.size == idx.size:
            J[..., a_idx], E[..., a_idx], ok[..., a_idx] = Jn, En, okn
            if wr is not None:
                wr[..., a_idx] = wr_n
        else:
            J[..., a_idx], E[..., a_idx], ok[..., a_idx] = Jn[..., accept], En[..., accept], okn[..., accept]
            if wr is not None:
                wr[..., a_idx] = wr_n[..., accept]
        cost[a_idx] = cost_n[accept]
        lam[a_idx] = np.where(lam[a_idx] / 10 < 1e-9, 0.0, lam[a_idx] / 10)
        rej = idx[~accept]
        # a rejected Newton step is retried as the IRLS step (a descent step) before damping
        retry = newton_ok[rej] if robust is not None else np.zeros(rej.size, dtype=bool)
        newton_ok[a_idx] = True
        newton_ok[rej[retry]] = False
        rej = rej[~retry]
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
            factors, usable = _vce_factors(J[..., d_idx], E[..., d_idx], ok[..., d_idx], robust)
            more = (np.abs(factors - 1) > VCE_TOL) & usable
            again = more.any(axis=1) & (vce_rounds[d_idx] < VCE_MAX_ROUNDS)
            change = np.where(usable & again[:, None], factors, 1.0)
            vf[d_idx] *= change
            vce_rounds[d_idx] += again
            rd = d_idx[again]
            if rd.size:  # rescale the standardized rows: sigma_g -> sigma_g sqrt(factor_g)
                s = 1.0 / np.sqrt(change[again])
                rows = np.stack([s[:, 0], s[:, 0], s[:, 1]])[:, None, :]  # (3, 1, rd): u, v, range rows
                J[..., rd] *= rows
                E[..., rd] *= rows
                pl.isd[..., rd] *= rows
                cost[rd], w_rd = _cost_weights(E[..., rd], robust)
                if wr is not None:
                    wr[..., rd] = w_rd
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
    N6, _ = _normal(J, E, wr)
    a, b, c, d, f, i = N6
    N = np.stack([a, b, c, b, d, f, c, f, i], axis=1).reshape(B, 3, 3)
    cov, singular = _inverse_spd(N)
    cond = condition_numbers(N)
    bad_cond = singular  # the Jacobi-scaled criterion of the iteration: cond of the scaled design ~> 1e10
    status[bad_cond & ~failed] = Status.DEGENERATE
    failed = (status == Status.DIVERGED) | (status == Status.DEGENERATE)
    X[failed] = np.nan
    cov[failed] = np.nan
    cond[failed & ~bad_cond] = np.nan
    m = _sum_rows(ok)
    WE = E if wr is None else wr * E
    with np.errstate(divide="ignore", invalid="ignore"):
        sigma0_sq = np.where(m > 3, _dot_rows(WE, E) / (m - 3), np.nan)
    extras = {"variance_factor_pixel": vf[:, 0], "variance_factor_range": vf[:, 1], "sigma0_sq": sigma0_sq,
              "vce_rounds": vce_rounds}
    return X, iterations, status, cond, cov, extras


def _inverse_spd(N: np.ndarray):
    inv, singular = inverse3(N)
    return 0.5 * (inv + np.swapaxes(inv, 1, 2)), singular


def _vce_factors(J, E, ok, robust):
    """Helmert/Foerstner variance component factors (b, 2) = (sum_g w e^2) / r_g with the redundancy numbers
    r_g = sum_g (1 - w_i J_i N^-1 J_i^T) over the usable rows of each group (pixels: the u and v rows, ranges),
    from the standardized J (3,3,n,b), E (3,n,b); and a (b, 2) flag 'usable' (redundancy of the group >= 0.5)."""
    _, w = _cost_weights(E, robust)
    N, _ = _normal(J, E, w)
    _, singular, (A0, B0, C0, D0, E0, F0), det = _solve3(N, [N[0]] * 3)
    inv = [np.where(singular, np.nan, x / det) for x in (A0, B0, C0, D0, E0, F0)]
    j0, j1, j2 = J
    quad = (inv[0] * j0 * j0 + inv[3] * j1 * j1 + inv[5] * j2 * j2
            + 2.0 * (inv[1] * j0 * j1 + inv[2] * j0 * j2 + inv[4] * j1 * j2))
    lev = quad if w is None else w * quad
    q = E * E if w is None else w * E * E
    b = E.shape[-1]
    out = np.ones((b, 2))
    usable = np.zeros((b, 2), dtype=bool)
    for g, rows in ((0, slice(0, 2)), (1, slice(2, 3))):
        sel = ok[rows]
        red = _sum_rows(np.where(sel, 1.0 - lev[rows], 0.0))
        qs = _sum_rows(np.where(sel, q[rows], 0.0))
        usable[:, g] = red >= 0.5
        with np.errstate(divide="ignore", invalid="ignore"):
            out[:, g] = np.where(usable[:, g], qs / red, 1.0)
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
