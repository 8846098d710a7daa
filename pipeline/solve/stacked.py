"""Batched observation arrays and the two measurement models (reprojection, range) every estimator shares.

`Stacked` is an `ObservationBatch` (or one `Observations`, as B = 1) with missing pixels and ranges replaced
by zeros and described by boolean masks, so that the batched kernels can weight missing rows with zero.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from pipeline.solve.observations import ObservationBatch, Observations, Sigma


@dataclass
class Stacked:
    """B problems of n frames. Shapes: M (B,n,3,3) = P[..., :3], p4 (B,n,3) = P[..., 3], pix (B,n,2) px
    (0 where missing), has_pix (B,n) bool, platform_m (B,n,3), range_m (B,n) (0 where missing),
    has_range (B,n) bool, truth_m (B,3) or None, t_ns (B,n) int64 timestamps or None (a batch has none)."""

    M: np.ndarray
    p4: np.ndarray
    pix: np.ndarray
    has_pix: np.ndarray
    platform_m: np.ndarray
    range_m: np.ndarray
    has_range: np.ndarray
    sigma: Sigma
    truth_m: np.ndarray | None = None
    t_ns: np.ndarray | None = None

    @classmethod
    def from_batch(cls, batch: ObservationBatch) -> Stacked:
        return cls._build(batch.P, batch.pixel, batch.platform_m, batch.range_m, batch.sigma, batch.truth_m)

    @classmethod
    def from_observations(cls, obs: Observations) -> Stacked:
        st = cls._build(obs.P[None], obs.pixel[None], obs.platform_m[None], obs.range_m[None], obs.sigma,
                        None if obs.truth_m is None else obs.truth_m[None])
        st.t_ns = obs.t_ns[None]
        return st

    @classmethod
    def _build(cls, P, pixel, platform, rng, sigma, truth) -> Stacked:
        has_pix = ~np.isnan(pixel[..., 0])
        has_range = ~np.isnan(rng)
        return cls(M=np.ascontiguousarray(P[..., :3]), p4=np.ascontiguousarray(P[..., 3]),
                   pix=np.where(has_pix[..., None], pixel, 0.0), has_pix=has_pix,
                   platform_m=np.asarray(platform, dtype=np.float64), range_m=np.where(has_range, rng, 0.0),
                   has_range=has_range, sigma=sigma, truth_m=truth)

    @property
    def size(self) -> int:
        return self.M.shape[0]

    @property
    def n(self) -> int:
        return self.M.shape[1]

    def take(self, idx: np.ndarray) -> Stacked:
        """The problems at integer indices idx, as a new Stacked."""
        return Stacked(M=self.M[idx], p4=self.p4[idx], pix=self.pix[idx], has_pix=self.has_pix[idx],
                       platform_m=self.platform_m[idx], range_m=self.range_m[idx], has_range=self.has_range[idx],
                       sigma=self.sigma, truth_m=None if self.truth_m is None else self.truth_m[idx],
                       t_ns=None if self.t_ns is None else self.t_ns[idx])

    # ---- derived camera quantities ---------------------------------------------------------------------

    @cached_property
    def gram(self) -> np.ndarray:
        """(B,n,3,3) M M^T (the rows' dot products)."""
        M, g = self.M, np.empty(self.M.shape)
        for i, j in PAIRS:  # entry by entry: a batched matmul of 3x3 matrices costs 2.5x more
            g[..., i, j] = g[..., j, i] = sum(M[..., i, k] * M[..., j, k] for k in range(3))
        return g

    @cached_property
    def unit_planes(self) -> Planes:
        """The problems as `Planes` with every row's sigma 1 (`pixel_model`, `range_model`)."""
        return Planes.from_stacked(self, np.ones((self.size, 3 * self.n)))

    @cached_property
    def det_M(self) -> np.ndarray:
        """(B,n) det of the left 3x3 block of each P."""
        a, b, c = self.M[..., 0, :], self.M[..., 1, :], self.M[..., 2, :]
        return (a[..., 0] * (b[..., 1] * c[..., 2] - b[..., 2] * c[..., 1])
                - a[..., 1] * (b[..., 0] * c[..., 2] - b[..., 2] * c[..., 0])
                + a[..., 2] * (b[..., 0] * c[..., 1] - b[..., 1] * c[..., 0]))

    def depth_sign(self) -> np.ndarray:
        """(B,n) sign of det(M): P and -P project alike, the sign says which side of the camera is 'front'."""
        return np.where(self.det_M < 0, -1.0, 1.0)

    def focal_px(self) -> tuple[np.ndarray, np.ndarray]:
        """(B,n) focal lengths fx, fy in px from the rows m1, m2, m3 of M = lambda K R (zero skew assumed):
        m1 x m3 = lambda^2 fx r1 x r3, so fx = |m1 x m3| / |m3|^2 = sqrt(|m1|^2 |m3|^2 - (m1.m3)^2) / |m3|^2,
        and likewise fy with m2."""
        g = self.gram
        g33 = g[..., 2, 2]
        fx = np.sqrt(np.maximum(g[..., 0, 0] * g33 - g[..., 0, 2] ** 2, 0.0)) / g33
        fy = np.sqrt(np.maximum(g[..., 1, 1] * g33 - g[..., 1, 2] ** 2, 0.0)) / g33
        return fx, fy

    def depths(self, X: np.ndarray) -> np.ndarray:
        """(B,n) signed depth in metres along each optical axis (positive in front) of points X (B,3):
        q3 / |m3| with q = M X + p4, since m3 = lambda r3 for P = lambda K [R | t]."""
        m3 = self.M[..., 2, :]
        q2 = (m3 @ X[:, :, None])[..., 0] + self.p4[..., 2]
        n3 = np.sqrt(self.gram[..., 2, 2])
        return q2 * self.depth_sign() / np.where(n3 > 0, n3, np.inf)


class Planes:
    """B problems as contiguous (n,b) planes: M entries Mc (3,3,n,b), p4c (3,n,b), pixels (2,n,b), platforms sc
    (3,n,b), ranges (n,b), the masks, and the rows' inverse standard deviations isd (3,n,b) (`mle.base_variances`).
    Numpy is slow on tiny trailing axes; with the problems last every operation is one contiguous pass."""

    __slots__ = ("Mc", "has_pix", "has_range", "isd", "p4c", "pixc", "rng", "sc")

    def __init__(self, Mc, p4c, pixc, sc, rng, has_pix, has_range, isd):
        self.Mc, self.p4c, self.pixc, self.sc, self.rng = Mc, p4c, pixc, sc, rng
        self.has_pix, self.has_range, self.isd = has_pix, has_range, isd

    @classmethod
    def from_stacked(cls, st: Stacked, var: np.ndarray) -> Planes:
        B, n = st.has_pix.shape
        isd = np.empty((3, n, B))
        np.divide(1.0, np.sqrt(var[:, :2 * n].reshape(B, n, 2).transpose(2, 1, 0)), out=isd[:2])
        np.divide(1.0, np.sqrt(var[:, 2 * n:].T), out=isd[2])
        c = np.ascontiguousarray
        return cls(c(st.M.transpose(2, 3, 1, 0)), c(st.p4.transpose(2, 1, 0)), c(st.pix.transpose(2, 1, 0)),
                   c(st.platform_m.transpose(2, 1, 0)), c(st.range_m.T), c(st.has_pix.T), c(st.has_range.T), isd)

    def take(self, idx: np.ndarray) -> Planes:
        return Planes(*(take_last(x, idx) for x in (self.Mc, self.p4c, self.pixc, self.sc, self.rng, self.has_pix,
                                                    self.has_range, self.isd)))


def take_last(x: np.ndarray, idx) -> np.ndarray:
    """x[..., idx] for integer (or boolean) idx: the problems on the last axis of planes. np.take and
    np.compress are several times faster than fancy indexing there (which copies element by element)."""
    idx = np.asarray(idx)
    return np.compress(idx, x, axis=-1) if idx.dtype == bool else np.take(x, idx, axis=-1)


def put_last(x: np.ndarray, idx: np.ndarray, v: np.ndarray) -> None:
    """x[..., idx] = v in place for integer idx (x C-contiguous, v shaped x[..., idx]): by flat indices (np.put,
    ~1.6x faster than fancy assignment on the last axis)."""
    b = x.shape[-1]
    flat = (np.arange(0, x.size, b)[:, None] + idx).ravel()
    np.put(x, flat, np.broadcast_to(v, (*x.shape[:-1], len(idx))))


def evaluate(pl: Planes, X: np.ndarray, rows: slice = slice(0, 3)):
    """Standardized Jacobian J (3,3,n,b) (J[c, k] = d row / d X_c over the row's sigma, rows k = u, v, range of
    each frame) and residuals E (3,n,b) at X (b,3); unusable rows (missing, q3 = 0, X on a platform) are zero;
    and their mask ok (3,n,b). The one measurement model (reprojection and range) of every estimator; rows: only
    those rows (slice(0, 2) the pixels, slice(2, 3) the ranges), J (3,k,n,b), E and ok (k,n,b)."""
    n, b = pl.has_pix.shape
    J = np.empty((3, 3, n, b))
    E = np.empty((3, n, b))
    ok = np.empty((3, n, b), dtype=bool)
    Mc, isd = pl.Mc, pl.isd
    Xp = X.T[:, None, :]  # (3,1,b): broadcasts over the frames
    if rows.start < 2:
        q = Mc[:, 0] * Xp[0] + Mc[:, 1] * Xp[1] + Mc[:, 2] * Xp[2] + pl.p4c  # (3,n,b)
        okp = np.logical_and(pl.has_pix, q[2] != 0, out=ok[0])
        ok[1] = okp
        iw = 1.0 / np.where(okp, q[2], np.inf)  # 1/q3, 0 on unusable rows
        uv = q[:2] * iw
        s = iw * isd[:2]
        for c in range(3):  # per coordinate, so that the temporaries stay (2,n,b) planes (in cache)
            np.multiply(Mc[:2, c] - uv * Mc[2, c], s, out=J[c, :2])
        np.multiply(pl.pixc - uv, np.where(okp, isd[:2], 0.0), out=E[:2])
    if rows.stop > 2:
        d = Xp - pl.sc
        dist = np.sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2])
        okr = np.logical_and(pl.has_range, dist > 0, out=ok[2])
        np.multiply(d, isd[2] / np.where(okr, dist, np.inf), out=J[:, 2])
        np.multiply(pl.rng - dist, np.where(okr, isd[2], 0.0), out=E[2])
    return J[:, rows], E[rows], ok[rows]


