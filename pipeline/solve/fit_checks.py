"""Does the error model fit the flight? Tests on the standardized residuals of a solve, batched over problems.

chi-square, lag-1 autocorrelation and batch means per sensor group (u and v pooled, ranges); why each:
docs/solvers.md, "Error models nobody stated".

Residual planes are (3, n, b): rows u, v, range of the n frames of b problems, zero where unused.
"""

from __future__ import annotations

import numpy as np
from scipy.special import chdtrc, chdtri  # chi2.sf / chi2.isf bit for bit, without importing scipy.stats

#: a model whose chi-square has a p-value below this fails the test
CHI2_ALPHA = 0.01
#: the largest inflation of a group's variances by the autocorrelation (rho = 0.98)
MAX_ACF_INFLATION = 99.0
#: false-alarm rate of the batch-means drift test (as the lag-1 test's two standard errors)
DRIFT_ALPHA = 0.023


def lag1_autocorrelation(E: np.ndarray, use: np.ndarray, rows: slice) -> tuple[np.ndarray, np.ndarray]:
    """(rho (b,), pairs (b,)): lag-1 autocorrelation of the residuals E (3,n,b) over the frames, pooled over the
    given rows (e.g. slice(0, 2) for u and v); only consecutive used frames (`use` (3,n,b) bool) pair up.
    NaN where there is no pair."""
    e = np.where(use[rows], E[rows], 0.0)
    pair = use[rows][:, 1:] & use[rows][:, :-1]
    num = np.where(pair, e[:, 1:] * e[:, :-1], 0.0).sum(axis=(0, 1))
    den = (e * e).sum(axis=(0, 1))
    pairs = pair.sum(axis=(0, 1))
    with np.errstate(divide="ignore", invalid="ignore"):
        rho = np.where((pairs > 0) & (den > 0), num / den, np.nan)
    return rho, pairs


def outlying_runs(off: np.ndarray) -> np.ndarray:
    """(n,b) bool: the frames of off (n,b) (a residual beyond the loss's full-weight zone) that have an off
    neighbour: runs of two or more consecutive frames. Under the error model two in a row happen with
    probability ~1e-5 per pair: such a run is one outlying segment (a mistracked run), not drift."""
    near = np.zeros_like(off)
    near[1:] |= off[:-1]
    near[:-1] |= off[1:]
    return off & near


def batch_means_ratio(E: np.ndarray, use: np.ndarray, rows: slice) -> tuple[np.ndarray, np.ndarray]:
    """(ratio (b,), blocks (b,)): the batch-means variance ratio of the residuals E (3,n,b), per row of `rows`
    (u and v apart) pooled: the used frames (`use` (3,n,b) bool) in blocks of k = floor(sqrt(count)), ratio =
    mean of k (block mean)^2 over the residuals' mean square: the variance inflation of an average (1 for white
    residuals, blocks * ratio then ~ chi-square with `blocks` dof; docs/solvers.md). NaN where no block."""
    u = use[rows]
    e = np.where(u, E[rows], 0.0)
    R, n, b = e.shape
    cnt = u.sum(axis=1)  # (R,b)
    k = np.maximum(np.floor(np.sqrt(cnt)), 2).astype(np.int64)
    nblk = cnt // k
    pos = np.cumsum(u, axis=1) - 1  # the used frame's rank in its row
    blk = pos // k[:, None, :]
    ok = u & (blk < nblk[:, None, :])
    flat = (np.arange(R)[:, None, None] * n + np.where(ok, blk, 0)) * b + np.arange(b)[None, None, :]
    sums = np.bincount(flat[ok], weights=e[ok], minlength=R * n * b).reshape(R, n, b)
    q = (sums * sums).sum(axis=1) / k  # (R,b): sum over blocks of k mean^2
    blocks = nblk.sum(axis=0)
    ms = (e * e).sum(axis=(0, 1)) / np.maximum(cnt.sum(axis=0), 1)
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = np.where((blocks > 0) & (ms > 0), q.sum(axis=0) / blocks / ms, np.nan)
    return ratio, blocks


