"""Every estimator for one problem, written without the batch bookkeeping (masks, index sets, frozen
problems), so that `solve()` costs a few dozen small numpy calls per iteration instead of a few hundred.

Each function is the batched kernel's algorithm step by step (same start values, steps, stopping rules,
degeneracy criterion and final quantities); tests check that `solve` and `solve_batch` agree.
"""

from __future__ import annotations

import math

import numpy as np

from pipeline.solve import correlated as _correlated
from pipeline.solve import iterate as _iterate
from pipeline.solve.estimate import Status
from pipeline.solve.least_squares import NORMALIZED_SINGULAR_DET
from pipeline.solve.mle import (
    _Q_GRID,
    CAUCHY_C,
    HUBER_C,
    VCE_MAX_ROUNDS,
    VCE_TOL,
    _cep_table,
    _rho_and_weight,
)
from pipeline.solve.observations import Sigma
from pipeline.solve.stacked import SINGULAR_DET, Stacked

# ---- small dense algebra on Python floats (the sizes are 3 and 4) --------------------------------------------

try:  # numpy.linalg.eigh/eigvalsh without their per-call wrapping (type checks, errstate): the same LAPACK call
    from numpy.linalg import _umath_linalg

    def _eigh(a: np.ndarray):
        return _umath_linalg.eigh_lo(a, signature="d->dd")

    def _eigvalsh(a: np.ndarray):
        return _umath_linalg.eigvalsh_lo(a, signature="d->d")

    def _solve(a: np.ndarray, b: np.ndarray):
        return _umath_linalg.solve(a, b, signature="dd->d")
except (ImportError, AttributeError):  # pragma: no cover - other numpy layouts
    _eigh, _eigvalsh, _solve = np.linalg.eigh, np.linalg.eigvalsh, np.linalg.solve


def camera_centres(M: np.ndarray, p4: np.ndarray) -> np.ndarray:
    """(k,3) camera centres C = -M^-1 p4 of (k,3,3) M and (k,3) p4 (one LAPACK call)."""
    return -_solve(M, p4[:, :, None])[:, :, 0]


def spd_solve(N: np.ndarray, g: np.ndarray, singular_below: float = SINGULAR_DET):
    """(x (k,), singular) for symmetric N (k,k): Jacobi scaling, Cholesky, and the criterion of
    `stacked.solve_spd` (the scaled determinant, the product of the squared Cholesky pivots)."""
    A = N.tolist()
    b = g.tolist()
    k = len(b)
    if k == 3:
        return _solve3(A, b, singular_below)
    x = _chol_solve(A, b, singular_below)
    return (None, True) if x is None else (np.array(x), False)


def _solve3(A, b, singular_below):
    """Cramer's rule for symmetric 3x3 (nested lists); det / (a e i) is the Jacobi-scaled determinant."""
    (a, bb, c), (_, e, f), (_, _, i) = A
    if not (a > 0 and e > 0 and i > 0) or not all(map(math.isfinite, (a, bb, c, e, f, i))):
        return None, True
    A0, B0, C0 = e * i - f * f, c * f - bb * i, bb * f - c * e
    det = a * A0 + bb * B0 + c * C0
    if not det / (a * e * i) > singular_below:
        return None, True
    E0, F0, I0 = a * i - c * c, bb * c - a * f, a * e - bb * bb
    g0, g1, g2 = b
    return np.array([(A0 * g0 + B0 * g1 + C0 * g2) / det, (B0 * g0 + E0 * g1 + F0 * g2) / det,
                     (C0 * g0 + F0 * g1 + I0 * g2) / det]), False


def inv3(N: np.ndarray):
    """(inverse (3,3), singular) of a symmetric 3x3 N with the `solve_spd` criterion."""
    (a, b, c), (_, e, f), (_, _, i) = N.tolist()
    if not (a > 0 and e > 0 and i > 0) or not all(map(math.isfinite, (a, b, c, e, f, i))):
        return np.full((3, 3), np.nan), True
    A, Bc, C = e * i - f * f, c * f - b * i, b * f - c * e
    det = a * A + b * Bc + c * C
    if not det / (a * e * i) > SINGULAR_DET:
        return np.full((3, 3), np.nan), True
    E, F, I = a * i - c * c, b * c - a * f, a * e - b * b
    return np.array([[A, Bc, C], [Bc, E, F], [C, F, I]]) / det, False


def condition(N: np.ndarray) -> float:
    """cond of the design matrix from its normal matrix, as `stacked.condition_numbers`."""
    if not np.isfinite(N).all():
        return math.nan
    ev = _eigvalsh(N).tolist()
    return math.sqrt(ev[-1] / ev[0]) if ev[0] > 0 else math.inf


def _finite(x: np.ndarray) -> bool:
    return all(map(math.isfinite, x.tolist()))


# ---- the measurement models for one problem ------------------------------------------------------------------