def pixel_model(st: Stacked, X: np.ndarray):
    """Reprojection Jacobian J (B,2n,3) d(u,v)/dX, residuals r (B,2n) observed - predicted (px) and mask (B,2n)
    at X (B,3), rows u_1, v_1, u_2, ...: `evaluate`'s pixel rows at unit sigmas, as rows (zero where masked: a
    missing pixel or q3 = 0)."""
    J, E, ok = evaluate(st.unit_planes, X, rows=slice(0, 2))
    B, n = st.has_pix.shape
    return (J.transpose(3, 2, 1, 0).reshape(B, 2 * n, 3), E.transpose(2, 1, 0).reshape(B, 2 * n),
            ok.transpose(2, 1, 0).reshape(B, 2 * n))


def range_model(st: Stacked, X: np.ndarray):
    """Range residuals and Jacobian at X (B,3): J (B,n,3) = (X - s_i)/|X - s_i|, r (B,n) = d_i - |X - s_i| (m),
    mask (B,n) bool (a missing range, or X on a platform position, is masked): `evaluate`'s range rows at unit
    sigmas, as rows."""
    J, E, ok = evaluate(st.unit_planes, X, rows=slice(2, 3))
    return J[:, 0].transpose(2, 1, 0), E[0].T, ok[0].T


