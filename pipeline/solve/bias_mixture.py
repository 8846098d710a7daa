"""How large is the constant part of the attitude error? Bayesian averaging over the boresight bias's prior
scale, for `mle` when nobody states the error model.

Told only "attitude 0.2 deg", nothing says how much of that error is constant over the flight (a boresight
bias: shared by every frame) and how much changes from frame to frame. The two call for different estimates:
a bias makes the frames' common pixel offset worthless for the target, white errors make it the best
information there is. So `mle` does not pick one; it averages over the bias's prior standard deviation
phi * sigma_att, phi on PHI_GRID (0: no bias, 1: a bias as large as the whole stated attitude error), equally
likely a priori, weighted by the evidence of the flight (the restricted likelihood: the target integrated out
with a flat prior). The stated attitude variance is the total: for each phi the frame-to-frame part keeps
(1 - phi^2) of it (`share`), so the residuals' scatter from frame to frame tells how much can be constant even
where the bias itself cannot be told from a target offset. Where the bias is observable the evidence also sees
the bias; where it is not, the estimate does not depend on phi (the bias and the target move the frames alike)
and the covariance carries the posterior's mean bias variance (the prior's: mean(PHI_GRID^2) = 0.35 of
sigma_att^2, when the flight tells nothing).

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

from pipeline.solve.stacked import inverse3

#: the bias's prior standard deviation over the stated attitude sigma: the candidates, equally likely a priori
PHI_GRID = np.linspace(0.0, 1.0, 9)
#: the smallest share of a pixel row's variance left when the bias takes the whole attitude error
RATIO_FLOOR = 1e-3


def _rows(A: np.ndarray, Bm: np.ndarray) -> np.ndarray:
    """(b,) sum over the rows of A * B, (n,b) or (3,n,b) planes."""
    return (A * Bm).reshape(-1, A.shape[-1]).sum(axis=0)


def _det3(N: np.ndarray) -> np.ndarray:
    """(b,) determinants of (b,3,3) matrices by cofactors."""
    return (N[:, 0, 0] * (N[:, 1, 1] * N[:, 2, 2] - N[:, 1, 2] * N[:, 2, 1])
            - N[:, 0, 1] * (N[:, 1, 0] * N[:, 2, 2] - N[:, 1, 2] * N[:, 2, 0])
            + N[:, 0, 2] * (N[:, 1, 0] * N[:, 2, 1] - N[:, 1, 1] * N[:, 2, 0]))


def mixture(J: np.ndarray, r: np.ndarray, a: np.ndarray, w: np.ndarray | None,
            share: np.ndarray | None = None) -> dict:
    """The bias-averaged linear step and covariance of b problems (module docstring).

    J (3,3,n,b), r (3,n,b), a (3,n,b) (rows 0 and 1 used), w (3,n,b) or None (unit weights); rows that are not
    in use must be zero in J and r and have zero weight (or zero a); share (2,n,b) or None: the attitude's
    share c in [0, 1] of each u and v row's variance (None: the frame-to-frame part keeps it all, the bias adds
    to it). Returns step (b,3) m, covariance (b,3,3) m^2, posterior (b,G) over PHI_GRID, bias (b,2) and
    bias_var (b,2) in units of a's prior (u, v), bias_cross (b,2,3) m the covariance of each bias with the
    target, singular (b,) where no candidate solves.
    """
    W1 = np.ones(r.shape) if w is None else np.asarray(w, dtype=np.float64)
    b = r.shape[-1]
    G = len(PHI_GRID)
    steps = np.empty((G, b, 3))
    covs = np.empty((G, b, 3, 3))
    logL = np.empty((G, b))
    bias = np.zeros((G, b, 2))
    bvar = np.zeros((G, b, 2))
    cross = np.zeros((G, b, 2, 3))
    singular_all = np.ones(b, dtype=bool)
    for j, phi in enumerate(PHI_GRID):
        p = phi * phi
        W, logdet_rows = W1, 0.0
        if share is not None:  # the frame-to-frame attitude variance is what the bias leaves of the stated one
            ratio = np.maximum(1.0 - p * share, RATIO_FLOOR)
            W = W1.copy()
            W[:2] = W1[:2] / ratio
            logdet_rows = np.where(W1[:2] > 0, np.log(ratio), 0.0).reshape(-1, b).sum(axis=0)
        WJ = J * W
        N0 = np.einsum("cknb,dknb->bcd", WJ, J)
        g0 = np.einsum("cknb,knb->bc", WJ, r)
        c0 = _rows(W * r, r)
        s = np.stack([_rows(W[k] * a[k], a[k]) for k in (0, 1)], axis=1)  # (b,2)
        h = np.stack([np.einsum("cnb,nb->bc", WJ[:, k], a[k]) for k in (0, 1)], axis=1)  # (b,2,3)
        t = np.stack([_rows(W[k] * a[k], r[k]) for k in (0, 1)], axis=1)  # (b,2)
        f = p / (1.0 + p * s)  # (b,2)
        N = N0 - np.einsum("bk,bkc,bkd->bcd", f, h, h)
        g = g0 - np.einsum("bk,bkc->bc", f * t, h)
        q = c0 - (f * t * t).sum(axis=1)
        C, singular = inverse3(N)
        d = np.einsum("bcd,bd->bc", C, g)
        det = _det3(N)
        with np.errstate(divide="ignore", invalid="ignore"):
            ll = -0.5 * (q - (g * d).sum(axis=1) + np.log1p(p * s).sum(axis=1) + np.log(det)
                         + logdet_rows)
        logL[j] = np.where(singular | ~np.isfinite(ll), -np.inf, ll)
        singular_all &= singular
        steps[j], covs[j] = d, C
        Ch = np.einsum("bcd,bkd->bkc", C, h)  # (b,2,3)
        bias[j] = f * (t - np.einsum("bkc,bc->bk", h, d))
        bvar[j] = f + f * f * np.einsum("bkc,bkc->bk", h, Ch)
        cross[j] = -f[..., None] * Ch
    top = logL.max(axis=0)
    with np.errstate(invalid="ignore"):
        pi = np.exp(logL - np.where(np.isfinite(top), top, 0.0))
    pi = np.where(np.isfinite(pi), pi, 0.0)
    total = pi.sum(axis=0)
    pi = np.where(total > 0, pi / np.where(total > 0, total, 1.0), 1.0 / G)
    # a singular candidate has no weight (pi = 0); keep its NaNs out of the sums
    steps, covs, bias, bvar, cross = (np.where(np.isfinite(x), x, 0.0) for x in (steps, covs, bias, bvar, cross))
    step = np.einsum("gb,gbc->bc", pi, steps)
    dev = steps - step
    cov = np.einsum("gb,gbcd->bcd", pi, covs + dev[..., :, None] * dev[..., None, :])
    bias_mean = np.einsum("gb,gbk->bk", pi, bias)
    bdev = bias - bias_mean
    bias_var = np.einsum("gb,gbk->bk", pi, bvar + bdev * bdev)
    bias_cross = np.einsum("gb,gbkc->bkc", pi, cross + bdev[..., None] * dev[:, :, None, :])
    cov[singular_all] = np.nan
    return {"step": step, "covariance": cov, "posterior": pi.T, "bias": bias_mean, "bias_var": bias_var,
            "bias_cross": bias_cross, "singular": singular_all}