class Frames:
    """One problem's frames with a pixel and frames with a range, as dense arrays."""

    def __init__(self, st: Stacked):
        self.st = st
        hp, hr = st.has_pix[0], st.has_range[0]
        n = hp.size
        # frames in use: a slice (views, no copies) when all of them are, else their indices
        self.n_pix, self.n_rng = int(np.count_nonzero(hp)), int(np.count_nonzero(hr))
        self.pix_f = slice(None) if self.n_pix == n else np.flatnonzero(hp)
        self.rng_f = slice(None) if self.n_rng == n else np.flatnonzero(hr)
        self.Mp = st.M[0, self.pix_f]
        self.M12, self.M3 = self.Mp[:, :2, :], self.Mp[:, 2:3, :]
        self.p4 = st.p4[0, self.pix_f]
        self._M2d = self.Mp.reshape(-1, 3)  # rows m1 m2 m3 of every frame: q = M2d X + p4 in one gemv
        self._p4f = self.p4.ravel()
        self.pix = st.pix[0, self.pix_f]
        self._AB0 = None  # `both4`'s constants, made at its first call
        self.S = st.platform_m[0, self.rng_f]
        self.d = st.range_m[0, self.rng_f]
        self.npix = 2 * self.n_pix
        self.centre = np.add.reduce(st.platform_m[0], axis=0) / n  # = mean(axis=0), without its wrapper
        # signed metric depth of X in the cameras with a pixel = m3s X + p4s (`Stacked.depths`)
        k = st.depth_sign()[0, self.pix_f] / np.sqrt(st._gram()[0, self.pix_f, 2, 2])
        self.m3s = self.Mp[:, 2, :] * k[:, None]
        self.p4s = self.p4[:, 2] * k

    @classmethod
    def of(cls, st: Stacked) -> Frames:
        """The Frames of a one-problem Stacked, made once and kept on it."""
        fr = st.__dict__.get("_frames")
        if fr is None:
            fr = st.__dict__["_frames"] = cls(st)
        return fr

    def depths(self, X: np.ndarray) -> np.ndarray:
        """(k,) signed depth in metres of X in each camera with a pixel."""
        return self.m3s @ X + self.p4s

    def pixel(self, X: np.ndarray):
        """J (2k,3), r (2k,) of the k frames with a pixel (rows u1 v1 u2 ...), as `stacked.pixel_model`."""
        q = (self._M2d @ X + self._p4f).reshape(-1, 3)
        w = q[:, 2:3]
        uv = q[:, :2] / w
        return ((self.M12 - uv[..., None] * self.M3) / w[..., None]).reshape(-1, 3), (self.pix - uv).ravel()

    def range(self, X: np.ndarray):
        """J (k,3), r (k,) of the k frames with a range, as `stacked.range_model`."""
        diff = X - self.S
        dist = np.sqrt((diff * diff).sum(axis=1))
        return diff / dist[:, None], self.d - dist

    def both(self, X: np.ndarray):
        """J (2k+l,3), r (2k+l,): `pixel` rows then `range` rows (views of `both4`)."""
        A = self.both4(X)
        return A[:, :3], A[:, 3]

    def both4(self, X: np.ndarray) -> np.ndarray:
        """[J | r] (2k+l, 4) of `pixel` rows then `range` rows, written into one array (the same arithmetic as
        `pixel` and `range`, without concatenation)."""
        npix, k = self.npix, self.n_pix
        A = np.empty((npix + self.n_rng, 4))
        q = (self._M2d @ X + self._p4f).reshape(-1, 3)
        w = q[:, 2:3]
        uv = q[:, :2] / w
        AB0 = self._AB0
        if AB0 is None:  # [m1 u; m2 v] and [m3 1] per frame: [m - u m3 | u_obs - u] of both rows in one broadcast
            AB0 = self._AB0 = (np.concatenate((self.M12, self.pix[:, :, None]), axis=2),
                               np.concatenate((self.M3, np.ones((k, 1, 1))), axis=2))
        Ap = A[:npix].reshape(k, 2, 4)
        np.subtract(AB0[0], uv[..., None] * AB0[1], out=Ap)  # uv * 1 is uv: the residual is pix - uv exactly
        Jp = Ap[..., :3]
        np.divide(Jp, w[..., None], out=Jp)
        diff = np.subtract(X, self.S, out=A[npix:, :3])
        dist = np.sqrt((diff * diff).sum(axis=1))
        np.divide(diff, dist[:, None], out=diff)
        np.subtract(self.d, dist, out=A[npix:, 3])
        return A

    @property
    def focal_px(self) -> np.ndarray:
        """(k,2) focal lengths fx, fy of the frames with a pixel (`Stacked.focal_px`)."""
        f = self.__dict__.get("_focal")
        if f is None:
            g = self.st._gram()[0, self.pix_f].reshape(-1, 9)
            g33 = g[:, 8:9]
            # columns (g00, g11) and (g02, g12) as strided views: no fancy-index copies
            f = np.multiply(g[:, 0:5:4], g33)
            f -= g[:, 2:6:3] ** 2
            f = self.__dict__["_focal"] = np.sqrt(np.maximum(f, 0.0, out=f), out=f) / g33
        return f

    def bound(self, X0: np.ndarray) -> float:
        """The divergence bound of `iterate.iterate` for the start X0."""
        s = np.asarray(X0 if _finite(X0) else self.centre) - self.st.platform_m[0]
        scale = math.sqrt(float((s * s).sum(axis=1).max()))
        return _iterate.DIVERGENCE_FACTOR * (max(scale, 1.0) if math.isfinite(scale) else 1.0)


# ---- closed forms ---------------------------------------------------------------------------------------------

