"""The `mle` iteration for one problem, written without the batch bookkeeping (masks, index sets, frozen
problems) so that a single solve costs a few dozen small numpy calls per iteration.

It is the same algorithm as `mle.mle` step by step (same start, weights, damping, acceptance, variance
components, stopping rules and final quantities); tests check that both give the same numbers.
"""

from __future__ import annotations

import math

import numpy as np

from pipeline.solve import iterate as _iterate
from pipeline.solve.estimate import Status
from pipeline.solve.mle import VCE_MAX_ROUNDS, VCE_TOL, _rho_and_weight, base_variances
from pipeline.solve.observations import Sigma
from pipeline.solve.stacked import Stacked


def _solve3(N: np.ndarray, g: np.ndarray):
    """(x, singular) for a symmetric 3x3 N, with the criterion of `stacked.solve_spd` (Jacobi-scaled det)."""
    (a, b, c), (_, e, f), (_, _, i) = N.tolist()
    if not (a > 0 and e > 0 and i > 0) or not all(map(math.isfinite, (a, b, c, e, f, i))):
        return None, True
    A = e * i - f * f
    Bc = c * f - b * i
    C = b * f - c * e
    det = a * A + b * Bc + c * C
    if not det / (a * e * i) > 1e-20:
        return None, True
    g0, g1, g2 = g.tolist()
    E = a * i - c * c
    F = b * c - a * f
    I = a * e - b * b
    return np.array([(A * g0 + Bc * g1 + C * g2) / det, (Bc * g0 + E * g1 + F * g2) / det,
                     (C * g0 + F * g1 + I * g2) / det]), False


def _inv3(N: np.ndarray):
    (a, b, c), (_, e, f), (_, _, i) = N.tolist()
    A, Bc, C = e * i - f * f, c * f - b * i, b * f - c * e
    det = a * A + b * Bc + c * C
    if not (a > 0 and e > 0 and i > 0) or not det / (a * e * i) > 1e-20:
        return np.full((3, 3), np.nan), True
    E, F, I = a * i - c * c, b * c - a * f, a * e - b * b
    return np.array([[A, Bc, C], [Bc, E, F], [C, F, I]]) / det, False


