"""The paper's Gauss-Newton estimators, batched over a `Stacked` of B problems from (B,3) starts: vision
(eqs. 9-15), range (16-27), fusion-raw, the min-max normalized fusion (36-41) and ridge (43-47); docs/solvers.md."""

from __future__ import annotations

import numpy as np

from pipeline.solve.estimate import Status
from pipeline.solve.iterate import finish, iterate
from pipeline.solve.stacked import Stacked, normal_equations, pixel_model, range_model, solve_spd

HKB_VARIANTS = ("paper", "textbook")
#: the min-max normalization can scale one block by 1/(max - min) -> huge when that block's residuals are
#: nearly equal, making T ill-conditioned without any geometric cause; its solves are therefore only refused
#: near machine precision, and degeneracy is judged on the geometry, the unnormalized [H; h]
NORMALIZED_SINGULAR_DET = 1e-20


def _gn_step(model):
    def step(sub: Stacked, X: np.ndarray):
        J, r, ok = model(sub, X)
        N, g = normal_equations(J, r, ok.astype(np.float64))
        dX, singular = solve_spd(N, g)
        return dX, singular, {}
    return step


def _fused_model(st: Stacked, X: np.ndarray):
    Jp, rp, okp = pixel_model(st, X)
    Jr, rr, okr = range_model(st, X)
    return (np.concatenate([Jp, Jr], axis=1), np.concatenate([rp, rr], axis=1),
            np.concatenate([okp, okr], axis=1))


def _run(st, X0, model, tol_m, max_iterations, init_status):
    X, it, status, _ = iterate(st, X0, _gn_step(model), tol_m, max_iterations, init_status)
    J, r, ok = model(st, np.where(np.isfinite(X), X, 0.0))
    N, _ = normal_equations(J, r, ok.astype(np.float64))
    cond = finish(X, status, N)
    return X, it, status, cond


def vision(st: Stacked, X0, tol_m, max_iterations, init_status=None):
    """Gauss-Newton on reprojection residuals (the corrected Jacobian of `pixel_model`); cond is that of H (2n x 3)."""
    return _run(st, X0, pixel_model, tol_m, max_iterations, init_status)


def collinear_platforms(platform_m: np.ndarray, used: np.ndarray, sigma_position_m: float | None) -> np.ndarray:
    """(B,) True where the used platform positions (B,n,3) lie on one straight line: exactly (second singular
    value of the centred positions below 1e-9 of the first), or, with a known position sigma, within their noise:
    s2^2 + s3^2 (the squared distances from the best-fitting line) below the 95 % quantile of sigma^2 chi-square
    with 2(k - 2) degrees of freedom (k positions; a line in 3D has 4 parameters)."""
    from scipy.special import chdtri  # = scipy.stats.chi2.ppf(0.95, dof), bit for bit, without its ~40 us wrapper

    w = used.astype(np.float64)
    k = w.sum(axis=1)
    mean = (platform_m * w[..., None]).sum(axis=1) / np.maximum(k, 1.0)[:, None]
    sv = np.linalg.svd((platform_m - mean[:, None, :]) * w[..., None], compute_uv=False)
    sv = np.pad(sv, ((0, 0), (0, 3 - sv.shape[1])))  # one or two positions: always on a line
    flat = sv[:, 1] <= 1e-9 * sv[:, 0]
    if sigma_position_m:
        dof = 2 * (k - 2)
        limit = chdtri(np.maximum(dof, 1), 1.0 - 0.95) * sigma_position_m ** 2
        flat |= (dof > 0) & (sv[:, 1] ** 2 + sv[:, 2] ** 2 < limit)
    return flat


def range_only(st: Stacked, X0, tol_m, max_iterations, init_status=None):
    """Gauss-Newton on laser ranges; cond is that of h (n x 3). Problems with collinear ranged platforms
    (`collinear_platforms`) are DEGENERATE; returns that flag (B,) too."""
    X, it, status, cond = _run(st, X0, range_model, tol_m, max_iterations, init_status)
    flat = collinear_platforms(st.platform_m, st.has_range, st.sigma.position_m)
    status[flat] = Status.DEGENERATE
    X[flat] = np.nan
    return X, it, status, cond, flat


def fusion_raw(st: Stacked, X0, tol_m, max_iterations, init_status=None):
    """Gauss-Newton on [pixels; ranges] with the design [H; h], unweighted (pixels in px, ranges in m)."""
    return _run(st, X0, _fused_model, tol_m, max_iterations, init_status)


def _minmax(r: np.ndarray, ok: np.ndarray):
    """Per problem Min and the divisor Max - Min over the rows in use; a divisor of 0 or no rows becomes 1 (the
    block is only shifted, not scaled)."""
    hi = np.max(np.where(ok, r, -np.inf), axis=1)
    lo = np.min(np.where(ok, r, np.inf), axis=1)
    span = hi - lo
    good = np.isfinite(span) & (span > 0)
    lo = np.where(np.isfinite(lo), lo, 0.0)
    return lo, np.where(good, span, 1.0)