def dlt_one(fr: Frames, with_condition: bool = False):
    """`linear.dlt` for one problem: X (3,), status, cond (NaN unless with_condition)."""
    st = fr.st
    if fr.n_pix < 2:
        return np.full(3, np.nan), Status.DEGENERATE, math.inf
    c = fr.centre
    dev = st.platform_m[0] - c
    spread = math.sqrt(float((dev * dev).sum()) / st.n)
    sc = spread if spread > 1.0 else 1.0
    Pp = np.empty((fr.n_pix, 3, 4))
    np.multiply(fr.Mp, sc, out=Pp[:, :, :3])
    np.add(fr.Mp @ c, fr.p4, out=Pp[:, :, 3])
    A = (fr.pix[:, :, None] * Pp[:, 2:3, :] - Pp[:, :2, :]).reshape(-1, 4)
    norm = np.sqrt(np.add.reduce(A * A, axis=1))
    if float(np.minimum.reduce(norm)) > 0:
        A /= norm[:, None]
    else:
        A = A / np.where(norm > 0, norm, 1.0)[:, None]
    evals, evecs = _eigh(A.T @ A)  # one LAPACK call; the batch's inverse iteration finds the same vector
    x0, x1, x2, x3 = evecs[:, 0].tolist()
    cond = math.nan
    if with_condition:
        _, e1, _, e3 = evals.tolist()
        cond = math.sqrt(e3 / e1) if e1 > 0 else math.inf
    if not abs(x3) > 1e-12 * math.sqrt(x0 * x0 + x1 * x1 + x2 * x2):
        return np.full(3, np.nan), Status.DEGENERATE, cond
    c0, c1, c2 = c.tolist()
    return np.array((c0 + sc * x0 / x3, c1 + sc * x1 / x3, c2 + sc * x2 / x3)), Status.CLOSED_FORM, cond


def los_one(fr: Frames):
    """`linear.los` for one problem: X (3,), status, points (n,3), oracle error."""
    st = fr.st
    n = st.n
    valid = np.flatnonzero(st.has_pix[0] & st.has_range[0])
    pts = np.full((n, 3), np.nan)
    if valid.size == 0:
        return np.full(3, np.nan), Status.DEGENERATE, pts, math.nan
    M = st.M[0, valid]
    Minv = np.linalg.inv(M)
    C = -(Minv @ st.p4[0, valid][:, :, None])[:, :, 0]
    xh = np.concatenate((st.pix[0, valid], np.ones((valid.size, 1))), axis=1)
    a = (Minv @ xh[:, :, None])[:, :, 0] * st.depth_sign()[0, valid][:, None]
    a /= np.sqrt((a * a).sum(axis=1))[:, None]
    cs = C - st.platform_m[0, valid]
    b = (a * cs).sum(axis=1)
    disc = b * b - ((cs * cs).sum(axis=1) - st.range_m[0, valid] ** 2)
    t = -b + np.sqrt(np.maximum(disc, 0.0))
    p = C + t[:, None] * a
    pts[valid] = p
    oracle = math.nan
    if st.truth_m is not None:
        e = p - st.truth_m[0]
        oracle = math.sqrt(float((e * e).sum(axis=1).min()))
    return np.median(p, axis=0), Status.CLOSED_FORM, pts, oracle


# ---- Gauss-Newton family --------------------------------------------------------------------------------------

def _iterate_one(X0, init_status, step, tol_m, max_iterations, bound, centre):
    """`iterate.iterate` for one problem: X (last finite iterate), iterations, status, extras."""
    extras: dict = {}
    if (init_status is not None and init_status in (Status.DIVERGED, Status.DEGENERATE)) or not _finite(X0):
        return X0.copy(), 0, (Status.DIVERGED if init_status == Status.DIVERGED else Status.DEGENERATE), extras
    # the iterate and the step as Python floats (the same additions as X + dX); an array only for the model
    X = X0.copy()
    x0, x1, x2 = X0.tolist()
    c0, c1, c2 = centre.tolist()
    status = Status.MAX_ITERATIONS
    it = 0
    for _ in range(max_iterations):
        dX, singular, ex = step(X)
        extras.update(ex)
        it += 1
        if singular:
            status = Status.DEGENERATE
            break
        d0, d1, d2 = dX
        n0, n1, n2 = x0 + d0, x1 + d1, x2 + d2
        finite = math.isfinite(n0) and math.isfinite(n1) and math.isfinite(n2)
        if finite:
            x0, x1, x2 = n0, n1, n2
            X = np.array((n0, n1, n2))
        if not finite or math.sqrt((n0 - c0) ** 2 + (n1 - c1) ** 2 + (n2 - c2) ** 2) > bound:
            status = Status.DIVERGED
            break
        if math.sqrt(d0 * d0 + d1 * d1 + d2 * d2) <= tol_m:
            status = Status.CONVERGED
            break
    return X, it, status, extras


def _finish_one(X, status, N, N_geometry=None):
    """`iterate.finish` for one problem: (X or NaN, status, cond)."""
    finite = _finite(X)
    cond = condition(N) if finite else math.nan
    G = N if N_geometry is None else N_geometry
    if finite and spd_solve(G, np.zeros(G.shape[0]))[1]:
        status = Status.DEGENERATE
    if status in (Status.DIVERGED, Status.DEGENERATE):
        X = np.full(3, np.nan)
    return X, status, cond


def gn_one(fr: Frames, model, X0, init_status, tol_m, max_iterations):
    """vision / range / fusion-raw: plain Gauss-Newton on model(X) -> (J, r). Returns X, it, status, cond."""
    def step(X):
        J, r = model(X)
        JT = J.T
        dX, singular = spd_solve(JT @ J, JT @ r)
        return (None if singular else dX.tolist()), singular, {}

    X, it, status, _ = _iterate_one(X0, init_status, step, tol_m, max_iterations, fr.bound(X0), fr.centre)
    if _finite(X):
        J, _ = model(X)
        N = J.T @ J
    else:
        N = np.full((3, 3), np.nan)
    X, status, cond = _finish_one(X, status, N)
    return X, it, status, cond