def normal_equations(J: np.ndarray, r: np.ndarray, w: np.ndarray):
    """N = J^T W J (B,k,k) and g = J^T W r (B,k) for diagonal weights w (B,m)."""
    Jw = J * w[..., None]
    Jt = np.swapaxes(Jw, 1, 2)
    return Jt @ J, (Jt @ r[..., None])[..., 0]


#: a normal matrix whose Jacobi-scaled determinant (1 for orthogonal columns, 0 for dependent ones) is below
#: this is singular: the smallest eigenvalue of the scaled normal matrix is then below ~1e-12, i.e. the
#: column-equilibrated design matrix has a condition number beyond ~1e6; well above rounding (~1e-16)
SINGULAR_DET = 1e-12


def solve_spd(N: np.ndarray, g: np.ndarray, singular_below: float = SINGULAR_DET):
    """Solve N x = g for a batch of symmetric positive (semi-)definite N (B,k,k).

    Returns x (B,k) and a (B,) bool 'singular' flag (`SINGULAR_DET`). Singular problems get x = NaN instead of
    a numpy LinAlgError for the whole batch.
    """
    if N.shape[-1] == 3:
        inv, singular = inverse3(N, singular_below)
        x = (inv @ g[..., None])[..., 0]
        x[singular] = np.nan
        return x, singular
    return _cholesky_solve(N, g, singular_below)


