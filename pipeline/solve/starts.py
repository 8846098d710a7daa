"""`mle` on one problem never worse than its own starting points: every other estimator's answer is a candidate
start, and a fit that explains the pixels away is not an answer (docs/solvers.md, "Never an answer that explains
the pixels away"). The fits are compared on one yardstick that does not depend on the model a fit chose
(`yardstick`)."""

from __future__ import annotations

import numpy as np

from pipeline.solve.mle import _rho_and_weight
from pipeline.solve.observations import Sigma
from pipeline.solve.stacked import Stacked, pixel_model, range_model

#: the other estimators whose answers start `mle` (range only where it converges: elsewhere not determined)
START_METHODS = ("dlt", "los", "vision", "fusion", "range")
#: a fit is "explaining the pixels away" when more than this share of its pixel rows got zero weight, or when
#: a variance factor or sigma0^2 left this range (the stated sigmas off by a factor of ~30 or more)
MAX_REJECTED_PIXEL_SHARE = 0.5
VARIANCE_FACTOR_RANGE = (1e-3, 1e3)
#: a candidate outside the fit's ellipsoid of this chi-square (3 dof, 99.9 %) disagrees beyond its uncertainty
DISAGREE_CHI2 = 16.27
#: another start's fit replaces the default start's when its common robust cost is lower by this share
CLEARLY_BETTER = 0.02
#: a model needing a stated sigma (the attitude error, the pixel or range noise) beyond this many times the stated
#: one explains those observations away: a boresight bias that large is refitted without (`methods._bias_refit`),
#: a learned drift model that needs it is not admitted (`learned_tau`)
MAX_OVER_STATED = 3.0
#: starts closer than this (m) to one already run are not run again
SAME_START_M = 1.0


def explains_away(ex: dict, npix: int) -> str | None:
    """Why a fit's extras (B = 1 arrays) show the pixels explained away rather than fitted, or None; npix: the
    problem's frames with a pixel."""
    rej = ex.get("rejected")
    if rej is not None and npix:
        share = float(rej[0, :, :2].any(axis=-1).sum()) / npix
        if share > MAX_REJECTED_PIXEL_SHARE:
            return f"{share:.0%} of the pixels got zero weight"
    lo, hi = VARIANCE_FACTOR_RANGE
    v = float(ex["variance_factor_pixel"][0])
    if np.isfinite(v) and not lo <= v <= hi:
        return f"pixel variance factor {v:.3g}"
    v = float(ex["sigma0_sq"][0])
    if np.isfinite(v) and v > hi:
        return f"sigma0^2 {v:.3g}"
    return None


def _residuals(st: Stacked, X: np.ndarray):
    """Pixel residuals (k,2) about their per-axis median and range residuals (l,) of one problem at X (3,)."""
    _, rp, _ = pixel_model(st, X[None])
    _, rr, _ = range_model(st, X[None])
    pix = rp[0].reshape(-1, 2)[st.has_pix[0]]
    if len(pix):
        pix = pix - np.median(pix, axis=0)
    return pix, rr[0, st.has_range[0]]


def yardstick(st: Stacked, sigma: Sigma, points: np.ndarray, consensus: np.ndarray) -> np.ndarray:
    """(len(points),) the common robust cost of one problem (B = 1) at points (k,3): the Huber cost of all pixel and
    range residuals at one scale per group (the stated white sigma, or larger the robust spread 1.4826 median
    |r - median r| at the candidates' consensus), the pixel residuals about their per-axis median (a constant
    boresight offset, which every fit may explain by a bias, costs nothing)."""
    pix0, rng0 = _residuals(st, consensus)
    scales = []
    for r, stated in ((pix0.ravel(), sigma.pixel_px), (rng0, sigma.range_m)):
        s = 1.4826 * float(np.median(np.abs(r - np.median(r)))) if r.size >= 3 else 0.0
        scales.append(max(s, stated or 0.0, 1e-6))
    out = []
    for X in points:
        cost = 0.0
        for r, s in zip(_residuals(st, X), scales, strict=True):
            cost += float(_rho_and_weight(np.ravel(r) / s, "huber")[0].sum())
        out.append(cost)
    return np.array(out)


def disagreement(X: np.ndarray, cov: np.ndarray, candidates: dict) -> dict:
    """{method: e^T C^-1 e} of each candidate (3,) against the fit X (3,) with covariance cov (3,3)."""
    out = {}
    try:
        inv = np.linalg.inv(cov)
    except np.linalg.LinAlgError:
        return out
    for name, c in candidates.items():
        e = c - X
        out[name] = float(e @ inv @ e)
    return out


__all__ = ["DISAGREE_CHI2", "START_METHODS", "disagreement", "explains_away", "yardstick"]