def _chol_solve(A: list, b: list, singular_below: float):
    """`spd_solve` on nested lists of Python floats: x as a list, or None when singular."""
    k = len(b)
    if k == 4:
        return _chol4(A, b, singular_below)
    d = []
    for i in range(k):
        a = A[i][i]
        if not (a > 0 and math.isfinite(a)):
            return None
        d.append(math.sqrt(a))
    L = [[0.0] * k for _ in range(k)]
    det = 1.0
    for j in range(k):
        Lj = L[j]
        s = A[j][j] / (d[j] * d[j])
        for m in range(j):
            s -= Lj[m] * Lj[m]
        if not s > 0:
            return None
        det *= s
        Lj[j] = ljj = math.sqrt(s)
        for i in range(j + 1, k):
            Li = L[i]
            t = A[i][j] / (d[i] * d[j])
            for m in range(j):
                t -= Li[m] * Lj[m]
            Li[j] = t / ljj
    if not det > singular_below:
        return None
    y = [0.0] * k
    for i in range(k):
        Li = L[i]
        t = b[i] / d[i]
        for m in range(i):
            t -= Li[m] * y[m]
        y[i] = t / Li[i]
    x = [0.0] * k
    for i in range(k - 1, -1, -1):
        t = y[i]
        for m in range(i + 1, k):
            t -= L[m][i] * x[m]
        x[i] = t / L[i][i]
    return [x[i] / d[i] for i in range(k)]


def _chol4(A: list, b: list, singular_below: float):
    """`_chol_solve` for 4x4, written out (upper triangle of the symmetric A read)."""
    (a00, a01, a02, a03), (_, a11, a12, a13), (_, _, a22, a23), (_, _, _, a33) = A
    if not (a00 > 0 and a11 > 0 and a22 > 0 and a33 > 0 and math.isfinite(a00 + a11 + a22 + a33)):
        return None
    d0, d1, d2, d3 = math.sqrt(a00), math.sqrt(a11), math.sqrt(a22), math.sqrt(a33)
    s0 = a00 / (d0 * d0)
    if not s0 > 0:
        return None
    l00 = math.sqrt(s0)
    l10, l20, l30 = a01 / (d1 * d0) / l00, a02 / (d2 * d0) / l00, a03 / (d3 * d0) / l00
    s1 = a11 / (d1 * d1) - l10 * l10
    if not s1 > 0:
        return None
    l11 = math.sqrt(s1)
    l21, l31 = (a12 / (d2 * d1) - l20 * l10) / l11, (a13 / (d3 * d1) - l30 * l10) / l11
    s2 = a22 / (d2 * d2) - (l20 * l20 + l21 * l21)
    if not s2 > 0:
        return None
    l22 = math.sqrt(s2)
    l32 = (a23 / (d3 * d2) - (l30 * l20 + l31 * l21)) / l22
    s3 = a33 / (d3 * d3) - (l30 * l30 + l31 * l31 + l32 * l32)
    if not (s3 > 0 and s0 * s1 * s2 * s3 > singular_below):
        return None
    l33 = math.sqrt(s3)
    b0, b1, b2, b3 = b
    y0 = b0 / d0 / l00
    y1 = (b1 / d1 - l10 * y0) / l11
    y2 = (b2 / d2 - (l20 * y0 + l21 * y1)) / l22
    y3 = (b3 / d3 - (l30 * y0 + l31 * y1 + l32 * y2)) / l33
    x3 = y3 / l33
    x2 = (y2 - l32 * x3) / l22
    x1 = (y1 - (l21 * x2 + l31 * x3)) / l11
    x0 = (y0 - (l10 * x1 + l20 * x2 + l30 * x3)) / l00
    return [x0 / d0, x1 / d1, x2 / d2, x3 / d3]


def normalized_normal_one(fr: Frames, X):
    """`least_squares.normalized_normal_equations` for one problem, as Python floats: N = T^T T (4x4 nested
    list), g = T^T dPhi, dd = dPhi^T dPhi and the rows in use, from the Gram matrix of each block's [J | r]
    and its column sums (T's rows are [J, -L]/S and dPhi's (r - L)/S, L the block's minimum residual, S its
    spread)."""
    A = fr.both4(X)
    # the sums of the two blocks' terms in the order of a loop over the blocks starting from zeros (written
    # out: the same floating-point operations, without the loops)
    n00 = n01 = n02 = n03 = n11 = n12 = n13 = n22 = n23 = n33 = 0.0
    g0 = g1 = g2 = g3 = dd = 0.0
    npix = fr.npix
    if 0 < npix < A.shape[0]:  # both blocks: their minima and maxima (exact) in one call each
        cuts = (0, npix)
        los = np.minimum.reduceat(A[:, 3], cuts).tolist()
        his = np.maximum.reduceat(A[:, 3], cuts).tolist()
    else:
        los = his = None
    for b, blk in enumerate((A[:npix], A[npix:])):
        cnt = blk.shape[0]
        if cnt == 0:
            continue
        if los is None:
            r = blk[:, 3]
            lo = float(np.minimum.reduce(r))
            span = float(np.maximum.reduce(r)) - lo
        else:
            lo = los[b]
            span = his[b] - lo
        # column sums by add.reduce per block (add.reduceat sums in another order)
        S0, S1, S2, S3 = np.add.reduce(blk).tolist()
        if not (span > 0 and math.isfinite(span)):
            span = 1.0
        s2 = 1.0 / (span * span)
        (G00, G01, G02, G03), (_, G11, G12, G13), (_, _, G22, G23), (_, _, _, G33) = (blk.T @ blk).tolist()
        nlo = -lo
        n00 += G00 * s2
        n01 += G01 * s2
        n02 += G02 * s2
        n03 += nlo * S0 * s2
        g0 += (G03 - lo * S0) * s2
        n11 += G11 * s2
        n12 += G12 * s2
        n13 += nlo * S1 * s2
        g1 += (G13 - lo * S1) * s2
        n22 += G22 * s2
        n23 += nlo * S2 * s2
        g2 += (G23 - lo * S2) * s2
        n33 += lo * lo * cnt * s2
        g3 += nlo * (S3 - lo * cnt) * s2
        dd += (G33 - 2 * lo * S3 + lo * lo * cnt) * s2
    N = [[n00, n01, n02, n03], [n01, n11, n12, n13], [n02, n12, n22, n23], [n03, n13, n23, n33]]
    return N, [g0, g1, g2, g3], dd, A.shape[0]