def mle_one(st: Stacked, X0: np.ndarray, sigma: Sigma, robust: str | None, vce: bool, tol_m: float,
            max_iterations: int, init_status: int | None):
    """One problem (st of size 1). Returns X (3,), iterations, status, cond, covariance (3,3), extras dict of
    floats (the keys of `mle.mle`) and the final residuals (pixels u v interleaved, then ranges)."""
    pix_f = np.flatnonzero(st.has_pix[0])
    rng_f = np.flatnonzero(st.has_range[0])
    Mp = st.M[0, pix_f]
    M12, M3 = Mp[:, :2, :], Mp[:, 2:3, :]
    p4 = st.p4[0, pix_f]
    pix = st.pix[0, pix_f]
    S = st.platform_m[0, rng_f]
    d = st.range_m[0, rng_f]
    npix = 2 * pix_f.size

    def model(X):
        q = Mp @ X + p4
        w = q[:, 2:3]
        uv = q[:, :2] / w
        Jp = (M12 - uv[..., None] * M3) / w[..., None]
        diff = X - S
        dist = np.sqrt(np.einsum("ij,ij->i", diff, diff))
        return (np.concatenate((Jp.reshape(-1, 3), diff / dist[:, None])),
                np.concatenate(((pix - uv).ravel(), d - dist)))

    status = Status.MAX_ITERATIONS
    X = np.array(X0, dtype=np.float64)
    bad = (init_status is not None and init_status in (Status.DIVERGED, Status.DEGENERATE)) or \
        not np.isfinite(X).all()
    if bad:
        status = Status.DIVERGED if init_status == Status.DIVERGED else Status.DEGENERATE
        X = np.zeros(3)
    var_all = base_variances(st, X[None], sigma)[0]
    var0 = np.concatenate((var_all[:2 * st.n].reshape(-1, 2)[pix_f].ravel(), var_all[2 * st.n:][rng_f]))
    vf = [1.0, 1.0]
    m = var0.size

    def var_of(vf):
        v = var0.copy()
        v[:npix] *= vf[0]
        v[npix:] *= vf[1]
        return v

    var = var_of(vf)
    J, r = model(X)
    centre = st.platform_m[0].mean(axis=0)
    scale = np.linalg.norm(np.asarray(X0 if not bad else centre) - st.platform_m[0], axis=1).max()
    bound = _iterate.DIVERGENCE_FACTOR * (max(scale, 1.0) if np.isfinite(scale) else 1.0)
    rho, _ = _rho_and_weight(r / np.sqrt(var), robust)
    cost = rho.sum()
    iterations = 0
    lam = 0.0
    vce_rounds = 0
    active = not bad
    for _ in range(max_iterations if active else 0):
        e = r / np.sqrt(var)
        _, wr = _rho_and_weight(e, robust)
        w = wr / var
        JW = J.T * w
        N = JW @ J
        g = JW @ r
        Nd = N + lam * np.diag(np.diag(N)) if lam else N
        dX, singular = _solve3(Nd, g)
        iterations += 1
        Xn = X if singular else X + dX
        exploded = not np.isfinite(Xn).all() or np.linalg.norm(Xn - centre) > bound
        if exploded:
            Xn = X
        Jn, rn = model(Xn)
        rho_n, _ = _rho_and_weight(rn / np.sqrt(var), robust)
        cost_n = rho_n.sum()
        accept = not singular and not exploded and cost_n <= cost * (1 + 1e-12) + 1e-300
        step_norm = math.inf if singular else float(np.linalg.norm(dX))
        if accept:
            X, J, r, cost = Xn, Jn, rn, cost_n
            lam = 0.0 if lam / 10 < 1e-9 else lam / 10
        else:
            lam = 1e-4 if lam == 0 else lam * 10
        small = step_norm <= tol_m
        if singular and not small:
            status = Status.DEGENERATE
            break
        if exploded and not singular:
            status = Status.DIVERGED
            break
        inner_done = small or (not accept and lam > 1e12)
        if vce and inner_done:
            factors, usable = _vce_factors(J, r, var, npix, robust)
            more = [usable[k] and abs(factors[k] - 1) > VCE_TOL for k in (0, 1)]
            if any(more) and vce_rounds < VCE_MAX_ROUNDS:
                vf = [vf[k] * factors[k] if usable[k] else vf[k] for k in (0, 1)]
                vce_rounds += 1
                var = var_of(vf)
                rho, _ = _rho_and_weight(r / np.sqrt(var), robust)
                cost = rho.sum()
                lam = 0.0
                continue
        if inner_done:
            status = Status.CONVERGED
            break
    failed = status in (Status.DIVERGED, Status.DEGENERATE)
    e = r / np.sqrt(var)
    _, wr = _rho_and_weight(e, robust)
    w = wr / var
    JW = J.T * w
    cov, singular = _inv3(JW @ J)
    s = np.linalg.svd(J * np.sqrt(w)[:, None], compute_uv=False)
    cond = s[0] / s[-1] if s[-1] > 0 else math.inf
    bad_cond = singular  # the Jacobi-scaled criterion of the iteration: cond of the scaled design ~> 1e10
    if bad_cond and not failed:
        status = Status.DEGENERATE
    failed = status in (Status.DIVERGED, Status.DEGENERATE)
    if failed:
        X = np.full(3, np.nan)
        cov = np.full((3, 3), np.nan)
        if not bad_cond:
            cond = math.nan
    sigma0_sq = float((w * r * r).sum() / (m - 3)) if m > 3 else math.nan
    extras = {"variance_factor_pixel": vf[0], "variance_factor_range": vf[1], "sigma0_sq": sigma0_sq,
              "vce_rounds": vce_rounds}
    return X, iterations, status, cond, 0.5 * (cov + cov.T), extras, r


def _vce_factors(J, r, var, npix, robust):
    e = r / np.sqrt(var)
    _, wr = _rho_and_weight(e, robust)
    w = wr / var
    Ninv, _ = _inv3((J.T * w) @ J)
    lev = w * np.einsum("mi,ij,mj->m", J, Ninv, J)
    q = w * r * r
    out, usable = [1.0, 1.0], [False, False]
    for k, sl in ((0, slice(0, npix)), (1, slice(npix, None))):
        red = float((1.0 - lev[sl]).sum())
        if red >= 0.5:
            f = float(q[sl].sum()) / red
            if math.isfinite(f) and f > 0:
                out[k], usable[k] = f, True
    return out, usable