def _cholesky_solve(N: np.ndarray, g: np.ndarray, singular_below: float):
    """`solve_spd` for small k by a Cholesky factorization written out over (B,) arrays (LAPACK's per-matrix
    overhead dominates at k = 4): Jacobi scaling, pivots, the scaled determinant as their product."""
    k = N.shape[-1]
    diag = np.einsum("bii->bi", N)
    ok = (diag > 0).all(axis=1) & np.isfinite(N).all(axis=(1, 2))
    d = np.sqrt(np.where(diag > 0, diag, 1.0))
    L = [[None] * k for _ in range(k)]
    det = np.ones(N.shape[0])
    for j in range(k):
        s = N[:, j, j] / (d[:, j] * d[:, j])
        for m in range(j):
            s = s - L[j][m] * L[j][m]
        ok &= s > 0
        s = np.where(s > 0, s, 1.0)
        det *= s
        L[j][j] = ljj = np.sqrt(s)
        for i in range(j + 1, k):
            t = N[:, i, j] / (d[:, i] * d[:, j])
            for m in range(j):
                t = t - L[i][m] * L[j][m]
            L[i][j] = t / ljj
    singular = ~(ok & (det > singular_below))
    b = g / d
    y = [None] * k
    for i in range(k):
        t = b[:, i]
        for m in range(i):
            t = t - L[i][m] * y[m]
        y[i] = t / L[i][i]
    x = [None] * k
    for i in range(k - 1, -1, -1):
        t = y[i]
        for m in range(i + 1, k):
            t = t - L[m][i] * x[m]
        x[i] = t / L[i][i]
    out = np.stack(x, axis=1) / d
    out[singular] = np.nan
    return out, singular


def cofactors3(N6, singular_below: float = SINGULAR_DET):
    """The inverse of symmetric 3x3 matrices given as their six entries N00 N01 N02 N11 N12 N22 (each an array
    of any one shape), by cofactors: the six entries of the inverse in the same order (NaN where singular),
    the determinant and the `solve_spd` singular flag (the Jacobi-scaled determinant det / (N00 N11 N22) below
    singular_below, or a non-positive diagonal). The one 3x3 inverse of the batched kernels."""
    a, b, c, e, f, i = N6
    A0, B0, C0 = e * i - f * f, c * f - b * i, b * f - c * e
    det = a * A0 + b * B0 + c * C0
    with np.errstate(divide="ignore", invalid="ignore"):
        singular = ~((a > 0) & (e > 0) & (i > 0) & (det / (a * e * i) > singular_below))
        inv = [x / det for x in (A0, B0, C0, a * i - c * c, b * c - a * f, a * e - b * b)]
    if singular.any():
        inv = [np.where(singular, np.nan, x) for x in inv]
    return inv, det, singular


#: the entry of the six (N00 N01 N02 N11 N12 N22) holding (row, column) of a symmetric 3x3 matrix
FULL3 = ((0, 1, 2), (1, 3, 4), (2, 4, 5))
#: the six unique entries (c, d) of a symmetric 3x3 matrix, in the order N00 N01 N02 N11 N12 N22
PAIRS = ((0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2))


def full3(N6) -> np.ndarray:
    """(B,3,3) symmetric matrices from their six entries (each (B,))."""
    return np.stack([N6[k] for row in FULL3 for k in row], axis=-1).reshape(-1, 3, 3)


def inverse3(N: np.ndarray, singular_below: float = SINGULAR_DET):
    """Inverses (B,3,3) of symmetric 3x3 N (`cofactors3`), and the `solve_spd` singular flag (B,). Singular
    ones are NaN."""
    inv, _, singular = cofactors3([N[:, r, c] for r, c in PAIRS], singular_below)
    return full3(inv), singular


def condition_numbers(N: np.ndarray) -> np.ndarray:
    """(B,) 2-norm condition numbers of design matrices A from their normal matrices N = A^T A (B,k,k):
    sqrt(largest / smallest eigenvalue); inf when singular. Through N, values beyond ~1e7 are only indicative
    (rounding); degeneracy is decided by `solve_spd`'s criterion, not by this number."""
    good = np.isfinite(N).all(axis=(1, 2))
    ev = np.linalg.eigvalsh(np.where(good[:, None, None], N, 0.0))
    with np.errstate(divide="ignore", invalid="ignore"):
        c = np.sqrt(ev[:, -1] / ev[:, 0])
    c = np.where(ev[:, 0] > 0, c, np.inf)
    return np.where(good, c, np.nan)