def _solve_augmented_one(N, g, k):
    """`least_squares._solve_augmented` for one problem on nested lists: beta (list of 4) or None."""
    if k:
        (a00, a01, a02, a03), (a10, a11, a12, a13), (a20, a21, a22, a23), (a30, a31, a32, a33) = N
        Nk = [[a00 + k, a01 + 0.0, a02 + 0.0, a03 + 0.0], [a10 + 0.0, a11 + k, a12 + 0.0, a13 + 0.0],
              [a20 + 0.0, a21 + 0.0, a22 + k, a23 + 0.0], [a30 + 0.0, a31 + 0.0, a32 + 0.0, a33 + k]]
    else:
        Nk = N
    beta = _chol_solve(Nk, g, NORMALIZED_SINGULAR_DET)
    if beta is None:
        dX = _chol_solve([row[:3] for row in Nk[:3]], [g[i] - N[i][3] for i in range(3)], NORMALIZED_SINGULAR_DET)
        beta = None if dX is None else [*dX, 1.0]
    return beta


def _scaled(N, g):
    """Columns scaled to unit length (the textbook HKB's standardized design): N / (d d^T), g / d, d."""
    d = [math.sqrt(N[i][i]) if N[i][i] > 0 else 1.0 for i in range(4)]
    return [[N[i][j] / (d[i] * d[j]) for j in range(4)] for i in range(4)], [g[i] / d[i] for i in range(4)], d


def _hkb_one(N, g, dd, rows, variant):
    """`least_squares.hkb_k` for one problem (nested lists)."""
    p = 4
    if variant == "textbook":
        N, g, _ = _scaled(N, g)
    beta = _chol_solve(N, g, SINGULAR_DET)
    if beta is None:
        return 0.0
    b0, b1, b2, b3 = beta
    rss = max(dd - (g[0] * b0 + g[1] * b1 + g[2] * b2 + g[3] * b3), 0.0)  # sum() from 0: the same additions
    dof = rows - p
    s2 = rss / dof if dof > 0 else 0.0
    if variant == "textbook":
        denom = b0 * b0 + b1 * b1 + b2 * b2 + b3 * b3
    else:
        (a00, a01, a02, a03), (a10, a11, a12, a13), (a20, a21, a22, a23), (a30, a31, a32, a33) = N
        denom = (b0 * a00 * b0 + b0 * a01 * b1 + b0 * a02 * b2 + b0 * a03 * b3
                 + b1 * a10 * b0 + b1 * a11 * b1 + b1 * a12 * b2 + b1 * a13 * b3
                 + b2 * a20 * b0 + b2 * a21 * b1 + b2 * a22 * b2 + b2 * a23 * b3
                 + b3 * a30 * b0 + b3 * a31 * b1 + b3 * a32 * b2 + b3 * a33 * b3)
    k = p * s2 / denom if denom != 0 else math.inf
    return k if math.isfinite(k) else 0.0


def normalized_one(fr: Frames, X0, init_status, tol_m, max_iterations, k=None, hkb=None):
    """`least_squares.normalized_fusion` for one problem: X, it, status, cond, extras {k, augmented}."""
    def step(X):
        N, g, dd, rows = normalized_normal_one(fr, X)
        if hkb is None:
            kk = 0.0 if k is None else float(k)
            beta = _solve_augmented_one(N, g, kk)
        else:
            kk = _hkb_one(N, g, dd, rows, hkb)
            if hkb == "textbook":
                Ns, gs, d = _scaled(N, g)
                gamma = _solve_augmented_one(Ns, gs, kk)
                beta = None if gamma is None else [gamma[i] / d[i] for i in range(4)]
            else:
                beta = _solve_augmented_one(N, g, kk)
        if beta is None:
            return None, True, {"k": kk, "augmented": math.nan}
        return beta[:3], False, {"k": kk, "augmented": beta[3]}

    X, it, status, extras = _iterate_one(X0, init_status, step, tol_m, max_iterations, fr.bound(X0), fr.centre)
    if _finite(X):
        N = np.array(normalized_normal_one(fr, X)[0])
        J, _ = fr.both(X)
        Ng = J.T @ J
    else:
        N, Ng = np.full((4, 4), np.nan), np.full((3, 3), np.nan)
    X, status, cond = _finish_one(X, status, N, Ng)
    return X, it, status, cond, extras


# ---- mle ------------------------------------------------------------------------------------------------------

