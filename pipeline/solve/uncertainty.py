"""Accuracy summaries of a position covariance, for `solve` and the report alike: CEP, the 3-D error ellipsoid
and the horizontal error ellipse. Pure numpy; covariances in m^2, East-North(-Up) axes.
"""

from __future__ import annotations

import numpy as np
from scipy.special import erf, erfinv

#: 95 % quantile of chi-square with 3 degrees of freedom, for the 95 % ellipsoid
CHI2_3_95 = 7.814727903251178
#: the confidence of the horizontal error ellipse the outputs draw
ELLIPSE_CONFIDENCE = 0.95

_Q_GRID = np.linspace(0.0, 1.0, 257)
_GL_X, _GL_W = np.polynomial.legendre.leggauss(64)
_GL_T = 0.5 * np.pi * _GL_X
_CEP_TABLES: dict[float, np.ndarray] = {}


def _prob_within(rho: np.ndarray, q: np.ndarray) -> np.ndarray:
    """P(|e| <= rho) for e ~ N(0, diag(1, q^2)), elementwise over rho, q (q <= 1): conditioned on the major component
    z1 = rho sin t, int_{-pi/2}^{pi/2} phi(rho sin t) erf(rho cos t / (sqrt(2) q)) rho cos t dt by 64-point
    Gauss-Legendre (smooth integrand; the steep erf at the ends is damped by cos t)."""
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


def _principal_sd(cov_xy: np.ndarray):
    """Principal standard deviations s1 >= s2 (...) of (..., 2, 2) covariances (closed-form eigenvalues)."""
    a, b, c = cov_xy[..., 0, 0], cov_xy[..., 0, 1], cov_xy[..., 1, 1]
    mean = 0.5 * (a + c)
    half = np.sqrt(0.25 * (a - c) ** 2 + b * b)
    return np.sqrt(np.maximum(mean + half, 0.0)), np.sqrt(np.maximum(mean - half, 0.0))


def cep_m(cov_xy: np.ndarray, p: float) -> np.ndarray:
    """(...) radius of the circle around the estimate holding probability p of the horizontal error, of (..., 2, 2)
    covariances of a zero-mean 2D Gaussian (0 for a zero covariance, NaN for a non-finite one): s1 rho_p(s2/s1)
    with principal standard deviations s1 >= s2, rho_p tabulated once per p on 257 ratios and interpolated
    linearly (relative error < 1e-5 against a 1025-point table)."""
    s1, s2 = _principal_sd(np.asarray(cov_xy, dtype=np.float64))
    ok = np.isfinite(s1) & (s1 > 0)
    q = np.where(ok, s2 / np.where(ok, s1, 1.0), 1.0)
    return np.where(ok, s1 * np.interp(q, _Q_GRID, _cep_table(float(p))), np.where(s1 == 0, 0.0, np.nan))


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


def summaries(cov: np.ndarray) -> dict:
    """The batched accuracy extras of (B,3,3) covariances: cep50_m, cep90_m (B,), the 1-sigma ellipsoid."""
    axes, vecs = ellipsoid(cov)
    return {"cep50_m": cep_m(cov[:, :2, :2], 0.5), "cep90_m": cep_m(cov[:, :2, :2], 0.9),
            "ellipsoid_semi_axes_1sigma_m": axes, "ellipsoid_axes": vecs}


def ellipsoid_json(axes: np.ndarray, vecs: np.ndarray) -> dict:
    """One problem's ellipsoid (`ellipsoid`'s (3,) axes, (3,3) vectors) as JSON values, with the 95 % axes."""
    ax = axes.tolist()
    s95 = float(np.sqrt(CHI2_3_95))
    return {"semi_axes_1sigma_m": ax, "semi_axes_95pct_m": [v * s95 for v in ax], "axes": vecs.T.tolist()}


def _ellipse(cov_en_m2: np.ndarray, confidence: float):
    """Eigenvalues (2,) (clipped at 0), eigenvectors and the 2-D chi-square quantile -2 ln(1 - confidence)."""
    w, v = np.linalg.eigh(np.asarray(cov_en_m2, dtype=np.float64))
    return np.clip(w, 0.0, None), v, -2.0 * np.log1p(-confidence)


def ellipse_axes_m(cov_en_m2: np.ndarray, confidence: float = ELLIPSE_CONFIDENCE) -> tuple[float, float, float]:
    """Semi-major and semi-minor axis (m) of the horizontal error ellipse holding `confidence` of a 2D Gaussian
    with (2, 2) East-North covariance, and the major axis' azimuth in degrees clockwise from North [0, 180)."""
    w, v, k2 = _ellipse(cov_en_m2, confidence)
    azimuth = float(np.degrees(np.arctan2(v[0, 1], v[1, 1])) % 180.0)
    return float(np.sqrt(k2 * w[1])), float(np.sqrt(k2 * w[0])), azimuth


def ellipse_points_en_m(cov_en_m2: np.ndarray, confidence: float = ELLIPSE_CONFIDENCE, n: int = 72) -> np.ndarray:
    """(n + 1, 2) East-North offsets (m) of the error ellipse boundary, counter-clockwise, first point repeated
    at the end (a closed ring)."""
    w, v, k2 = _ellipse(cov_en_m2, confidence)
    t = np.linspace(0.0, 2.0 * np.pi, n, endpoint=False)
    pts = np.stack([np.cos(t), np.sin(t)], axis=1) * np.sqrt(k2 * w) @ v.T
    if np.linalg.det(v) < 0:  # a reflection would turn the ring clockwise
        pts = pts[::-1]
    return np.vstack([pts, pts[:1]])


def horizontal(cov_m2: np.ndarray) -> dict:
    """CEP50, CEP90, vertical sigma and the 95 % horizontal ellipse (semi-axes, azimuth) of one (3,3)
    covariance, as the report's columns."""
    en = np.asarray(cov_m2, dtype=np.float64)[:2, :2]
    a, b, az = ellipse_axes_m(en)
    return {"cep50_m": float(cep_m(en, 0.5)), "cep90_m": float(cep_m(en, 0.9)),
            "sigma_up_m": float(np.sqrt(max(cov_m2[2][2], 0.0))), "ellipse95_semi_major_m": a,
            "ellipse95_semi_minor_m": b, "ellipse95_azimuth_deg": az}
