"""Weighted maximum-likelihood estimator (beyond the paper): Gauss-Newton / Levenberg-Marquardt on pixel and
range residuals weighted by each sensor's standard deviation, robust loss by IRLS, optional variance component
estimation, posterior covariance, CEP and error ellipsoid. Batched over B problems.
"""

from __future__ import annotations

import numpy as np

from pipeline.solve import bias_mixture, fit_checks
from pipeline.solve import iterate as _iterate
from pipeline.solve.estimate import Status
from pipeline.solve.iterate import divergence_bound, start_status
from pipeline.solve.observations import Sigma
from pipeline.solve.stacked import (
    FULL3,
    PAIRS,
    Planes,
    Stacked,
    cofactors3,
    condition_numbers,
    evaluate,
    full3,
    inverse3,
    put_last,
    take_last,
)

ROBUST_LOSSES = (None, "huber", "cauchy", "redescending")
#: the default loss of `solve` and `solve_batch`
DEFAULT_ROBUST = "redescending"
#: tuning constants in units of the standardized residual (95 % efficiency under Gaussian noise)
HUBER_C = 1.345
CAUCHY_C = 2.3849
#: the redescending loss: quadratic up to REDESCEND_A (full weight: ~100 % Gaussian efficiency), the weight
#: falling smoothly (biweight-shaped) to zero at REDESCEND_B, zero beyond: a gross outlier has no pull at all.
#: A frame's pixel is one 2-D residual, weighted (or rejected) whole by its length: full weight up to
#: REDESCEND_A_PIXEL, the length a 2-D Gaussian exceeds as rarely (0.27 %) as a 1-D one exceeds REDESCEND_A
REDESCEND_A = 3.0
REDESCEND_A_PIXEL = 3.44
REDESCEND_B = 6.0
#: the boresight bias prior when the sigma gives no attitude accuracy (deg)
DEFAULT_BIAS_PRIOR_DEG = 0.5
#: the Huber phase before the redescending one ends where its step is below this many standard deviations of
#: the target (the redescending phase moves the answer by about one standard deviation from there)
START_TOL_SIGMA = 0.1
#: the bias profile's IRLS rounds end once no problem's bias (in prior standard deviations) moves by more
PROFILE_TOL = 1e-12
#: the bias mixture's step is relinearized (the model evaluated where it leads and the mixture taken again) while
#: longer than this many standard deviations of the target; the steps shrink quadratically (paper's problems:
#: ~0.6 sigma, then ~0.1 %), so the step left untried is ~1e-4 of a sigma or less
MIXTURE_RELINEARIZE_SIGMA = 0.1
#: rounds of the mixture at most (a problem still beyond after them keeps its last step, residuals moved with it)
MIXTURE_MAX_ROUNDS = 5
VCE_MAX_ROUNDS = 10
VCE_TOL = 0.01
#: a group's stated sigma counts as this many residuals where its variance component would shrink it (the factor
#: at least (the group's r^T C^-1 r + VCE_PRIOR_DOF) / (its redundancy + VCE_PRIOR_DOF), in units of the stated
#: variance), so that a handful of rows (two or three laser ranges) cannot shrink a stated sigma to nothing
VCE_PRIOR_DOF = 4.0


def _curvature(e: np.ndarray, robust: str) -> np.ndarray:
    """Newton weights of the normal matrix: rho''(e) (0 beyond Huber's c, negative beyond Cauchy's c), floored
    at a thousandth of the IRLS weight rho'(e)/e so that the normal matrix stays regular when most residuals are
    large (a far start)."""
    if robust == "huber":
        a = np.abs(e)
        return np.where(a <= HUBER_C, 1.0, 0.001 * HUBER_C / np.where(a <= HUBER_C, 1.0, a))
    z = (e / CAUCHY_C) ** 2
    w = 1.0 / (1.0 + z)
    return np.maximum((1.0 - z) * w * w, 0.001 * w)


def _rho_and_weight(e: np.ndarray, robust: str, rho: bool = True):
    """Huber's or Cauchy's loss rho(e) and IRLS weight rho'(e)/e of standardized residuals e (rho None unless
    asked for)."""
    assert robust in ("huber", "cauchy"), robust  # the callers handle None and "redescending" themselves
    if robust == "huber":
        a = np.abs(e)
        w = np.minimum(1.0, HUBER_C / np.maximum(a, 1e-300))
        if not rho:
            return None, w
        t = np.maximum(a - HUBER_C, 0.0)  # rho = e^2/2 inside, c|e| - c^2/2 = e^2/2 - (|e| - c)^2/2 outside
        return 0.5 * (e * e - t * t), w
    z = (e / CAUCHY_C) ** 2
    return (0.5 * CAUCHY_C ** 2 * np.log1p(z) if rho else None), 1.0 / (1.0 + z)


def _redescending(e: np.ndarray, A: float = REDESCEND_A, rho: bool = True):
    """rho and weight of the redescending loss: w = 1 for |e| <= A, (1 - t^2)^2 with t = (|e| - A) / (B - A)
    up to B = REDESCEND_B, 0 beyond; rho = integral of w e de (continuous, constant beyond B); rho None unless
    asked for."""
    D = REDESCEND_B - A
    a = np.abs(e)
    t = np.clip((a - A) / D, 0.0, 1.0)
    t2 = t * t
    u = 1.0 - t2
    w = u * u  # 1 where |e| <= A (t = 0)
    if not rho:
        return None, w
    tail = 0.5 * A * A + D * (A * t * (1.0 - t2 * (2.0 / 3.0 - t2 / 5.0)) + D * (1.0 - w * u) / 6.0)
    return np.where(a <= A, 0.5 * e * e, tail), w


def pixel_pair_redescending(e_u: np.ndarray, e_v: np.ndarray, rho: bool = True):
    """rho and weight (shaped as e_u) of the redescending loss of the pixel residuals (e_u, e_v), standardized,
    by their length: a mistracked frame moves the pixel in 2-D, and both coordinates go (or stay) together."""
    return _redescending(np.sqrt(e_u * e_u + e_v * e_v), REDESCEND_A_PIXEL, rho)