def mle_one(fr: Frames, X0: np.ndarray, sigma: Sigma, robust: str | None, vce: bool, tol_m: float,
            max_iterations: int, init_status):
    """`mle.mle` for one problem. Returns X (3,), iterations, status, cond, covariance (3,3), extras dict of
    floats (the keys of `mle.mle`) and the final residuals (pixels u v interleaved, then ranges).

    Works on the standardized rows Aw = [J | r] / sd (whitened with correlation times): their weighted Gram
    matrix holds the normal matrix, the gradient and the cost in one product; the 3x3 steps are solved in
    closed form on Python floats.
    """
    npix = fr.npix
    status = Status.MAX_ITERATIONS
    X = np.array(X0, dtype=np.float64)
    bad = (init_status is not None and init_status in (Status.DIVERGED, Status.DEGENERATE)) or not _finite(X)
    if bad:
        status = Status.DIVERGED if init_status == Status.DIVERGED else Status.DEGENERATE
        X = np.zeros(3)
    W = None
    if sigma.correlated:
        C = _covariance_one(fr, X, sigma)
        if robust is not None and not bad and (C != np.diag(np.diag(C))).any():
            return _mle_correlated_robust(fr, X, C, robust, vce, tol_m, max_iterations, init_status)
        W = _correlated.inflated_whitening(C, np.ones(len(C)))
    if W is None:
        var0 = _base_variances_one(fr, X, sigma)
        model = fr.both4
    else:  # generalized least squares: whitened rows have unit variance (`correlated`)
        var0 = np.ones(W.shape[0])

        def model(X):
            return W @ fr.both4(X)
    huber = robust == "huber"

    def evaluate(X, isd):
        """Aw (m,4), the cost, the IRLS Gram matrix [N g; g^T e'We] as nested lists, |e| (Huber) at X."""
        Aw = model(X) * isd
        if robust is None:
            G = (Aw.T @ Aw).tolist()
            return Aw, 0.5 * G[3][3], G, None
        if huber:  # cost 0.5 sum(w e^2) + 0.5 c sum(max(|e| - c, 0)), w = c / max(|e|, c) (`mle._rho_and_weight`)
            a = np.abs(Aw[:, 3])
            mx = np.maximum(a, HUBER_C)
            wr = HUBER_C / mx
            # one product for the Newton matrix (weights rho'' = w inside c, w/1000 outside: `mle._curvature`)
            # and the IRLS gradient and cost (weights w): [N_newton g; . sum w e^2]
            Y = Aw * wr[:, None]
            Y[:, :3] *= np.where(a <= HUBER_C, 1.0, 0.001)[:, None]
            G = (Aw.T @ Y).tolist()
            return Aw, 0.5 * (G[3][3] + HUBER_C * float(np.add.reduce(mx - HUBER_C))), G, (a, wr)
        e = Aw[:, 3]
        wr = _rho_and_weight(e, robust)[1]
        G = (Aw.T @ (Aw * wr[:, None])).tolist()
        return Aw, _cost(e, robust), G, (e, wr)

    vf = [1.0, 1.0]
    m = var0.size
    var = var0
    isd = (1.0 / np.sqrt(var))[:, None]
    Aw, cost, G, aux = evaluate(X, isd)
    bound = fr.bound(X0)
    c0, c1, c2 = fr.centre.tolist()
    iterations = 0
    lam = 0.0
    vce_rounds = 0
    newton_ok = True
    for _ in range(0 if bad else max_iterations):
        g0, g1, g2 = G[0][3], G[1][3], G[2][3]
        if huber and newton_ok:  # Newton: the loss's curvature rho'' in the normal matrix (in G already)
            (a, b, c, _), (_, d, f, _), (_, _, i, _), _ = G
        elif huber:  # the IRLS normal matrix
            Jw = Aw[:, :3]
            (a, b, c), (_, d, f), (_, _, i) = ((Jw.T * aux[1]) @ Jw).tolist()
        elif robust is not None and newton_ok:
            Jw = Aw[:, :3]
            curv = _weight_curvature(aux[0], robust)[1]
            (a, b, c), (_, d, f), (_, _, i) = ((Jw.T * curv) @ Jw).tolist()
        else:
            (a, b, c, _), (_, d, f, _), (_, _, i, _), _ = G
        iterations += 1
        # N + lam diag(N), solved by Cramer's rule with the `stacked.solve_spd` criterion
        if lam:
            a, d, i = a + lam * a, d + lam * d, i + lam * i
        singular = True
        if a > 0 and d > 0 and i > 0 and math.isfinite(a + b + c + d + f + i):
            A0, B0, C0 = d * i - f * f, c * f - b * i, b * f - c * d
            det = a * A0 + b * B0 + c * C0
            if det / (a * d * i) > SINGULAR_DET:
                singular = False
                D0, E0, F0 = a * i - c * c, b * c - a * f, a * d - b * b
                dx0 = (A0 * g0 + B0 * g1 + C0 * g2) / det
                dx1 = (B0 * g0 + D0 * g1 + E0 * g2) / det
                dx2 = (C0 * g0 + E0 * g1 + F0 * g2) / det
        if singular:  # never 'small' (an infinite step): the geometry does not determine the target
            status = Status.DEGENERATE
            break
        x0, x1, x2 = X.tolist()
        n0, n1, n2 = x0 + dx0, x1 + dx1, x2 + dx2
        if not math.isfinite(n0 + n1 + n2) or math.sqrt((n0 - c0) ** 2 + (n1 - c1) ** 2 + (n2 - c2) ** 2) > bound:
            status = Status.DIVERGED
            break
        Xn = np.array((n0, n1, n2))
        trial = evaluate(Xn, isd)
        accept = trial[1] <= cost * (1 + 1e-12) + 1e-300
        if accept:
            X = Xn
            Aw, cost, G, aux = trial
            lam = 0.0 if lam / 10 < 1e-9 else lam / 10
            newton_ok = True
        elif robust is not None and newton_ok:
            newton_ok = False  # retry as the IRLS step before damping
        else:
            lam = 1e-4 if lam == 0 else lam * 10
        inner_done = math.sqrt(dx0 * dx0 + dx1 * dx1 + dx2 * dx2) <= tol_m or (not accept and lam > 1e12)
        if vce and inner_done:
            factors, usable = _vce_factors(Aw[:, :3], Aw[:, 3], npix, robust)
            more = [usable[k] and abs(factors[k] - 1) > VCE_TOL for k in (0, 1)]
            if any(more) and vce_rounds < VCE_MAX_ROUNDS:
                vf = [vf[k] * factors[k] if usable[k] else vf[k] for k in (0, 1)]
                vce_rounds += 1
                var = var0.copy()
                var[:npix] *= vf[0]
                var[npix:] *= vf[1]
                isd = (1.0 / np.sqrt(var))[:, None]
                Aw, cost, G, aux = evaluate(X, isd)
                lam = 0.0
                continue
        if inner_done:
            status = Status.CONVERGED
            break
    failed = status in (Status.DIVERGED, Status.DEGENERATE)
    # the IRLS weights at the final iterate (G holds the Newton matrix for Huber)
    N = (Aw[:, :3].T * aux[1]) @ Aw[:, :3] if huber else np.array(G)[:3, :3]
    e = Aw[:, 3]
    # the reported residuals are observed - predicted, not whitened
    resid = e / isd[:, 0] if W is None else fr.both4(X)[:, 3]
    cov, singular = inv3(N)
    cond = condition(N)
    if singular and not failed:
        status = Status.DEGENERATE
    failed = status in (Status.DIVERGED, Status.DEGENERATE)
    if failed:
        X = np.full(3, np.nan)
        cov = np.full((3, 3), np.nan)
        if not singular:
            cond = math.nan
    sigma0_sq = G[3][3] / (m - 3) if m > 3 else math.nan
    extras = {"variance_factor_pixel": vf[0], "variance_factor_range": vf[1], "sigma0_sq": sigma0_sq,
              "vce_rounds": vce_rounds}
    # inv3's inverse is symmetric by construction: 0.5 (cov + cov^T) would return it unchanged
    return X, iterations, status, cond, cov, extras, resid


