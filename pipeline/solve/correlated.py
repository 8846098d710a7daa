"""Time-correlated telemetry errors for `mle` (generalized least squares) in O(n) (docs/solvers.md, "Time-correlated
attitude and position errors").

Per group of rows (u, v over the frames with a pixel, range over the ranged frames) C = R + G K G^T: R the white
variances, G the rows' gains of the Gauss-Markov states (one per frame and process, chained by their transitions
a_i = exp(-dt_i / tau), so K^-1 is tridiagonal). The states eliminate by Woodbury with A = K^-1 + G^T R^-1 G
banded (bandwidth = the number of processes): C^-1 y = R^-1 y - R^-1 G A^-1 G^T R^-1 y and log det C = log det R
+ log det A + log det K, by LAPACK's banded Cholesky; no n x n matrix. A robust weight w makes a row's variance
C_ii / w (only R changes), so a gross error in one frame does not leak into the others.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.linalg.lapack import dpbtrf as _pbtrf
from scipy.linalg.lapack import dpbtrs as _pbtrs

from pipeline.solve import iterate as _iterate
from pipeline.solve import mle as _mle
from pipeline.solve.iterate import start_status
from pipeline.solve.mle import VCE_MAX_ROUNDS, VCE_TOL
from pipeline.solve.stacked import Stacked, inverse3, pixel_model, range_model, solve_spd

#: 1 - a^2 floor of a transition (frames at equal times): keeps the chain's precision finite
_MIN_INNOVATION = 1e-10


@dataclass(frozen=True)
class Slip:
    """A tracker slip: the target's pixel off by a constant offset (u and v, each of prior sigma prior_px) over the
    frames of mask (n,) bool, integrated out like the boresight bias (a gain column on those u and v rows); the
    run was the likeliest of `runs` searched (its prior: one in that many)."""
    mask: np.ndarray
    prior_px: float
    runs: int


@dataclass
class Models:
    """K GLS residual models of one problem's rows in use (`rows_in_use`: npix pixel rows, u v interleaved, then
    the ranges), stacked over K (`problem_models`, `Models.concat`): per group u, v, range (rows (k,), gains
    (K,k,p) of p unit-variance Gauss-Markov states, the band template of A (K,p+1,kp) and K^-1's diagonal (K,k,p)
    (the parts of A that do not depend on the row weights), log det K (K,)); the marginal and white variances
    Cii, R0 (K,m); correlated (K,): some state has a nonzero transition (else C is diagonal); bias: per group the
    rows' gains (K,k) of a constant boresight bias of unit prior variance (zero: none; the range group's always).
    """
    groups: tuple
    Cii: np.ndarray
    R0: np.ndarray
    npix: int
    correlated: np.ndarray
    bias: tuple

    def take(self, idx: np.ndarray) -> Models:
        return Models(tuple((r, G[idx], ab[idx], dg[idx], li[idx]) for r, G, ab, dg, li in self.groups),
                      self.Cii[idx], self.R0[idx], self.npix, self.correlated[idx], tuple(b[idx] for b in self.bias))

    @staticmethod
    def concat(parts: list) -> Models:
        """The models of parts side by side; ValueError where they differ in their rows or states."""
        groups = []
        for gs in zip(*(md.groups for md in parts), strict=True):
            if any(g[1].shape[1:] != gs[0][1].shape[1:] or not np.array_equal(g[0], gs[0][0]) for g in gs):
                raise ValueError("the models differ in their rows or states")
            groups.append((gs[0][0], *(np.concatenate([g[j] for g in gs]) for j in range(1, 5))))
        cat = np.concatenate
        return Models(tuple(groups), cat([md.Cii for md in parts]), cat([md.R0 for md in parts]), parts[0].npix,
                      cat([md.correlated for md in parts]),
                      tuple(cat([md.bias[g] for md in parts]) for g in range(len(groups))))


def problem_models(st: Stacked, X0: np.ndarray, sigmas: list, bias_deg: list | None = None) -> Models:
    """The `Models` of one problem (B = 1) under the sigmas, with the focal lengths, the distances at X0 (3,) and
    the frames' times (frames with a pixel, ranged frames, each in time order). Unknown pixel / range sigmas count
    as 1 px / 1 m (variance components then scale them), like `mle.base_variances`; a part without a correlation
    time is white (on R); bias_deg (per sigma, None or 0: none): the prior sigma of a constant boresight bias
    (pixel offsets f * angle in u and v, as `mle`'s), or a `Slip` (that offset on its frames only). ValueError
    where the sigmas give different states."""
    t_ns = st.t_ns[0]
    t_s = (t_ns - t_ns.min()).astype(np.float64) * 1e-9  # differences of int64 first: no rounding of epochs
    hp, hr = st.has_pix[0], st.has_range[0]
    fx, fy = st.focal_px()
    D = np.sqrt(((X0 - st.platform_m[0, hp]) ** 2).sum(axis=1))
    order_p = np.argsort(t_s[hp], kind="stable")
    order_r = np.argsort(t_s[hr], kind="stable")
    inv_d = np.where(np.isfinite(D) & (D > 0), 1.0 / np.where(D > 0, D, 1.0), 0.0)[order_p]
    tp, tr = t_s[hp][order_p], t_s[hr][order_r]
    k = order_p.size
    m = 2 * k + tr.size
    out = []
    for sigma, b_deg in zip(sigmas, bias_deg or [None] * len(sigmas), strict=True):
        s_px = 1.0 if sigma.pixel_px is None else sigma.pixel_px
        s_r = 1.0 if sigma.range_m is None else sigma.range_m
        s_pos = 0.0 if sigma.position_m is None else sigma.position_m
        s_att = 0.0 if sigma.attitude_deg is None else math.radians(sigma.attitude_deg)
        built = []
        for axis, f in ((0, fx[0, hp][order_p]), (1, fy[0, hp][order_p])):
            parts = [(f * s_att, sigma.attitude_tau_s), (f * s_pos * inv_d, sigma.position_tau_s)]
            built.append(_group(2 * order_p + axis, np.full(k, s_px ** 2), parts, tp))
        built.append(_group(2 * k + order_r, np.full(tr.size, s_r ** 2), [(np.full(tr.size, s_pos),
                                                                            sigma.position_tau_s)], tr))
        if isinstance(b_deg, Slip):
            g = np.where(b_deg.mask[hp][order_p], b_deg.prior_px, 0.0)
            bias = (g, g.copy(), np.zeros(tr.size))
        else:
            b = math.radians(b_deg or 0.0)
            bias = (fx[0, hp][order_p] * b, fy[0, hp][order_p] * b, np.zeros(tr.size))
        Cii, R0 = np.empty(m), np.empty(m)
        for (g, r0, cii, _), gb in zip(built, bias, strict=True):
            Cii[g[0]], R0[g[0]] = cii + gb * gb, r0
        out.append(Models(tuple((g[0], *(np.asarray(x)[None] for x in g[1:])) for g, _, _, _ in built), Cii[None],
                          R0[None], 2 * k, np.array([any(c for _, _, _, c in built)]), tuple(x[None] for x in bias)))
    return Models.concat(out)


def _group(rows, R0, parts, t_s):
    """One uncorrelated block of rows (u, v or range) in time order: rows (k,), white variances R0 (k,), parts
    [(gains (k,), tau_s)] (white without a tau, else a unit-variance Gauss-Markov state). Returns (rows, gains
    (k,p), band template (p+1,kp), K^-1's diagonal (k,p), log det K), R0, marginal variances C_ii (k,) and
    whether some state has a nonzero transition."""
    gains, chains = [], []
    for g, tau in parts:
        if not (g != 0).any():
            continue
        if tau:
            gains.append(g)
            chains.append(np.exp(-np.diff(t_s) / tau))  # the transitions between time-ordered frames
        else:
            R0 = R0 + g * g
    G = np.stack(gains, axis=1) if gains else np.zeros((rows.size, 0))
    a = np.stack(chains, axis=1) if chains else np.zeros((max(rows.size - 1, 0), 0))
    k, p = G.shape
    diag, ab, log_inn = np.zeros((k, p)), np.zeros((p + 1, k * p)), 0.0
    if p and k:
        inn = np.maximum(1.0 - a ** 2, _MIN_INNOVATION)  # (k-1, p)
        # A = K^-1 + G^T R^-1 G, states ordered frame by frame (index i p + j), lower banded storage ab[d, c]:
        # K^-1's diagonal here, its transitions (offset p) in the template
        diag = np.ones((k, p))
        diag[1:] += 1.0 / inn - 1.0
        diag[:-1] += a ** 2 / inn
        ab[p, :(k - 1) * p] = (-a / inn).ravel()
        log_inn = float(np.log(inn).sum())
    correlated = bool(a.size and (a > 0).any() and (G != 0).any())
    return (rows, G, ab, diag, log_inn), R0, R0 + (G * G).sum(axis=1), correlated


# ---- the estimator (one problem) ----------------------------------------------------------------------------

def rows_in_use(st: Stacked, X: np.ndarray) -> np.ndarray:
    """[J | r] (m,4) at X (3,) of one problem (B = 1): the u and v rows of the frames with a pixel (interleaved),
    then the rows of the frames with a range; r observed - predicted (px, m). With X (B,3) and st B copies of
    one problem: (B,m,4), the rows at each X."""
    one = X.ndim == 1
    X = X.reshape(-1, 3)
    Jp, rp, _ = pixel_model(st, X)
    Jr, rr, _ = range_model(st, X)
    pix = np.repeat(st.has_pix[0], 2)
    rng = st.has_range[0]
    out = np.concatenate([np.concatenate([Jp[:, pix], rp[:, pix, None]], axis=2),
                          np.concatenate([Jr[:, rng], rr[:, rng, None]], axis=2)], axis=1)
    return out[0] if one else out


def quadratic_forms_stacked(sk: Models, A: np.ndarray, w: np.ndarray, vf: np.ndarray) -> list:
    """Per model of the K `Models` and per group (u, v, range): ([J|r]^T C_w^-1 [J|r] (4,4), log det C_w, rows with
    weight) at its rows A (K,m,4), robust weights w (K,m) (a row's variance C_ii / w, the rest of C unchanged) and
    variance factors vf (K,2); one banded factorization per group for all K (side by side, their band matrices are
    one block-diagonal band matrix). A boresight bias (`Models.bias`, a gain column a of unit prior variance) is
    integrated out by Sherman-Morrison on the forms: with F = [J|r|a]^T C^-1 [J|r|a], the form is
    F_yy - F_ya F_ay / (1 + F_aa) and log det grows by log(1 + F_aa)."""
    K = A.shape[0]
    # R_w = C_ii / w - (C_ii - R0): the weight inflates the row's own variance only
    with np.errstate(divide="ignore"):
        Rinv_all = np.where(w > 0, w / (sk.Cii - w * (sk.Cii - sk.R0)), 0.0)
    out = [[] for _ in range(K)]
    for gi, (rows, G, ab0, diag, log_inn) in enumerate(sk.groups):
        k, p = G.shape[1:]
        if k == 0:
            for o in out:
                o.append((np.zeros((4, 4)), 0.0, 0))
            continue
        Rinv, Y = Rinv_all[:, rows], A[:, rows]
        biased = bool((sk.bias[gi] != 0).any())
        if biased:
            Y = np.concatenate([Y, sk.bias[gi][..., None]], axis=2)
        scale = vf[:, 0] if gi < 2 else vf[:, 1]
        RiY = Rinv[:, :, None] * Y
        logdet = np.log(scale[:, None] / np.where(Rinv > 0, Rinv, scale[:, None])).sum(axis=1)  # rows with weight
        if p == 0:
            CY = RiY / scale[:, None, None]
        else:
            # A = K^-1 + G^T R^-1 G: the same frame's states (offsets 0..p-1) on the template's transitions
            ab = ab0.copy()
            ab4 = ab.reshape(K, p + 1, k, p)
            for d in range(p):
                blk = Rinv[:, :, None] * G[:, :, :p - d] * G[:, :, d:]
                if d == 0:
                    blk = blk + diag
                ab4[:, d, :, :p - d] = blk
            band = np.ascontiguousarray(ab.transpose(1, 0, 2).reshape(p + 1, K * k * p))
            cb, info = _pbtrf(band, lower=1, overwrite_ab=1)  # LAPACK directly: scipy's checks cost more
            if info > 0:
                raise np.linalg.LinAlgError(f"{info}-th leading minor not positive definite")
            GtRiY = (G[:, :, :, None] * RiY[:, :, None, :]).reshape(K * k * p, -1)
            Z = _pbtrs(cb, GtRiY, lower=1)[0].reshape(K, k, p, -1)  # info is nonzero only for bad arguments
            CY = (RiY - Rinv[:, :, None] * np.einsum("jkp,jkpq->jkq", G, Z)) / scale[:, None, None]
            logdet = logdet + (2.0 * np.log(cb[0]).reshape(K, k * p).sum(axis=1) + log_inn)
        forms = np.swapaxes(Y, 1, 2) @ CY
        if biased:
            faa = forms[:, 4, 4]
            forms = forms[:, :4, :4] - forms[:, :4, 4:] * forms[:, 4:, :4] / (1.0 + faa)[:, None, None]
            logdet = logdet + np.log1p(faa)
        counts = np.count_nonzero(Rinv, axis=1)
        for j in range(K):
            out[j].append((forms[j], float(logdet[j]), int(counts[j])))
    return out


def gls(sts: list, X0s: np.ndarray, models: Models, robust: str | None, vce: bool, tol_m: float,
        max_iterations: int, rows0: list | None = None, weights: np.ndarray | None = None, prior_dof=0.0):
    """Generalized least squares `mle` of T problems (B = 1 each) with the same rows in use (the same frames with
    a pixel and with a range, in the same time order) from usable starts X0s (T,3), each under K models of its
    rows (models: T K, problem by problem), all T K fits side by side, each exactly as alone: `Correlated` through
    the one iteration and finish of `mle.run` (the loss's phases and scale guard), damped, with fixed robust
    weights (T,3,n) of the u, v and range rows (None: 1); rows0: the problems' `rows_in_use` at their starts
    where the caller has them; prior_dof: the variance components' prior (`mle.vce_prior_dof` of the stated
    sigma). Returns `mle.finish`'s tuple over the T K fits."""
    T = len(sts)
    K = models.Cii.shape[0] // T
    X = np.repeat(np.asarray(X0s, dtype=np.float64).reshape(T, 3), K, axis=0)
    status, bad = start_status(X, None)
    stk = stack_problems([st.take(np.zeros(K, dtype=np.intp)) for st in sts])
    if rows0 is None:
        rows0 = [rows_in_use(st, X[t * K]) for t, st in enumerate(sts)]
    rows = [r for r in rows0 for _ in range(K)]
    w = None if weights is None else np.repeat(np.asarray(weights, dtype=np.float64), K, axis=0)
    return _mle.run(Correlated(stk, models, X, vce, rows, w, prior_dof), stk, X, status, bad, robust, tol_m,
                    max_iterations)


def stack_problems(sts: list) -> Stacked:
    """One Stacked of the problems of several with the same number of frames and sigma (truth and timestamps
    kept only where every one has them)."""
    if len(sts) == 1:
        return sts[0]
    cat = np.concatenate
    truth = None if any(s.truth_m is None for s in sts) else cat([s.truth_m for s in sts])
    t_ns = None if any(s.t_ns is None for s in sts) else cat([s.t_ns for s in sts])
    return Stacked(M=cat([s.M for s in sts]), p4=cat([s.p4 for s in sts]), pix=cat([s.pix for s in sts]),
                   has_pix=cat([s.has_pix for s in sts]), platform_m=cat([s.platform_m for s in sts]),
                   range_m=cat([s.range_m for s in sts]), has_range=cat([s.has_range for s in sts]),
                   sigma=sts[0].sigma, truth_m=truth, t_ns=t_ns)


class Correlated(_iterate.Model):
    """The `mle` model (`iterate.drive`, `mle.finish`) of one problem (B = 1) with time-correlated errors under K
    residual models at once (`gls`): damped generalized least squares (Levenberg-Marquardt in `iterate.drive`: a
    step must not raise r^T C_w^-1 r) with fixed robust weights w (a row's variance C_ii / w, the rest of C
    unchanged): every row at weight 1, or a first fit's weights. The weights are never updated from the rows'
    marginal residuals under the correlated C: that update descends no objective and, where many rows sit near
    the loss's corners, wanders without converging (docs/solvers.md, "Three more rules of the first fit"). The
    drift is modelled (no autocorrelation inflation in `mle.finish`)."""

    drift_modelled = True
    fixed_weights = True
    damped = True

    def __init__(self, st: Stacked, models: Models, X: np.ndarray, vce: bool, rows: list,
                 weights: np.ndarray | None = None, prior_dof=0.0):
        """st: problems with the same rows in use, each once per model (`gls`); X (K,3) their starts, rows the
        list of each model's rows at its start (`rows_in_use`), weights (K,3,n) of their u, v and range rows
        (None: 1)."""
        K, m = models.Cii.shape
        self.st, self.models, self.K, self.X, self.vce = st, models, K, X, vce
        self.sd = np.sqrt(models.Cii).T  # (m, K)
        self.grp = np.r_[np.zeros(models.npix, dtype=int), np.ones(m - models.npix, dtype=int)]
        self.vf, self.guard = np.ones((K, 2)), np.ones((K, 2))
        self.vce_rounds = np.zeros(K, dtype=np.int64)
        self.prior_dof = prior_dof
        pf, rf = np.flatnonzero(st.has_pix[0]), np.flatnonzero(st.has_range[0])
        # the rows' places in the (3,n,K) residual planes: u, v of the pixel frames (interleaved), the ranged frames
        self._at = np.concatenate([(np.arange(2)[None, :] * st.n + pf[:, None]).ravel(), 2 * st.n + rf])
        self.ok = self._planes(np.ones((m, K)), 0.0) > 0
        self.w, self.wr = np.ones((m, K)), None
        if weights is not None:
            self.w = np.moveaxis(np.asarray(weights, dtype=np.float64), 0, -1).reshape(3 * st.n, K)[self._at]
            self.wr = self._planes(self.w, 1.0)
        self.A = list(rows)  # per model; replaced, never changed in place
        self._last_forms = [None] * K
        self._scaled_vf = None  # the variance factors of the row scales self._s and self._isd

    def _planes(self, rows: np.ndarray, fill: float) -> np.ndarray:
        """(3,n,K) planes of per-row values (m,K) (u, v of the pixel frames, then the ranged frames)."""
        out = np.full((3, self.st.n, rows.shape[1]), fill)
        out.reshape(-1, rows.shape[1])[self._at] = rows
        return out

    def _refresh(self):
        """The residual planes at the current rows A and variance factors."""
        if self._scaled_vf is None or not np.array_equal(self.vf, self._scaled_vf):
            self._s = self.sd * np.sqrt(self.vf[:, self.grp].T)
            self._isd, self._scaled_vf = self._planes(1.0 / self._s, 1.0), self.vf.copy()
        r = np.stack([A[:, 3] for A in self.A], axis=1)
        self.E = self._planes(r / self._s, 0.0)

    def _forms(self, idx, var_scale=None, rows=None) -> list:
        """Per model k of idx: (`quadratic_forms_stacked`, their sum) at its current rows (or rows, a list over
        idx: a trial's), weights and variance factors times var_scale (len(idx),2) (None: 1); the last ones are
        kept per model (the convergence test and the finish ask again at the same state)."""
        vfs = self.vf[idx] if var_scale is None else self.vf[idx] * var_scale
        rows = [self.A[k] for k in idx] if rows is None else rows
        out, todo = [None] * len(idx), []
        for j, k in enumerate(idx):
            last = self._last_forms[k]
            if last is not None and last[0] is rows[j] and np.array_equal(last[1], vfs[j]):  # the weights are fixed
                out[j] = last[2]
            else:
                todo.append(j)
        if todo:
            ks = np.asarray(idx)[todo]
            sk = self.models if len(ks) == self.K else self.models.take(ks)
            qs = quadratic_forms_stacked(sk, np.stack([rows[j] for j in todo]), self.w[:, ks].T, vfs[todo])
            for j, k, q in zip(todo, ks, qs, strict=True):
                out[j] = (q, sum(f for f, _, _ in q))
                self._last_forms[k] = (rows[j], vfs[j], out[j])
        return out

    def start(self, robust):  # the weights are fixed: the loss's phases change nothing but the guard's scales
        self._refresh()

    def step(self, idx, X, lam):
        G = np.stack([f[1] for f in self._forms(idx)])
        N = G[:, :3, :3]
        if lam is not None:  # Levenberg-Marquardt: N + lam diag(N)
            N = N + lam[:, None, None] * (N * np.eye(3))
        return solve_spd(N, G[:, :3, 3])

    def trial(self, idx, Xn):
        """The rows at Xn; accepted where the GLS objective r^T C_w^-1 r (at the weights and variance factors) did
        not rise: the trial's forms are kept, so an accepted step's next step reuses them."""
        Xall = np.repeat(Xn[:1], self.K, axis=0)  # every model's rows at once (the others discarded)
        Xall[idx] = Xn
        A = rows_in_use(self.st, Xall)
        self._A = [A[k] for k in idx]
        cost0 = np.array([f[1][3, 3] for f in self._forms(idx)])
        cost = np.array([f[1][3, 3] for f in self._forms(idx, rows=self._A)])
        return cost <= cost0 * (1 + 1e-12) + 1e-300

    def accept(self, idx, accepted):
        if accepted.any():
            for k, A, ok in zip(idx, self._A, accepted, strict=True):
                if ok:
                    self.A[k] = A
            self._refresh()
        return np.zeros(idx.size, dtype=bool)

    def converged(self, idx):
        again = np.zeros(idx.size, dtype=bool)
        if not self.vce:
            return again
        for j, k in enumerate(idx):
            if self.vce_rounds[k] < VCE_MAX_ROUNDS:
                factors, usable = _vce_factors(*self._forms([k])[0], self.vf[k], self.prior_dof)
                if (usable & (np.abs(factors - 1) > VCE_TOL)).any():
                    self.vf[k] = np.where(usable, self.vf[k] * factors, self.vf[k])
                    self.vce_rounds[k] += 1
                    again[j] = True
        if again.any():
            self._refresh()
        return again

    def rescale(self, idx, g, factor):
        self.vf[idx, g] *= factor
        self._refresh()

    def isd(self):
        return self._isd

    def information(self, var_scale):
        G = np.stack([f[1] for f in self._forms(np.arange(self.K), var_scale)])
        return G[:, :3, :3].copy(), G[:, 3, 3].copy()


def _vce_factors(q, G, vf, prior_dof):
    """`mle.helmert` factors (2,) and usable (2,) of the pixel and range groups from the per-group forms q and their
    sum G: a group's r^T C^-1 r over its rows with weight minus trace(N^-1 J_g^T C_g^-1 J_g), at the current
    factors vf (2,), with the prior prior_dof."""
    Ninv = inverse3(G[None, :3, :3])[0][0]
    Q = [sum(f for f, _, _ in parts) for parts in (q[:2], q[2:])]
    red = [sum(n for _, _, n in parts) - float(np.sum(Ninv * Qg[:3, :3])) for parts, Qg in zip((q[:2], q[2:]), Q,
                                                                                              strict=True)]
    f, usable = _mle.helmert(np.array([[Qg[3, 3] for Qg in Q]]), np.array([red]), vf[None], prior_dof)
    return f[0], usable[0]