def normalized_normal_equations(st: Stacked, X: np.ndarray):
    """N = T^T T (B,4,4), g = T^T dPhi (B,4), dd = dPhi^T dPhi (B,) and the rows in use (B,) of eqs. (36)-(38) at X,
    without forming T (tests/support/references.py forms it, as the paper writes it): a block's rows of T are
    [J, -L]/S and of dPhi (r - L)/S, so each block contributes through the Gram matrix of [J | r | 1] over its rows
    (L = Min or min, S = Max - Min or max - min)."""
    Jp, rp, okp = pixel_model(st, X)
    Jr, rr, okr = range_model(st, X)
    B = X.shape[0]
    N = np.zeros((B, 4, 4))
    g = np.zeros((B, 4))
    dd = np.zeros(B)
    for J, r, ok in ((Jp, rp, okp), (Jr, rr, okr)):
        L, S = _minmax(r, ok)
        A = np.concatenate([J, r[..., None], ok[..., None].astype(np.float64)], axis=2)  # (B,m,5)
        G = np.swapaxes(A, 1, 2) @ A
        s2 = 1.0 / (S * S)
        J1, cnt, r1 = G[:, :3, 4], G[:, 4, 4], G[:, 3, 4]
        N[:, :3, :3] += G[:, :3, :3] * s2[:, None, None]
        col = -L[:, None] * J1 * s2[:, None]
        N[:, :3, 3] += col
        N[:, 3, :3] += col
        N[:, 3, 3] += L * L * cnt * s2
        g[:, :3] += (G[:, :3, 3] - L[:, None] * J1) * s2[:, None]
        g[:, 3] += -L * (r1 - L * cnt) * s2
        dd += (G[:, 3, 3] - 2 * L * r1 + L * L * cnt) * s2
    return N, g, dd, okp.sum(axis=1) + okr.sum(axis=1)


def hkb_k(N, g, dd, rows, variant: str = "paper"):
    """Hoerl-Kennard-Baldwin ridge parameter (B,) of T beta = dPhi from N = T^T T, g = T^T dPhi, dd = dPhi^T dPhi and
    the rows in use: variant "paper" (eqs. 44-45 as read in docs/solvers.md, ridge) or "textbook" (on the
    column-standardized system; k then applies to the standardized normal matrix)."""
    p = N.shape[-1]
    if variant == "textbook":
        d = _column_scales(N)
        N = N / (d[:, :, None] * d[:, None, :])
        g = g / d
    beta, singular = solve_spd(N, g)
    rss = np.maximum(dd - np.einsum("bi,bi->b", g, beta), 0.0)
    dof = rows - p
    s2 = np.where(dof > 0, rss / np.where(dof > 0, dof, 1), 0.0)
    if variant == "textbook":
        denom = np.einsum("bi,bi->b", beta, beta)
    else:
        denom = np.einsum("bi,bij,bj->b", beta, N, beta)
    with np.errstate(divide="ignore", invalid="ignore"):
        k = p * s2 / denom
    return np.where(np.isfinite(k) & ~singular, k, 0.0)


def _column_scales(N):
    """(B,4) the lengths of T's columns from N = T^T T (1 where zero): the textbook variant's standardization."""
    d = np.sqrt(np.einsum("bii->bi", N))
    return np.where(d > 0, d, 1.0)


def _solve_augmented(N, g, k):
    """beta = (N + k I)^-1 g for [dX; a]; where that is singular but the 3 dX columns are not (the 4th column of T
    vanishes at an exact fit, Max = Min = 0), a is held at the paper's 1: dX = (N33 + k I)^-1 (g3 - N[:3, 3])."""
    beta, singular = solve_spd(N + k[:, None, None] * np.eye(4), g, NORMALIZED_SINGULAR_DET)
    if singular.any():
        i = np.flatnonzero(singular)
        dX, sing3 = solve_spd(N[i, :3, :3] + k[i, None, None] * np.eye(3), g[i, :3] - N[i, :3, 3],
                              NORMALIZED_SINGULAR_DET)
        beta[i, :3] = dX
        beta[i, 3] = 1.0
        singular[i] = sing3
    return beta, singular


def _normalized_step(k_fixed: float | None, hkb: str | None):
    def step(sub: Stacked, X: np.ndarray):
        N, g, dd, rows = normalized_normal_equations(sub, X)
        if hkb is None:
            k = np.zeros(N.shape[0]) if k_fixed is None else np.full(N.shape[0], float(k_fixed))
        else:
            k = hkb_k(N, g, dd, rows, hkb)
        if hkb == "textbook":  # solved in standardized columns, as its k was chosen
            d = _column_scales(N)
            gamma, singular = _solve_augmented(N / (d[:, :, None] * d[:, None, :]), g / d, k)
            beta = gamma / d
        else:
            beta, singular = _solve_augmented(N, g, k)
        return beta[:, :3], singular, {"k": k, "augmented": beta[:, 3]}
    return step


def normalized_fusion(st: Stacked, X0, tol_m, max_iterations, init_status=None, k: float | None = None,
                      hkb: str | None = None):
    """The paper's normalized fusion (k = None, hkb = None) or ridge fusion (hkb "paper" or "textbook", or a fixed
    k): T [dX; a] = dPhi, X updated by dX only. Returns X, iterations, status, cond (of T at the final iterate) and
    the last iteration's extras {k, augmented}; degeneracy is judged on the unnormalized [H; h]."""
    X, it, status, extras = iterate(st, X0, _normalized_step(k, hkb), tol_m, max_iterations, init_status,
                                    extra_names=("k", "augmented"))
    Xf = np.where(np.isfinite(X), X, 0.0)
    N, _, _, _ = normalized_normal_equations(st, Xf)
    J, r, ok = _fused_model(st, Xf)
    Ng, _ = normal_equations(J, r, ok.astype(np.float64))
    cond = finish(X, status, N, Ng)
    return X, it, status, cond, extras