def _mle_correlated_robust(fr: Frames, X0, C, robust, vce, tol_m, max_iterations, init_status):
    """Robust generalized least squares by iteratively reweighted least squares: every iteration takes the robust
    weights w_i = rho'(z)/z of the rows' marginal standardized residuals z_i = r_i / sqrt(C_ii) (C_ii times the
    variance factor of the row's group) at the current estimate, applies them as inflated variances C_ii / w_i
    of an independent gross error (`correlated.inflated_whitening`), and takes the Gauss-Newton step of the
    whitened problem. Stops when the step is below tol_m (then, with variance components, re-estimates them
    and continues while they change). Weights on the whitened residuals instead would mix a gross error of
    one frame into the rows of the next frames and let it drag the estimate."""
    npix, m = fr.npix, len(C)
    sd = np.sqrt(np.diag(C))
    bound = fr.bound(X0)
    centre = fr.centre
    vf = [1.0, 1.0]
    vce_rounds = 0

    def rows_scale(vf):
        return np.r_[np.full(npix, vf[0]), np.full(m - npix, vf[1])]

    scale = rows_scale(vf)
    X = np.array(X0, dtype=np.float64)
    A = fr.both4(X)
    status = Status.MAX_ITERATIONS
    it = 0
    for _ in range(max_iterations):
        w = _rho_and_weight(A[:, 3] / (sd * np.sqrt(scale)), robust)[1]
        Aw = _correlated.inflated_whiten(C, w, A) / np.sqrt(scale)[:, None]
        G = Aw.T @ Aw
        dX, singular = spd_solve(G[:3, :3], G[:3, 3])
        it += 1
        if singular:
            status = Status.DEGENERATE
            break
        Xn = X + dX
        if not _finite(Xn) or math.sqrt(float((Xn - centre) @ (Xn - centre))) > bound:
            status = Status.DIVERGED
            break
        X = Xn
        A = fr.both4(X)
        if math.sqrt(float(dX @ dX)) <= tol_m:
            if vce:
                w = _rho_and_weight(A[:, 3] / (sd * np.sqrt(scale)), robust)[1]
                Aw = _correlated.inflated_whiten(C, w, A) / np.sqrt(scale)[:, None]
                factors, usable = _vce_factors(Aw[:, :3], Aw[:, 3], npix, None)
                if any(usable[k] and abs(factors[k] - 1) > VCE_TOL for k in (0, 1)) and vce_rounds < VCE_MAX_ROUNDS:
                    vf = [vf[k] * factors[k] if usable[k] else vf[k] for k in (0, 1)]
                    vce_rounds += 1
                    scale = rows_scale(vf)
                    continue
            status = Status.CONVERGED
            break
    # covariance with the weights at the final estimate
    w = _rho_and_weight(A[:, 3] / (sd * np.sqrt(scale)), robust)[1]
    Aw = _correlated.inflated_whiten(C, w, A) / np.sqrt(scale)[:, None]
    N = Aw[:, :3].T @ Aw[:, :3]
    cov, singular = inv3(N)
    cond = condition(N)
    failed = status in (Status.DIVERGED, Status.DEGENERATE)
    if singular and not failed:
        status = Status.DEGENERATE
    resid = A[:, 3].copy()
    if status in (Status.DIVERGED, Status.DEGENERATE):
        X = np.full(3, np.nan)
        cov = np.full((3, 3), np.nan)
        if not singular:
            cond = math.nan
    e = Aw[:, 3]
    extras = {"variance_factor_pixel": vf[0], "variance_factor_range": vf[1],
              "sigma0_sq": float(e @ e) / (m - 3) if m > 3 else math.nan, "vce_rounds": vce_rounds}
    return X, it, status, cond, cov, extras, resid


def _covariance_one(fr: Frames, X0: np.ndarray, sigma: Sigma) -> np.ndarray:
    """`correlated.full_covariance` of the rows in use (interleaved), with the focal lengths and distances (at
    X0) of `_base_variances_one` and the frames' times in seconds."""
    st = fr.st
    n = st.n
    t_ns = st.t_ns[0] if st.t_ns is not None else np.arange(n, dtype=np.int64) * 1_000_000_000
    t_s = (t_ns - t_ns.min()).astype(np.float64) * 1e-9  # differences of int64 first: no rounding of epochs
    fxy = fr.focal_px
    diff = X0 - st.platform_m[0, fr.pix_f]
    D = np.sqrt((diff * diff).sum(axis=1))
    return _correlated.full_covariance(t_s[fr.pix_f], t_s[fr.rng_f], fxy[:, 0], fxy[:, 1], D, sigma)


