"""How large is the constant part of the attitude error? Bayesian averaging over the boresight bias's prior
scale, for `mle` when nobody states the error model.

Why, and what the flight can tell: docs/solvers.md, "Boresight bias from the flight, its size by evidence".
PHI_GRID: the candidates phi (0: no bias, 1: a bias as large as the whole stated attitude error).

The model is linear at the solve's solution: standardized residual rows r (3,n,b) (u, v, range of n frames of
b problems), Jacobian J (3,3,n,b) of the rows in the target, bias columns a (3,n,b) (the u and v rows' pixel
offset per unit bias at the largest prior; range rows 0), IRLS weights w, and each pixel row's attitude share
c of its variance. With p = phi^2 the rows' variances are (1 - p c) / w (W = w / (1 - p c)) plus the bias's;
with s_k = a_k' W a_k, h_k = J' W a_k, t_k = a_k' W r for the u and v biases (disjoint rows), the bias
integrated out:

    N_p = J'WJ - sum_k p h_k h_k' / (1 + p s_k)     g_p = J'Wr - sum_k p h_k t_k / (1 + p s_k)
    step d_p = N_p^-1 g_p, covariance N_p^-1,
    log L(p) = -1/2 (r'Wr - sum_k p t_k^2 / (1 + p s_k) - g_p' d_p + sum_k log(1 + p s_k) + log det N_p
                     + sum_rows log(1 - p c))

and the answer is the posterior mixture: step sum pi_p d_p, covariance sum pi_p (N_p^-1 + d_p d_p') - d d'.
"""

from __future__ import annotations

import numpy as np

from pipeline.solve.stacked import FULL3, PAIRS, cofactors3

#: the bias's prior standard deviation over the stated attitude sigma: the candidates, equally likely a priori
PHI_GRID = np.linspace(0.0, 1.0, 9)
#: the smallest share of a pixel row's variance left when the bias takes the whole attitude error
RATIO_FLOOR = 1e-3

#: the per-row products summed for each candidate (planes of `_row_products`): J_c J_d (6), J_c r (3), r r,
#: a J_c (3), a a, a r
_JJ, _JR, _RR, _AJ, _AA, _AR = slice(0, 6), slice(6, 9), 9, slice(10, 13), 13, 14


def _row_products(J: np.ndarray, r: np.ndarray, a: np.ndarray, W: np.ndarray) -> np.ndarray:
    """(15,k,n,b) the weighted products of each row whose sums make the normal equations and the bias terms
    (`_JJ` ... `_AR`), from J (3,k,n,b), r, a, W (k,n,b)."""
    WJ = J * W
    F = np.empty((15, *r.shape))
    for e, (c, d) in enumerate(PAIRS):
        np.multiply(WJ[c], J[d], out=F[e])
    for c in range(3):
        np.multiply(WJ[c], r, out=F[6 + c])
        np.multiply(WJ[c], a, out=F[10 + c])
    Wr = W * r
    np.multiply(Wr, r, out=F[_RR])
    np.multiply(W * a, a, out=F[_AA])
    np.multiply(Wr, a, out=F[_AR])
    return F