def bias_prior_deg(sigma: Sigma, options: dict) -> tuple[float | None, bool]:
    """The prior standard deviation (deg) of the constant boresight bias `mle` estimates, and whether its size is
    unknown: the option bias_prior_deg when given (0: no bias; used as given), none when the sigma gives
    correlation times (the configured error model wins), else the attitude sigma (else DEFAULT_BIAS_PRIOR_DEG)
    as the largest bias, its size learned from the flight (`bias_mixture`)."""
    b = options.get("bias_prior_deg")
    if b is not None:
        return float(b) or None, False
    if sigma.correlated:
        return None, False
    return sigma.attitude_deg or DEFAULT_BIAS_PRIOR_DEG, True


def base_variances(st: Stacked, X0: np.ndarray, sigma: Sigma):
    """A priori variances (B, 2n+n) of the residual rows [u_1, v_1, ..., d_1, ...], from the sensor sigmas:
    pixel sigma_px^2 + f^2 (sigma_att^2 + (sigma_pos / D)^2) (f `focal_px` of that axis, D the platform-to-target
    distance at X0), range sigma_range^2 + sigma_pos^2; unknown sigmas: 1 px, 1 m, 0 (docs/solvers.md, mle)."""
    s_px = 1.0 if sigma.pixel_px is None else sigma.pixel_px
    s_r = 1.0 if sigma.range_m is None else sigma.range_m
    s_pos = 0.0 if sigma.position_m is None else sigma.position_m
    s_att = 0.0 if sigma.attitude_deg is None else np.deg2rad(sigma.attitude_deg)
    fx, fy = st.focal_px()
    B, n = fx.shape
    if s_pos > 0:
        diff = X0[:, None, :] - st.platform_m
        D = np.sqrt(np.einsum("bni,bni->bn", diff, diff))
        D = np.where(np.isfinite(D) & (D > 0), D, np.inf)
        pos_rad2 = (s_pos / D) ** 2
    else:
        pos_rad2 = 0.0
    var_u = s_px ** 2 + fx ** 2 * (s_att ** 2 + pos_rad2)
    var_v = s_px ** 2 + fy ** 2 * (s_att ** 2 + pos_rad2)
    var_pix = np.stack([var_u, var_v], axis=-1).reshape(B, 2 * n)
    var_rng = np.full((B, n), s_r ** 2 + s_pos ** 2)
    var = np.concatenate([var_pix, var_rng], axis=1)
    var = np.where(var > 0, var, 1.0)  # all sigmas zero: unit weights
    return var


def vce_prior_dof(sigma: Sigma) -> np.ndarray:
    """(2,) the variance components' prior degrees of freedom of the pixel and range groups: VCE_PRIOR_DOF where
    the sigma states that group's noise (pixel_px, range_m), 0 where not (its component from the rows alone)."""
    return VCE_PRIOR_DOF * np.array([sigma.pixel_px is not None, sigma.range_m is not None], dtype=np.float64)


def _sum_rows(A: np.ndarray) -> np.ndarray:
    """(b,) sums over the rows (k, frame) of (3,n,b) planes."""
    return A.reshape(-1, A.shape[-1]).sum(axis=0)


def _cost_weights(E: np.ndarray, robust: str | None):
    """sum rho(e) (b,) and the IRLS weights rho'(e)/e (3,n,b) (None for the squared loss) of standardized E."""
    if robust is None:
        return 0.5 * _sum_rows(E * E), None
    if robust == "redescending":
        rho_p, w_p = pixel_pair_redescending(E[0], E[1])
        rho_r, w_r = _redescending(E[2])
        return rho_p.sum(axis=0) + rho_r.sum(axis=0), np.stack([w_p, w_p, w_r])
    rho, w = _rho_and_weight(E, robust)
    return _sum_rows(rho), w


def _normal(J: np.ndarray, E: np.ndarray, w, wn=None):
    """The six entries N00 N01 N02 N11 N12 N22 (b,) of J^T diag(wn) J (wn defaults to w; None = 1) and the three
    of g = J^T diag(w) E."""
    b = E.shape[-1]
    WE = E if w is None else w * E
    Jr = J.reshape(3, -1, b)
    g = np.einsum("crb,rb->cb", Jr, WE.reshape(-1, b))
    wn = w if wn is None else wn
    CJ = Jr if wn is None else (J * wn).reshape(3, -1, b)
    N = np.einsum("crb,drb->cdb", CJ, Jr)  # one call: as fast as six row sums on large batches, cheaper on small
    return [N[0, 0], N[0, 1], N[0, 2], N[1, 1], N[1, 2], N[2, 2]], g


def _solve3(N, g, lam=None):
    """Closed-form solution (b,3) of (N + lam diag N) x = g from the six entries (`stacked.cofactors3`) and
    the singular flag (b,)."""
    if lam is not None:
        N = [x + lam * x if k in (0, 3, 5) else x for k, x in enumerate(N)]
    inv, _, singular = cofactors3(N)
    return np.stack([sum(inv[FULL3[c][e]] * g[e] for e in range(3)) for c in range(3)], axis=1), singular


def mle(st: Stacked, X0: np.ndarray, sigma: Sigma, robust: str | None, vce: bool, tol_m: float,
        max_iterations: int, init_status: np.ndarray | None = None, bias_deg: float | None = None,
        bias_size_unknown: bool = True, terrain=None):
    """Returns X (B,3), iterations (B,), status (B,) int8, cond (B,) of the weighted design W^1/2 J,
    covariance (B,3,3) m^2 and `finish`'s extras (B, ...), with bias_deg the boresight bias's too.

    bias_deg > 0: a constant boresight bias (pixel offsets f * angle in u and v) with a zero-mean prior of that
    sigma, eliminated by Schur complement; with bias_size_unknown the largest bias, its size averaged over
    (`bias_mixture`). terrain=(fn, sigma_m): a soft prior on the target's height, fn(e_m, n_m) -> (up_m, dup_de,
    dup_dn) in the problems' ENU frame. The model: docs/solvers.md, mle.
    """
    X = np.array(X0, dtype=np.float64, copy=True)
    status, bad = start_status(X, init_status)
    X[bad] = 0.0
    return run(White(st, X, sigma, vce, terrain, bias_deg, bias_size_unknown), st, X, status, bad, robust, tol_m,
               max_iterations)