def _base_variances_one(fr: Frames, X0: np.ndarray, sigma: Sigma) -> np.ndarray:
    """`mle.base_variances` of the rows in use (pixels u v interleaved, then ranges), one problem."""
    s_px = 1.0 if sigma.pixel_px is None else sigma.pixel_px
    s_r = 1.0 if sigma.range_m is None else sigma.range_m
    s_pos = 0.0 if sigma.position_m is None else sigma.position_m
    s_att = 0.0 if sigma.attitude_deg is None else math.radians(sigma.attitude_deg)
    var = np.empty(fr.npix + fr.n_rng)
    f2 = fr.focal_px ** 2
    if s_pos > 0:
        diff = X0 - fr.st.platform_m[0, fr.pix_f]
        D2 = np.add.reduce(diff * diff, axis=1)
        a2, p2 = s_att ** 2, s_pos ** 2
        # a few floats: a list is cheaper than the masks (0 < D2 < inf, i.e. finite and positive)
        ang2 = np.array([a2 + (p2 / v if 0.0 < v < math.inf else 0.0) for v in D2.tolist()])
        np.multiply(f2, ang2[:, None], out=var[:fr.npix].reshape(-1, 2))
    else:
        np.multiply(f2, s_att ** 2, out=var[:fr.npix].reshape(-1, 2))
    var[:fr.npix] += s_px ** 2
    var[fr.npix:] = s_r ** 2 + s_pos ** 2
    return np.where(var > 0, var, 1.0)


_CEP_LISTS: dict[float, list] = {}
_Q_STEPS = _Q_GRID.size - 1


def _interp_q(q: float, p: float) -> float:
    """np.interp(q, _Q_GRID, _cep_table(p)) on Python floats (the grid is j / 256, exact in binary), with
    numpy's formula slope * (q - x_j) + y_j, so bit-identical."""
    y = _CEP_LISTS.get(p)
    if y is None:
        y = _CEP_LISTS[p] = _cep_table(p).tolist()
    if not 0.0 <= q < 1.0:  # q = 1 (and the out-of-range and NaN cases): np.interp's own answer
        return float(np.interp(q, _Q_GRID, _cep_table(p)))
    j = int(q * _Q_STEPS)
    xj = j / _Q_STEPS
    if xj == q:
        return y[j]
    slope = (y[j + 1] - y[j]) / ((j + 1) / _Q_STEPS - xj)
    return slope * (q - xj) + y[j]


def summaries_one(cov: np.ndarray):
    """`mle` accuracy summaries of one (3,3) covariance: CEP50 and CEP90 (m, floats), the 1-sigma semi-axes
    (list of 3 floats, m, ascending) and the axes as columns (3,3); NaN when cov is not finite."""
    (a, b, _), (_, c, _), _ = rows = cov.tolist()
    if not all(map(math.isfinite, rows[0] + rows[1] + rows[2])):
        return math.nan, math.nan, [math.nan] * 3, np.full((3, 3), np.nan)
    ev, vec = _eigh(cov)
    half = math.sqrt(0.25 * (a - c) ** 2 + b * b)
    s1 = math.sqrt(max(0.5 * (a + c) + half, 0.0))
    s2 = math.sqrt(max(0.5 * (a + c) - half, 0.0))
    cep50, cep90 = (s1 * _interp_q(s2 / s1, p) if s1 > 0 else math.nan for p in (0.5, 0.9))
    return cep50, cep90, [math.sqrt(v if v > 0.0 else 0.0) for v in ev.tolist()], vec


def _weight_curvature(e: np.ndarray, robust: str):
    """The IRLS weight of `mle._rho_and_weight` and the Newton weight of `mle._curvature`."""
    if robust == "huber":
        a = np.abs(e)
        w = np.minimum(1.0, HUBER_C / np.maximum(a, 1e-300))
        return w, np.where(a <= HUBER_C, 1.0, 0.001 * w)
    z = (e / CAUCHY_C) ** 2
    w = 1.0 / (1.0 + z)
    return w, np.maximum((1.0 - z) * w * w, 0.001 * w)


def _cost(e: np.ndarray, robust: str | None) -> float:
    """sum of rho(e) of `mle._rho_and_weight`."""
    if robust is None:
        return 0.5 * float(e @ e)
    if robust == "huber":
        t = np.maximum(np.abs(e) - HUBER_C, 0.0)
        return 0.5 * (float(e @ e) - float(t @ t))
    return 0.5 * CAUCHY_C ** 2 * float(np.log1p((e / CAUCHY_C) ** 2).sum())


def _vce_factors(Jw, e, npix, robust):
    """`mle._vce_factors` on the standardized rows Jw = J / sd, e = r / sd."""
    wr = _rho_and_weight(e, robust)[1]
    Ninv, _ = inv3((Jw.T * wr) @ Jw)
    lev = wr * ((Jw @ Ninv) * Jw).sum(axis=1)
    q = wr * e * e
    out, usable = [1.0, 1.0], [False, False]
    for k, sl in ((0, slice(0, npix)), (1, slice(npix, None))):
        red = float((1.0 - lev[sl]).sum())
        if red >= 0.5:
            f = float(q[sl].sum()) / red
            if math.isfinite(f) and f > 0:
                out[k], usable[k] = f, True
    return out, usable