def ratios(share: np.ndarray, w: np.ndarray | None):
    """Each candidate's ratios of the u and v rows' frame-to-frame variance to the stated one, 1 - p c (at least
    RATIO_FLOOR), for the attitude's share c (2,n,b) of each row's variance (0 where the weight w (3,n,b) is 0:
    rows not in use): their inverses (G,2,n,b) and the sums of their logs over the rows (G,b), for `mixture`
    (they depend on the rows' shares and weights only, not on where the model is linearized)."""
    if w is not None:
        share = np.where(np.asarray(w)[:2] > 0, share, 0.0)
    p = PHI_GRID * PHI_GRID
    ratio = np.maximum(1.0 - p[:, None, None, None] * share, RATIO_FLOOR)
    # one log per block of <= 100 rows, not per row (100 ratios >= RATIO_FLOOR = 1e-3 multiply to >= 1e-300)
    G, b = len(PHI_GRID), share.shape[-1]
    rows = ratio.reshape(G, -1, b)
    m = rows.shape[1]
    size = -(-m // -(-m // 100))  # ceil(m / ceil(m / 100))
    if m % size:
        rows = np.concatenate([rows, np.ones((G, size - m % size, b))], axis=1)
    return 1.0 / ratio, np.log(rows.reshape(G, -1, size, b).prod(axis=2)).sum(axis=1)


def mixture(J: np.ndarray, r: np.ndarray, a: np.ndarray, w: np.ndarray | None, rows=None) -> dict:
    """The bias-averaged linear step and covariance of b problems (module docstring).

    J (3,3,n,b), r (3,n,b), a (3,n,b) (rows 0 and 1 used), w (3,n,b) or None (unit weights); rows that are not
    in use must be zero in J and r and have zero weight (or zero a); rows: `ratios` of the attitude's share
    of each u and v row's variance, or None (the frame-to-frame part keeps it all, the bias adds to it).
    Returns step (b,3) m, covariance (b,3,3) m^2, posterior (b,G) over PHI_GRID, bias (b,2) and bias_var (b,2)
    in units of a's prior (u, v), bias_cross (b,2,3) m the covariance of each bias with the target, singular
    (b,) where no candidate solves.

    Only the u and v rows' weights depend on the candidate (through the ratios): the rows' weighted products
    are formed once (`_row_products`) and each candidate sums them over the frames with its ratios; the range
    rows' sums are the same for all. Then all candidates at once as (G,b) planes, 3x3 solves by cofactors.
    """
    W1 = np.ones(r.shape) if w is None else np.asarray(w, dtype=np.float64)
    b = r.shape[-1]
    G = len(PHI_GRID)
    p = (PHI_GRID * PHI_GRID)[:, None]  # (G,1)
    F = _row_products(J[:, :2], r[:2], a[:2], W1[:2])  # (15,2,n,b)
    Jr, rr, Wr = J[:, 2], r[2], W1[2]
    WJr = Jr * Wr
    range_sums = np.stack([(WJr[c] * Jr[d]).sum(axis=0) for c, d in PAIRS]
                          + [(WJr[c] * rr).sum(axis=0) for c in range(3)] + [(Wr * rr * rr).sum(axis=0)])
    if rows is None:  # the same sums for every candidate
        S = np.broadcast_to(F.sum(axis=2), (G, 15, 2, b))
        logdet_rows = np.zeros((G, b))
    else:  # the frame-to-frame attitude variance is what the bias leaves of the stated one
        inv_ratio, logdet_rows = rows
        S = np.empty((G, 15, 2, b))
        for j in range(G):
            np.einsum("fknb,knb->fkb", F, inv_ratio[j], out=S[j])
    both = S[:, :10].sum(axis=2) + range_sums  # (G,10,b): N0's six entries, g0, c0
    s, t = S[:, _AA], S[:, _AR]  # (G,2,b)
    h = S[:, _AJ]  # (G,3,2,b)
    f = p[..., None] / (1.0 + p[..., None] * s)  # (G,2,b)
    fh = f[:, None] * h
    n00, n01, n02, n11, n12, n22 = (both[:, e] - (fh[:, c] * h[:, d]).sum(axis=1) for e, (c, d) in enumerate(PAIRS))
    g = both[:, _JR] - (fh * t[:, None]).sum(axis=2)  # (G,3,b)
    q = both[:, _RR] - (f * t * t).sum(axis=1)
    C, det, singular = cofactors3([n00, n01, n02, n11, n12, n22])  # (G,b) planes, in PAIRS order
    C = np.stack(C)
    d = np.stack([sum(C[FULL3[c][e]] * g[:, e] for e in range(3)) for c in range(3)], axis=1)  # (G,3,b)
    with np.errstate(divide="ignore", invalid="ignore"):
        ll = -0.5 * (q - (g * d).sum(axis=1) + np.log1p(p[..., None] * s).sum(axis=1) + np.log(det) + logdet_rows)
    logL = np.where(singular | ~np.isfinite(ll), -np.inf, ll)
    singular_all = singular.all(axis=0)
    top = logL.max(axis=0)
    with np.errstate(invalid="ignore"):
        pi = np.exp(logL - np.where(np.isfinite(top), top, 0.0))
    pi = np.where(np.isfinite(pi), pi, 0.0)
    total = pi.sum(axis=0)
    pi = np.where(total > 0, pi / np.where(total > 0, total, 1.0), 1.0 / G)
    # a singular candidate has no weight (pi = 0); keep its NaNs out of the sums (a candidate with a finite
    # likelihood has finite terms: only the others can hold any)
    unclean = not np.isfinite(logL).all()
    d0, C0 = d, C
    if unclean:
        d, C = (np.where(np.isfinite(x), x, 0.0) for x in (d, C))
    step = (pi[:, None] * d).sum(axis=0)  # (3,b)
    Ch = np.stack([sum(C0[FULL3[c][e]][:, None] * h[:, e] for e in range(3)) for c in range(3)], axis=1)  # (G,3,2,b)
    bias = f * (t - (h * d0[:, :, None]).sum(axis=1))  # (G,2,b)
    bvar = f + f * f * (h * Ch).sum(axis=1)
    cross = -f[:, None] * Ch  # (G,3,2,b)
    if unclean:
        bias, bvar, cross = (np.where(np.isfinite(x), x, 0.0) for x in (bias, bvar, cross))
    dev = d - step
    cov6 = np.stack([(pi * (C[e] + dev[:, c] * dev[:, dd])).sum(axis=0) for e, (c, dd) in enumerate(PAIRS)])
    cov = cov6[[0, 1, 2, 1, 3, 4, 2, 4, 5]].T.reshape(b, 3, 3)
    bias_mean = (pi[:, None] * bias).sum(axis=0)  # (2,b)
    bdev = bias - bias_mean
    bias_var = (pi[:, None] * (bvar + bdev * bdev)).sum(axis=0)
    bias_cross = (pi[:, None, None] * (cross + bdev[:, None] * dev[:, :, None])).sum(axis=0)  # (3,2,b)
    cov[singular_all] = np.nan
    return {"step": step.T, "covariance": cov, "posterior": pi.T, "bias": bias_mean.T, "bias_var": bias_var.T,
            "bias_cross": bias_cross.transpose(2, 1, 0), "singular": singular_all}