def run(m, st: Stacked, X: np.ndarray, status: np.ndarray, bad: np.ndarray, robust: str | None, tol_m: float,
        max_iterations: int):
    """The one `mle` iteration and finish of a model m (`White`, or `correlated.Correlated`): Levenberg-Marquardt
    / IRLS by `iterate.drive` with m's loss; with the redescending loss Huber first, then the scale guard
    (`robust_scale`), then the redescending loss from there (for a model with fixed weights, whose objective the
    loss does not change, only where the guard rescaled a group). Returns `finish`'s tuple."""
    iterations = np.zeros(st.size, dtype=np.int64)
    centre, bound = divergence_bound(st, X)  # the bad starts' bound is never used: they do not iterate
    active = ~bad
    for phase in (("huber", "redescending") if robust == "redescending" else (robust,)):
        if phase == "redescending":
            robust_scale(m)
            active = ~((status == Status.DIVERGED) | (status == Status.DEGENERATE)) & ~bad
            if m.fixed_weights:  # the loss does not change the objective: only a rescaled group or an unfinished
                active &= (m.guard != 1).any(axis=1) | (status == Status.MAX_ITERATIONS)  # fit goes on
            status[active] = Status.MAX_ITERATIONS
        m.start(phase)
        m.start_only = phase != robust  # the Huber phase: the redescending phase's start
        _iterate.drive(m, X, status, active, iterations, bound, centre, tol_m, max_iterations, damped=m.damped)
    return finish(m, X, status, iterations)