def batch_means_significant(ratio: np.ndarray, blocks: np.ndarray) -> np.ndarray:
    """(b,) True where blocks * ratio exceeds the chi-square quantile of white residuals at DRIFT_ALPHA."""
    # the quantile once per distinct number of blocks (scipy's per-call cost dominates on a batch)
    dof, at = np.unique(np.maximum(blocks, 1), return_inverse=True)
    with np.errstate(invalid="ignore"):
        return np.isfinite(ratio) & (blocks >= 2) & (ratio * blocks > chdtri(dof, DRIFT_ALPHA)[at.reshape(-1)])


def batch_means_inflation(ratio: np.ndarray, significant: np.ndarray) -> np.ndarray:
    """(b,) variance inflation: the batch-means ratio where significant (at most MAX_ACF_INFLATION), else 1."""
    return np.where(significant, np.clip(np.nan_to_num(ratio, nan=1.0), 1.0, MAX_ACF_INFLATION), 1.0)


def acf_significant(rho: np.ndarray, pairs: np.ndarray) -> np.ndarray:
    """(b,) True where a positive lag-1 autocorrelation exceeds two standard errors 2 / sqrt(pairs) of white
    residuals (about 2.3 % false alarms)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.isfinite(rho) & (pairs >= 3) & (rho > 2.0 / np.sqrt(np.maximum(pairs, 1)))


def acf_inflation(rho: np.ndarray, significant: np.ndarray) -> np.ndarray:
    """(b,) variance inflation (1 + rho) / (1 - rho) where the autocorrelation is significant, else 1."""
    r = np.clip(np.where(significant, rho, 0.0), 0.0, 0.98)
    return np.minimum((1.0 + r) / (1.0 - r), MAX_ACF_INFLATION)


def chi_square_p(chi2: np.ndarray, dof: np.ndarray) -> np.ndarray:
    """(b,) upper-tail p-value of chi2 with dof degrees of freedom (NaN where dof < 1)."""
    with np.errstate(invalid="ignore"):
        return np.where(dof >= 1, chdtrc(np.maximum(dof, 1), chi2), np.nan)


def describe(chi2: float, dof: float, p: float, rho_pix: float, rho_rng: float, acf_pix: bool, acf_rng: bool,
             inflation: float, spread: float = 1.0, blocks_pix: float | None = None,
             blocks_rng: float | None = None) -> str | None:
    """One sentence for the console and the report when the model does not fit; None when it does. spread: the
    largest robust spread (1.4826 median |e|) of a group's standardized residuals, when the loss's rejection
    thresholds were widened by it (else 1); blocks_pix, blocks_rng: the batch-means ratio of a group whose block
    test failed (else None)."""
    parts = []
    if spread > 1.0:
        parts.append(f"the residuals are spread {spread:.1f} times wider than the stated sigmas (robust scale)")
    if np.isfinite(p) and p < CHI2_ALPHA:
        parts.append(f"the residuals are {np.sqrt(chi2 / dof):.1f} times larger than the error model says "
                     f"(chi-square {chi2:.0f} on {dof:.0f} degrees of freedom, p = {p:.1g})")
    for name, rho, drift in (("pixel", rho_pix, acf_pix), ("range", rho_rng, acf_rng)):
        if drift:
            parts.append(f"the {name} residuals drift slowly from frame to frame (lag-1 autocorrelation {rho:.2f})")
    for name, r in (("pixel", blocks_pix), ("range", blocks_rng)):
        if r is not None:
            parts.append(f"the {name} residuals' means over blocks of consecutive frames vary {r:.1f} times more than "
                         "independent errors' would (a slow drift)")
    if not parts:
        return None
    return ("the error model does not fit this flight: " + "; ".join(parts)
            + f"; the covariance was inflated (ellipse axes x{np.sqrt(inflation):.1f}) by what the residuals show,"
            " which cannot show an error that stays constant over the flight: the ellipse may still be too small")