def robust_scale(m) -> None:
    """The scale guard before the redescending phase (docs/solvers.md): a group whose Huber-fit residuals spread
    wider than its sigma (1.4826 median |e| beyond the MAD's own noise, ~1.17 / sqrt(count)) has its variances
    scaled by that (`m.rescale`), so that a misfit model rejects no good data; the factors go to m.guard."""
    E, ok = m.E, m.ok
    for g, rows in ((0, slice(0, 2)), (1, slice(2, 3))):
        # the median of each problem's usable |e| (NaN where none): sorted, the unusable ones (inf) last
        e = np.sort(np.where(ok[rows], np.abs(E[rows]), np.inf).reshape(-1, E.shape[-1]), axis=0)
        cnt = ok[rows].reshape(-1, E.shape[-1]).sum(axis=0)
        lo = np.take_along_axis(e, np.maximum(cnt - 1, 0)[None] // 2, axis=0)[0]
        hi = np.take_along_axis(e, np.minimum(cnt // 2, e.shape[0] - 1)[None], axis=0)[0]
        with np.errstate(all="ignore"):
            mad = np.where(cnt > 0, 1.4826 * (0.5 * (lo + hi)), np.nan)
        big = np.isfinite(mad) & (cnt >= 4) & (mad > 1.0 + 2.34 / np.sqrt(np.maximum(cnt, 1)))
        f = np.where(big, mad ** 2, 1.0)
        m.rescale(slice(None), g, f)
        m.guard[:, g] = f


def finish(m, X: np.ndarray, status: np.ndarray, iterations: np.ndarray):
    """The one finish of every `mle` model m at its final iterate X (B,3) with its final weights: X, iterations,
    status, cond (B,), covariance (B,3,3) and the extras (B, ...) (rejected and residuals (B,n,3), the fit checks).
    m gives E (3,n,B), ok, wr (or None), guard, vf (B,2) and information(var_scale (B,2)) -> (information
    (B,3,3), chi-square (B,)). Drift (unless m models it) and a failed chi-square inflate (docs/solvers.md)."""
    E, ok, wr, guard = m.E, m.ok, m.wr, m.guard
    B = X.shape[0]
    failed = (status == Status.DIVERGED) | (status == Status.DEGENERATE)
    use = ok if wr is None else ok & (wr > 0)
    dof = _sum_rows(use) - 3 + m.extra_dof()  # a bias angle costs a degree of freedom, its prior gives one back
    cond = condition_numbers(m.information(np.ones((B, 2)))[0])
    N0, chi2 = m.information(1.0 / guard)  # before the scale guard
    with np.errstate(divide="ignore", invalid="ignore"):
        sigma0_sq = np.where(dof > 0, chi2 / dof, np.nan)
    p = fit_checks.chi_square_p(chi2, dof)
    # the residuals as the fit weighs them: a run of frames the robust loss (partly) rejects is no drift
    Ew = E if wr is None else np.sqrt(wr) * E
    # a slow drift under white noise hardly shows at lag 1 but does in the means over blocks of frames (batch
    # means): the larger factor inflates, and either test calls the evidence step (`methods._with_learned_tau`)
    # a run of consecutive frames beyond the redescending loss's full-weight zone (rejected ones included) is one
    # outlying segment (a mistracked run), not drift: left out of the lag-1 test (the batch means keep it)
    seg_pix = fit_checks.outlying_runs(ok[0] & (np.hypot(E[0], E[1]) > REDESCEND_A_PIXEL))
    use_acf = use & ~np.stack([seg_pix, seg_pix, fit_checks.outlying_runs(ok[2] & (np.abs(E[2]) > REDESCEND_A))])
    rho, drift, ratio, block, infl = [], [], [], [], []
    for rows in (slice(0, 2), slice(2, 3)):
        r, pairs = fit_checks.lag1_autocorrelation(Ew, use_acf, rows)
        d = fit_checks.acf_significant(r, pairs) & (not m.drift_modelled)
        vr, blocks = fit_checks.batch_means_ratio(Ew, use, rows)
        blk = fit_checks.batch_means_significant(vr, blocks) & (not m.drift_modelled)
        rho.append(r), drift.append(d), ratio.append(vr), block.append(blk)
        infl.append(np.maximum(fit_checks.acf_inflation(r, d), fit_checks.batch_means_inflation(vr, blk)))
    N, chi2_s = m.information(np.stack(infl, axis=1))
    p_fail = np.isfinite(p) & (p < fit_checks.CHI2_ALPHA)
    # what `robust_scale` already folded in counts towards the chi-square's variance factor
    with np.errstate(divide="ignore", invalid="ignore"):
        vf_chi = np.where(p_fail & (dof > 0), np.maximum(chi2_s / dof, 1.0), 1.0)
    cov, singular = _inverse_spd(N)
    cov = cov * vf_chi[:, None, None]
    cov0 = _inverse_spd(N0)[0]  # the covariance the model as stated gives
    cov, cov0, E_report, mix_singular = m.adjust(cov, cov0, np.stack(infl, axis=1), vf_chi, failed,
                                                 drift[0] | block[0])
    singular |= mix_singular
    status[singular & ~failed] = Status.DEGENERATE
    failed = (status == Status.DIVERGED) | (status == Status.DEGENERATE)
    X[failed] = np.nan
    cov[failed] = np.nan
    cond[failed & ~singular] = np.nan
    with np.errstate(divide="ignore", invalid="ignore"):
        inflation = np.trace(cov, axis1=1, axis2=2) / np.trace(cov0, axis1=1, axis2=2)
    extras = {"variance_factor_pixel": m.vf[:, 0], "variance_factor_range": m.vf[:, 1],
              "sigma0_sq": sigma0_sq, "vce_rounds": m.vce_rounds,
              "rejected": (np.zeros_like(ok) if wr is None else ok & (wr == 0)).transpose(2, 1, 0),
              "residual_sigmas": E_report.transpose(2, 1, 0).copy(),
              "residuals": (E_report / m.isd()).transpose(2, 1, 0),
              "chi2": chi2, "chi2_dof": dof.astype(np.float64), "chi2_p": p,
              "autocorrelation_pixel": rho[0], "autocorrelation_range": rho[1],
              "drift_pixel": drift[0], "drift_range": drift[1],
              "batch_means_pixel": ratio[0], "batch_means_range": ratio[1],
              "block_drift_pixel": block[0], "block_drift_range": block[1],
              "consistent": ~(p_fail | drift[0] | drift[1] | block[0] | block[1] | (guard > 1).any(axis=1)),
              "robust_spread": np.sqrt(guard),
              "covariance_inflation": np.where(np.isfinite(inflation), inflation, 1.0)}
    extras.update(m.bias_extras(cov, vf_chi))
    return X, iterations, status, cond, cov, extras


class White(_iterate.Model):
    """The `mle` model of errors independent from frame to frame (a boresight bias and the terrain prior
    optional): the state of the batched Levenberg-Marquardt / IRLS iteration of B problems (`iterate.Model`)."""

    damped = True
    skips_last_step = True

    def __init__(self, st, X, sigma, vce, terrain, bias_deg, bias_size_unknown):
        B = st.size
        self.st, self.X, self.vce, self.terrain = st, X, vce, terrain
        self.pl = pl = Planes.from_stacked(st, base_variances(st, X, sigma))
        self.a = None
        if bias_deg:
            fx, fy = st.focal_px()  # the bias columns (2,n,B) of the u and v rows
            self.a = np.where(pl.has_pix, np.stack([fx.T, fy.T]) * np.deg2rad(bias_deg), 0.0) * pl.isd[:2]
        self.bias_sigma_deg, self.bias_size_unknown = bias_deg, bias_size_unknown
        # the stated attitude sigma is split between the bias and the frame-to-frame error (it is the largest bias)
        self.split_attitude = bool(self.a is not None and bias_size_unknown and sigma.attitude_deg)
        # GNSS errors wander over minutes: over a segment much of them is an offset shared by every frame, which
        # moves the target exactly as the platforms and shows in no residual; the covariance carries all of the
        # stated position variance as that offset (the rows keep it too, as frame-to-frame: the safe side)
        self.position_m = sigma.position_m if bias_deg and bias_size_unknown and sigma.position_m else 0.0
        self.vf = np.ones((B, 2))  # variance factors of the pixel and range groups
        self.vce_rounds = np.zeros(B, dtype=np.int64)
        self.prior_dof = vce_prior_dof(sigma)
        self.z = np.zeros((3, B))  # the bias in prior standard deviations (u, v; the range row stays 0)
        self.guard = np.ones((B, 2))  # `robust_scale`'s factors: a misfit, unlike variance components
        self.mix = None
        self.start_only = False
        self._sums = self.J = None  # `information`'s group sums and `jacobian` at the final state

    def _eval(self, pl, a, X, z, robust):
        """J, bias-corrected E, ok, z, cost, IRLS weights at X (the sub-batch of pl, a, z)."""
        J, E, ok = evaluate(pl, X)
        if a is not None:
            E, z = _profile_bias(E, a, robust, z.copy())
        cost, w = _cost_weights(E, robust)
        if a is not None:
            cost = cost + 0.5 * (z * z).sum(axis=0)
        if self.terrain is not None:
            cost = cost + 0.5 * _terrain_rows(self.terrain, X)[1] ** 2
        return J, E, ok, z, cost, w

    def start(self, robust):
        """Evaluate every problem at X for this loss; Newton steps only where it is convex or nearly so."""
        self.robust = robust
        self.newton = robust in ("huber", "cauchy") and self.a is None
        J, self.E, self.ok, self.z, self.cost, self.wr = self._eval(self.pl, self.a, self.X, self.z, robust)
        self.NG = self._normal_state(J, self.E, self.wr, self.a)
        self.newton_ok = np.full(self.st.size, self.newton)
        self._cidx = self._c = None

    def _normal_state(self, J, E, w, a):
        """(9,b): the normal matrix's six entries (the bias eliminated) and the gradient's three (`_normal`), and
        with Newton steps the six of the Newton normal matrix: what `step` needs, kept instead of J (3,3,n,b)."""
        N, g = _normal(J, E, w)
        if a is not None:
            _schur(N, _bias_terms(J, a, w))
        newton = _normal(J, E, w, _curvature(E, self.robust))[0] if self.newton else []
        return np.stack([*N, *g, *newton])

    #: each problem's iteration state (planes over the B problems; a read-only), kept apart for the active ones
    STATE = ("NG", "E", "ok", "wr", "z", "a")

    def _active(self, idx):
        """[NG, E, ok, wr, z, a] of the problems idx (sorted; None for what the model lacks): kept between
        iterations (`accept` merges into it), written back to the full arrays as problems leave the active set."""
        cidx = self._cidx
        if cidx is not None and not (cidx is idx or np.array_equal(cidx, idx)):
            pos = np.searchsorted(cidx, idx)
            if (pos < cidx.size).all() and (cidx[np.minimum(pos, cidx.size - 1)] == idx).all():  # a subset
                leave = np.ones(cidx.size, dtype=bool)
                leave[pos] = False
                self._write_back(cidx[leave], [None if c is None else take_last(c, leave) for c in self._c])
                self._c = [None if c is None else take_last(c, pos) for c in self._c]
                self._cidx = idx
            else:
                self.settle()
        if self._cidx is None:
            full = idx.size == self.st.size
            self._c = [None if x is None else (x if full else take_last(x, idx))
                       for x in (getattr(self, name) for name in self.STATE)]
            self._cidx = idx
        return self._c

    def _write_back(self, idx, state):
        for name, c in zip(self.STATE, state, strict=True):
            if c is not None and name != "a":
                put_last(getattr(self, name), idx, c)

    def settle(self):
        """Write the active problems' state back to the full arrays."""
        self._sums = self.J = None
        if self._cidx is None:
            return
        if self._cidx.size == self.st.size:
            for name, c in zip(self.STATE, self._c, strict=True):
                setattr(self, name, c)
        else:
            self._write_back(self._cidx, self._c)
        self._cidx = self._c = None

    def step(self, idx, X, lam):
        NG = self._active(idx)[0]
        N, g = list(NG[:6]), NG[6:9].copy()
        if self.newton:
            nok = self.newton_ok[idx]
            N = [np.where(nok, n, m) for n, m in zip(NG[9:], N, strict=True)]
        if self.terrain is not None:
            _add_terrain(N, g, *_terrain_rows(self.terrain, X)[:2])
        dX, singular = _solve3(N, g, lam)
        self._N = N
        return dX, singular

    def negligible(self, idx, dX):
        """In the Huber phase before the redescending one (a start), a step shorter than START_TOL_SIGMA of the
        target's standard deviation as that step's normal matrix N gives it (dX^T N dX, the rows standardized)."""
        if not self.start_only:
            return np.zeros(idx.size, dtype=bool)
        x0, x1, x2 = dX.T
        n00, n01, n02, n11, n12, n22 = self._N
        q = (n00 * x0 * x0 + n11 * x1 * x1 + n22 * x2 * x2
             + 2.0 * (n01 * x0 * x1 + n02 * x0 * x2 + n12 * x1 * x2))
        return q <= START_TOL_SIGMA ** 2

    def trial(self, idx, Xn):
        z, a = self._active(idx)[4:]
        J, *rest = self._eval(self.pl if idx.size == self.st.size else self.pl.take(idx), a, Xn, z, self.robust)
        self._trial = (self._normal_state(J, rest[0], rest[4], a), *rest)
        return rest[3] <= self.cost[idx] * (1 + 1e-12) + 1e-300

    def accept(self, idx, accept):
        NGn, En, okn, zn, cost_n, wr_n = self._trial
        a_idx = idx[accept]
        every = a_idx.size == idx.size
        self._c = [new if every or new is None or new is old else np.where(accept, new, old)
                   for old, new in zip(self._active(idx), (NGn, En, okn, wr_n, zn, self._c[-1]), strict=True)]
        self.cost[a_idx] = cost_n[accept]
        # a rejected Newton step is retried as the IRLS step (a descent step) before damping
        retry = ~accept & self.newton_ok[idx] if self.robust is not None else np.zeros(idx.size, dtype=bool)
        if self.robust in ("huber", "cauchy") and self.a is None:
            self.newton_ok[a_idx] = True
        self.newton_ok[idx[retry]] = False
        return retry

    def converged(self, d_idx):
        """Variance components at convergence (at the final iterate; a step that ended a start phase was taken
        without a trial, so the state is evaluated there first): the problems whose factors changed go on."""
        if not self.vce:
            return np.zeros(d_idx.size, dtype=bool)
        self.settle()  # the variance components rescale the full arrays
        J = self._reevaluate(d_idx)
        factors, usable = _vce_factors(J, take_last(self.E, d_idx), take_last(self.ok, d_idx),
                                       self.robust, None if self.a is None else take_last(self.a, d_idx),
                                       None if self.terrain is None else _terrain_rows(self.terrain, self.X[d_idx]),
                                       self.vf[d_idx], self.prior_dof)
        more = (np.abs(factors - 1) > VCE_TOL) & usable
        again = more.any(axis=1) & (self.vce_rounds[d_idx] < VCE_MAX_ROUNDS)
        change = np.where(usable & again[:, None], factors, 1.0)
        self.vce_rounds[d_idx] += again
        rd = d_idx[again]
        if rd.size:  # rescale the standardized rows: sigma_g -> sigma_g sqrt(factor_g)
            self.rescale(rd, 0, change[again, 0])
            self.rescale(rd, 1, change[again, 1])
            self._reevaluate(rd)
        return again

    def _reevaluate(self, idx):
        """The state (normal equations, E, ok, z, weights, cost) of the problems idx evaluated again at self.X
        (after `settle`); returns their J."""
        a = None if self.a is None else take_last(self.a, idx)
        J, E, ok, z, cost, w = self._eval(self.pl.take(idx), a, self.X[idx], take_last(self.z, idx), self.robust)
        self.cost[idx] = cost
        for name, new in zip(("NG", "E", "ok", "z", "wr"), (self._normal_state(J, E, w, a), E, ok, z, w), strict=True):
            if new is not None:
                put_last(getattr(self, name), idx, new)
        return J

    def rescale(self, idx, g, factor):
        """Multiply the variances of group g (0 pixels, 1 ranges) of problems idx (indices, or a slice) by factor."""
        self._sums = self.J = None  # the normal equations are evaluated again before the next step
        self.vf[idx, g] *= factor
        s = 1.0 / np.sqrt(factor)
        rows = slice(0, 2) if g == 0 else slice(2, 3)
        for arr in (self.E[rows], self.pl.isd[rows]) + ((self.a[rows],) if self.a is not None else ()):
            arr[..., idx] *= s

    def jacobian(self):
        """J (3,3,n,B) at the final X."""
        if self.J is None:
            self.J = evaluate(self.pl, self.X)[0]
        return self.J

    def extra_dof(self):
        return 0 if self.terrain is None else _terrain_rows(self.terrain, self.X)[2]

    def isd(self):
        return self.pl.isd

    def _rows(self, var_scale):
        """(3,1,B) row scale of each group's variances scaled by var_scale (B,2)."""
        return (1.0 / np.sqrt(var_scale[:, [0, 0, 1]].T))[:, None, :]

    def information(self, var_scale):
        """Each group's sums are formed once at the final state (`settle` and `rescale` drop them) and scaled."""
        if self._sums is None:
            J, E, w = self.jacobian(), self.E, self.wr
            WE = E * E if w is None else w * E * E
            groups = [_normal(J[:, r], E[r], None if w is None else w[r])[0] + [_sum_rows(WE[r])]
                      for r in (slice(0, 2), slice(2, 3))]
            self._sums = groups, None if self.a is None else _bias_terms(J, self.a, w)
        (pix, rng), bias = self._sums
        vp, vr = var_scale[:, 0], var_scale[:, 1]
        N6 = [p / vp + r / vr for p, r in zip(pix, rng, strict=True)]
        chi2 = N6.pop()
        if bias is not None:  # the bias columns scale with the pixel rows
            self.hs = [(h / vp[:, None], s / vp) for h, s in bias]
            _schur(N6, self.hs)
            chi2 = chi2 + (self.z * self.z).sum(axis=0)
        if self.terrain is not None:  # the terrain prior is one more observation
            jt, et, _ = _terrain_rows(self.terrain, self.X)
            _add_terrain(N6, None, jt, et)
            chi2 = chi2 + et ** 2
        return full3(N6), chi2

    def adjust(self, cov, cov0, infl, vf_chi, failed, drift_pix):
        """The bias averaged over its size (`_mixture`) where it is unknown: (cov, cov0, E_report, singular)."""
        if self.a is None or not self.bias_size_unknown:
            return cov, cov0, self.E, np.zeros(cov.shape[0], dtype=bool)
        # a misfit scales every stated sigma (told wrong by that factor, they are likely all wrong alike): the
        # shared GNSS offset by the larger of the robust scale guard and the chi-square's variance factor; the bias
        # prior by the chi-square's factor only (the bias columns scaled by s, the rows by s / sqrt(vf_chi)): the
        # guard measures the frame-to-frame spread (a late pose under a slewing gimbal: 5-17 x), which says nothing
        # of the constant part of the attitude error, and a prior grown with it let the bias turn every line of
        # sight to where the ranges pull (docs/validation.md, "Unseen families")
        s, g = self._rows(infl), self._rows(1.0 / self.guard)
        mix, cov_stated, E_report = self._mixture(s / np.sqrt(vf_chi), s, g, failed, drift_pix)
        self.mix = mix
        misfit = vf_chi * self.guard.max(axis=1)
        eye = self.position_m ** 2 * np.eye(3)
        cov = np.where(failed[:, None, None], cov, mix["covariance"] + misfit[:, None, None] * eye)
        cov0 = np.where(failed[:, None, None], cov0, cov_stated + eye)
        return cov, cov0, E_report, mix["singular"]

    def bias_extras(self, cov, vf_chi) -> dict:
        if self.mix is not None:
            return _mixture_summary(self, self.mix, cov)
        return {} if self.a is None else _bias_summary(self, cov, self.hs, vf_chi)

    def _with_terrain(self, J, E, a, w, share, idx=slice(None)):
        """The mixture's arguments (of problems idx) with the terrain prior (if any) at self.X as one more frame:
        its range row the terrain residual, no pixel, no bias column, unit weight."""
        if self.terrain is None:
            return J, E, a, w, share
        jt, et, _ = _terrain_rows(self.terrain, self.X[idx])
        b = E.shape[-1]
        Jt, Et, wt, pad = np.zeros((3, 3, 1, b)), np.zeros((3, 1, b)), np.zeros((3, 1, b)), np.zeros((2, 1, b))
        Jt[:, 2, 0], Et[2, 0], wt[2] = jt, et, 1.0
        return (np.concatenate([J, Jt], axis=2), np.concatenate([E, Et], axis=1), np.concatenate([a, pad], axis=1),
                np.concatenate([w, wt], axis=1), None if share is None else np.concatenate([share, pad], axis=1))

    def _mixture(self, s, s_bias, g, failed, drift_pix):
        """`bias_mixture.mixture` at the solution (`_mix`), the rows scaled by s (3,1,B) and the bias columns by
        s_bias; moves X by its step (relinearized beyond MIXTURE_RELINEARIZE_SIGMA, at most MIXTURE_MAX_ROUNDS).
        Returns the mixture (bias, bias_var, bias_cross in units of the stated prior), its covariance (B,3,3)
        with the sigmas as stated (scaled by g) and the standardized residuals (3,n,B) at the final X to first
        order, the mean bias removed."""
        J, E, ok = self.jacobian(), self.E.copy(), self.ok
        E[:2] += self.a * self.z[:2, None, :]
        mix, a0 = self._mix(J, E, ok, s, s_bias, drift_pix, slice(None))
        step = np.where(~failed[:, None] & np.isfinite(mix["step"]), mix["step"], 0.0)
        self.X += step
        cinv = inverse3(mix["covariance"])[0]
        far = np.flatnonzero(np.einsum("bi,bij,bj->b", step, cinv, step) > MIXTURE_RELINEARIZE_SIGMA ** 2)
        if far.size:
            J, ok, a0 = J.copy(), ok.copy(), a0.copy()
        for _ in range(MIXTURE_MAX_ROUNDS - 1):
            if not far.size:
                break
            J2, E2, ok2 = evaluate(self.pl.take(far), self.X[far])
            mix2, a02 = self._mix(J2, E2, ok2, take_last(s, far), take_last(s_bias, far), drift_pix[far], far)
            step[far] = np.where(np.isfinite(mix2["step"]), mix2["step"], 0.0)
            self.X[far] += step[far]
            for k, v in mix2.items():
                mix[k][far] = v
            for x, v in ((J, J2), (E, E2), (ok, ok2), (a0, a02)):
                put_last(x, far, v)
            far = far[np.einsum("bi,bij,bj->b", step[far], inverse3(mix2["covariance"])[0], step[far])
                      > MIXTURE_RELINEARIZE_SIGMA ** 2]
        # the same point as stated (rows and bias columns scaled by g): where nothing scaled them (s = g = 1) the
        # mixture just computed, else computed again for those problems
        cov_stated = mix["covariance"].copy()
        restate = np.flatnonzero(~((s == 1).all(axis=(0, 1)) & (g == 1).all(axis=(0, 1))))
        if restate.size:
            g0 = take_last(g, restate)
            cov_stated[restate] = self._mix(*(take_last(x, restate) for x in (J, E, ok)), g0, g0, drift_pix[restate],
                                            restate)[0]["covariance"]
        # the bias in units of the stated prior: the columns passed carry the scaling s_bias / s (sqrt(vf_chi))
        unit = (s_bias / s)[0, 0]
        mix["bias"] = mix["bias"] * unit[:, None]
        mix["bias_var"] = mix["bias_var"] * (unit * unit)[:, None]
        mix["bias_cross"] = mix["bias_cross"] * unit[:, None, None]
        mix["prior_scale"] = unit
        # the residuals at the final X, evaluated there
        E_report = evaluate(self.pl, self.X)[1]
        E_report[:2] -= a0 * mix["bias"].T[:, None, :]
        return mix, cov_stated, E_report

    def _mix(self, J, E, ok, s, s_bias, drift_pix, idx):
        """`bias_mixture.mixture` of the problems idx (a slice or indices) at J (3,3,n,b), E (3,n,b) (the bias not
        removed), rows in use ok, with the final weights; drift_pix (b,): no attitude variance split there (a
        drift is neither constant nor frame-to-frame). Returns it and the bias columns a0 (2,n,b) it used."""
        a0 = np.where(ok[:2], self.a[..., idx], 0.0)
        w = np.where(ok, 1.0 if self.wr is None else self.wr[..., idx], 0.0)
        a_mix = a0 * s_bias[:2]
        # the attitude's share of each row's variance, as the columns passed weigh it (a bias at the largest prior
        # is the whole attitude error); none where the residuals drift
        share = np.where(drift_pix, 0.0, np.minimum(a_mix ** 2, 1.0)) if self.split_attitude else None
        Jm, Em, am, wm, share = self._with_terrain(J * s, E * s, a_mix, w, share, idx)
        return bias_mixture.mixture(Jm, Em, am, wm, None if share is None else bias_mixture.ratios(share, wm)), a0


def _terrain_rows(terrain, X: np.ndarray):
    """The terrain prior's standardized row jt (3,b) (d residual model / dX over sigma: [-dup_de, -dup_dn, 1] /
    sigma_m), residual et (b,) ((fn(e, n) - up) / sigma_m) and whether it is in use (b,) int (fn finite) at
    X (b,3); zero where not in use."""
    fn, sigma_m = terrain
    b = X.shape[0]
    up, de, dn = (np.broadcast_to(np.asarray(v, dtype=np.float64), (b,)) for v in fn(X[:, 0], X[:, 1]))
    use = np.isfinite(up) & np.isfinite(de) & np.isfinite(dn) & np.isfinite(X).all(axis=1)
    jt = np.where(use, np.stack([-de, -dn, np.ones(b)]), 0.0) / sigma_m
    et = np.where(use, up - X[:, 2], 0.0) / sigma_m
    return jt, et, use.astype(np.int64)


def _add_terrain(N, g, jt, et):
    """Add the terrain row jt (3,b), residual et (b,) to the six normal-matrix entries N and g (in place)."""
    for e, (c, d) in enumerate(PAIRS):
        N[e] = N[e] + jt[c] * jt[d]
    if g is not None:
        for c in range(3):
            g[c] = g[c] + jt[c] * et


def _profile_bias(E, a, robust, z):
    """The bias-corrected residuals E - a z (3,n,b) (E in place; a (2,n,b) the u and v rows' bias columns) and
    z (3,b): the bias (in prior standard deviations) that minimizes sum rho(E - a z) + |z|^2 / 2 over the u and v
    rows (a few IRLS rounds from the previous z; a problem keeps its bias once it moves by at most PROFILE_TOL,
    the rounds stop when every problem has; once fewer than half still move, they go on with those alone)."""
    aEa = np.concatenate([a * E[:2], a * a])  # (4,n,b): a E of the u and v rows, then a a
    if robust is None:
        z[:2] = aEa[:2].sum(axis=1) / (1.0 + aEa[2:].sum(axis=1))
    Ew, aw, zw, work = E[:2], a, z[:2], slice(None)  # the problems still iterated (work) and their E, a, z
    live = np.ones(z.shape[1], dtype=bool)  # the problems whose profile still moves (the others keep theirs)
    for _ in range(0 if robust is None else 4):
        Euv = Ew - aw * zw[:, None, :]
        if robust == "redescending":  # one weight per frame for both rows
            w = pixel_pair_redescending(Euv[0], Euv[1], rho=False)[1]
            nd = np.einsum("nb,knb->kb", w, aEa)
        else:
            w = _rho_and_weight(Euv, robust, rho=False)[1]
            nd = np.concatenate([np.einsum("knb,knb->kb", w, aEa[:2]), np.einsum("knb,knb->kb", w, aEa[2:])])
        zn = nd[:2] / (1.0 + nd[2:])
        moved = (np.abs(zn - zw) > PROFILE_TOL).any(axis=0)  # per problem: its weights changed (NaN: no)
        zw = np.where(live, zn, zw)
        live &= moved
        z[:2, work] = zw
        if not live.any():  # every problem's weights stand: its profile is exact
            break
        if 2 * np.count_nonzero(live) < live.size:
            keep = np.flatnonzero(live)
            work = keep if isinstance(work, slice) else work[keep]
            Ew, aw, aEa, zw = (take_last(x, keep) for x in (Ew, aw, aEa, zw))
            live = np.ones(keep.size, dtype=bool)
    E[:2] -= a * z[:2, None, :]
    return E, z


def _bias_terms(J, a, w):
    """[(h (b,3), s (b,)) for the u and v bias]: h = J^T W a, s = a^T W a over that group's rows."""
    out = []
    for k in (0, 1):
        wa = a[k] if w is None else w[k] * a[k]
        out.append((np.einsum("cnb,nb->bc", J[:, k], wa), np.einsum("nb,nb->b", wa, a[k])))
    return out


def _schur(N, hs):
    """Eliminate the u and v bias (`_bias_terms` hs) from the six normal-matrix entries N (in place):
    N -= h h^T / (1 + s)."""
    for h, s in hs:
        for e, (c, d) in enumerate(PAIRS):
            N[e] = N[e] - h[:, c] * h[:, d] / (1.0 + s)


def _bias_summary(it: White, cov, hs, vf_chi) -> dict:
    """The bias estimate (B,2) deg (u: about the camera's vertical axis, v: about its horizontal axis, as
    pixel offsets / f), its posterior standard deviation and its correlation with the target (B,2,3)."""
    B = cov.shape[0]
    sb = np.full((B, 2), it.bias_sigma_deg)
    bias = it.z[:2].T * sb
    sd = np.empty((B, 2))
    corr = np.empty((B, 2, 3))
    sx = np.sqrt(np.einsum("bii->bi", cov))
    for k, (h, s) in enumerate(hs):
        c_xz = -np.einsum("bij,bj->bi", cov, h) / (1.0 + s)[:, None]
        var_z = vf_chi / (1.0 + s) + np.einsum("bi,bij,bj->b", h, cov, h) / (1.0 + s) ** 2
        sd[:, k] = np.sqrt(var_z) * sb[:, k]
        with np.errstate(divide="ignore", invalid="ignore"):
            corr[:, k] = c_xz / (sx * np.sqrt(var_z)[:, None])
    return {"bias_deg": bias, "bias_sigma_deg": sd, "bias_target_correlation": corr, "bias_prior_deg": sb}


def _mixture_summary(it: White, mix: dict, cov) -> dict:
    """`_bias_summary` from the bias mixture, with the prior's sigma (B,2) (the largest bias, scaled by the
    chi-square's variance factor, times the rms of PHI_GRID) and the bias size the flight supports (B,) deg (the
    prior scale's posterior rms)."""
    sb = it.bias_sigma_deg
    sd = np.sqrt(mix["bias_var"]) * sb
    sx = np.sqrt(np.einsum("bii->bi", cov))
    with np.errstate(divide="ignore", invalid="ignore"):
        corr = mix["bias_cross"] * sb / (sx[:, None, :] * sd[..., None])
    largest = sb * mix["prior_scale"]
    phi_rms = np.sqrt(mix["posterior"] @ bias_mixture.PHI_GRID ** 2)
    prior = largest * np.sqrt(np.mean(bias_mixture.PHI_GRID ** 2))
    return {"bias_deg": mix["bias"] * sb, "bias_sigma_deg": sd, "bias_target_correlation": corr,
            "bias_prior_deg": np.repeat(prior[:, None], 2, axis=1), "bias_size_deg": phi_rms * largest}


def _inverse_spd(N: np.ndarray):
    inv, singular = inverse3(N)
    return 0.5 * (inv + np.swapaxes(inv, 1, 2)), singular


def _vce_factors(J, E, ok, robust, a=None, terrain_rows=None, vf=None, prior_dof=0.0):
    """Helmert/Foerstner variance component factors (b, 2) (`helmert`: sum_g w e^2 over the redundancy numbers
    r_g = sum_g (1 - w_i h_i), with the prior prior_dof on the current factors vf (b, 2)) over the usable rows of
    each group (pixels: the u and v rows, ranges; rows a redescending loss rejected do not count), h_i the leverage
    of row i in the joint problem (target, and the bias columns a when given, the terrain prior's `_terrain_rows`
    when given), from the standardized J (3,3,n,b), E (3,n,b); and a (b, 2) flag 'usable'."""
    _, w = _cost_weights(E, robust)
    N, _ = _normal(J, E, w)
    hs = _bias_terms(J, a, w) if a is not None else []
    _schur(N, hs)
    if terrain_rows is not None:
        _add_terrain(N, None, *terrain_rows[:2])
    inv = cofactors3(N)[0]
    j0, j1, j2 = J
    quad = (inv[0] * j0 * j0 + inv[3] * j1 * j1 + inv[5] * j2 * j2
            + 2.0 * (inv[1] * j0 * j1 + inv[2] * j0 * j2 + inv[4] * j1 * j2))
    for k, (h, s) in enumerate(hs):
        c = [-sum(inv[FULL3[r][e]] * h[:, e] for e in range(3)) / (1 + s) for r in range(3)]
        czz = 1.0 / (1 + s) - sum(c[e] * h[:, e] for e in range(3)) / (1 + s)
        quad[k] = quad[k] + 2.0 * a[k] * sum(J[e, k] * c[e] for e in range(3)) + a[k] ** 2 * czz
    lev = quad if w is None else w * quad
    q = E * E if w is None else w * E * E
    use = ok if w is None else ok & (w > 0)
    groups = (slice(0, 2), slice(2, 3))
    return helmert(np.stack([_sum_rows(np.where(use[r], q[r], 0.0)) for r in groups], axis=1),
                   np.stack([_sum_rows(np.where(use[r], 1.0 - lev[r], 0.0)) for r in groups], axis=1), vf, prior_dof)


def helmert(q: np.ndarray, red: np.ndarray, vf=None, prior_dof=0.0):
    """The one Helmert/Foerstner variance-component step of every `mle` model: factors (b,2) of the pixel and
    range groups that multiply their current variance factors vf (b,2) (None: 1), from each group's weighted
    r^T C^-1 r q (b,2) at those factors over its redundancy red (b,2) (rows with weight minus the trace of their
    share of the hat matrix). A stated variance (prior_dof (2,) or (b,2) > 0, `vce_prior_dof`) is not shrunk
    below what it gives counted as prior_dof more residuals: the new factor is the larger of vf q / red and
    (vf q + prior_dof) / (red + prior_dof) (a few rows cannot shrink it to nothing; a group the rows say is worse
    than stated keeps what they say: the admission rule and the loss see it; with red < 0.5, as one range, the
    second alone). Usable: red + prior_dof >= 0.5, a finite factor > 0 (else 1)."""
    vf = np.ones_like(q) if vf is None else vf
    n0 = np.broadcast_to(np.asarray(prior_dof, dtype=np.float64), q.shape)
    with np.errstate(divide="ignore", invalid="ignore"):
        own = np.where(red >= 0.5, vf * q / red, 0.0)
        f = np.where(red + n0 >= 0.5, np.maximum(own, (vf * q + n0) / (red + n0)) / vf, 1.0)
        f = np.where(n0 > 0, f, np.where(red >= 0.5, q / red, 1.0))  # no prior: the rows' factor, to the bit
    usable = (red + n0 >= 0.5) & np.isfinite(f) & (f > 0)
    return np.where(usable, f, 1.0), usable
