"""The telemetry errors' model (white, with a boresight bias, or drifting with a correlation time; and, where the sigma
does not state it, their size; or white with a tracker slip) chosen from the flight by evidence, for `mle` on one
problem whose sigma gives no correlation time (docs/solvers.md, "Error model learned from the flight, by evidence"):
the GLS fit (`correlated.gls`) under every candidate of `candidates` (and the problem's `slip_segment`), without the
rows the first solve rejected and without robust weights (the first solve's loss did that job; an iteratively
reweighted GLS fit descends no objective and wandered, docs/solvers.md), each `admitted` one weighted by its
restricted (REML) Gaussian likelihood and the prior of its variance factors (`log_likelihoods`; the slip's less the
price of its search); where the slip is the likeliest its fit is the answer, where the white models hold half of the
posterior the first answer stands, else the answer is the drifting models' posterior mixture, with the fit checks of
the most likely one. A configured correlation time is the same fit with one model, the first solve's robust weights
held (`methods._configured_tau`).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from pipeline.solve import bias_mixture, uncertainty
from pipeline.solve import correlated as _correlated
from pipeline.solve import mle as _mle
from pipeline.solve import starts as _starts
from pipeline.solve.estimate import Status
from pipeline.solve.observations import Sigma
from pipeline.solve.stacked import Stacked

#: candidate correlation times (s); from frame-to-frame to about the length of a survey flight
TAU_GRID_S = (5.0, 10.0, 20.0, 40.0, 80.0, 160.0, 320.0)
#: candidate attitude sigmas (deg) where the sigma states none
ATTITUDE_GRID_DEG = (0.01, 0.03, 0.1, 0.3, 1.0)
#: the boresight bias's prior scale in the white candidates with a bias (`candidates`): the first fit's grid
#: (`bias_mixture.PHI_GRID`) without its 0 (the white model without a bias); the likelihood is sharp in phi (zoo
#: flight s18/z128: 95 log units between phi 0.875 and 1), so a coarser grid let a drift win for want of the bias
WHITE_BIAS_PHI = tuple(float(p) for p in bias_mixture.PHI_GRID[1:])
#: rows of the candidates' fits side by side at most (models x problems x rows): their arrays (~750 bytes per
#: row) stay within a few hundred MB on a 10-minute video at 30 Hz (36,600 rows: 6 models at a time, not a
#: family's 35-45; `python scripts/bench_solvers.py --scale`)
MODEL_ROWS_AT_ONCE = 250_000


#: run lengths of a tracker slip tried one by one (`slip_segment`; all of them on flights of up to 2,048 pixels),
#: longer ones on a geometric grid of this ratio
SLIP_EXACT_LENGTHS = 1024
SLIP_LENGTH_STEP = 1.02


def without_rejected(st: Stacked, rejected: np.ndarray) -> Stacked:
    """st (B = 1) without the pixels (u or v rejected) and ranges the first solve gave zero weight;
    rejected (n, 3) bool."""
    has_pix = st.has_pix & ~rejected[:, :2].any(axis=1)[None]
    has_range = st.has_range & ~rejected[:, 2][None]
    return dataclasses.replace(st, has_pix=has_pix, has_range=has_range)


def slip_segment(st: Stacked, E: np.ndarray, r: np.ndarray) -> _correlated.Slip | None:
    """The tracker-slip candidate of one problem (st B = 1) from its first fit's standardized residuals E (n,3) and
    residuals r (n,3) (px): the run of consecutive frames with a pixel (in time order, at least 2, at most half of
    them) whose residuals' sums (u, v) are largest for its length, |sum e_u|^2 + |sum e_v|^2 over the length (the
    mean-shift statistic); its offset's prior sigma `starts.MAX_OVER_STATED` times the pixel rows' median sigma in
    the first fit (the admission rule's factor), and the number of runs searched (all starts and lengths; the
    evidence gives each the same prior, `_mixture`). None with fewer than 8 such frames. Every run length up to
    SLIP_EXACT_LENGTHS, longer ones on a grid of ratio SLIP_LENGTH_STEP with the best run's ends refined: O(k) per
    length, ~1,100 lengths at most (0.4 s on 18,000 frames)."""
    idx = np.flatnonzero(st.has_pix[0] & np.isfinite(E[:, :2]).all(axis=1))
    idx = idx[np.argsort(st.t_ns[0][idx], kind="stable")]
    k = idx.size
    if k < 8:
        return None
    e = E[idx, :2]
    S = np.vstack([np.zeros((1, 2)), np.cumsum(e, axis=0)])
    longest = k // 2
    lengths = np.arange(2, min(longest, SLIP_EXACT_LENGTHS) + 1)
    if longest > SLIP_EXACT_LENGTHS:  # longer runs on a geometric grid, the best one's ends refined below
        grid = SLIP_EXACT_LENGTHS * SLIP_LENGTH_STEP ** np.arange(1, 1 + int(np.ceil(
            np.log(longest / SLIP_EXACT_LENGTHS) / np.log(SLIP_LENGTH_STEP))))
        lengths = np.concatenate([lengths, np.unique(np.minimum(np.round(grid), longest).astype(np.int64))])
    best, run = 0.0, None
    for length in lengths:
        D = S[length:] - S[:-length]
        t = (D * D).sum(axis=1) / length
        j = int(np.argmax(t))
        if t[j] > best:
            best, run = float(t[j]), (j, j + int(length))
    if run is None:
        return None
    if run[1] - run[0] > SLIP_EXACT_LENGTHS:  # every start and end within a grid step of the best run's
        d = int(np.ceil((SLIP_LENGTH_STEP - 1.0) * (run[1] - run[0]))) + 1
        a = np.arange(max(run[0] - d, 0), run[0] + d + 1)[:, None]
        b = np.arange(run[1] - d, min(run[1] + d, k) + 1)[None, :]
        D = S[b] - S[a]
        with np.errstate(divide="ignore", invalid="ignore"):
            t = np.where((b - a >= 2) & (b - a <= longest), (D * D).sum(axis=-1) / (b - a), -np.inf)
        i, j = np.unravel_index(int(np.argmax(t)), t.shape)
        run = (int(a[i, 0]), int(b[0, j]))
    with np.errstate(divide="ignore", invalid="ignore"):
        sd = np.abs(r[idx, :2] / e)
        prior_px = _starts.MAX_OVER_STATED * float(np.nanmedian(np.where(np.isfinite(sd), sd, np.nan)))
    if not (np.isfinite(prior_px) and prior_px > 0):
        return None
    mask = np.zeros(st.n, dtype=bool)
    mask[idx[run[0]:run[1]]] = True
    runs = (longest - 1) * (k + 1) - (longest * (longest + 1) // 2 - 1)  # sum of k - L + 1 over L = 2 .. longest
    return _correlated.Slip(mask, prior_px, runs)


def log_likelihoods(st: Stacked, Xs: np.ndarray, sigmas: list, vfs: list, biases: list | None = None) -> list:
    """(restricted log L plus the variance factors' prior, chi-square r^T C^-1 r, rows m) of one problem at K points
    Xs (K,3), each under its sigma (and boresight bias prior, deg, or `correlated.Slip`: biases, None: none) and
    variance factors vf (2,) scaling the pixel and range blocks of C (models with the same parts: the candidates),
    in one `correlated.quadratic_forms_stacked`; every row at full weight (the same data under every model); C's
    overall scale k = max(chi2 / m, 1) (the stated sigmas a lower bound: with sigmas stated too small, a model is
    not chosen for hiding the misfit in the target).
    A group with rows whose noise sigma is stated adds the log prior of the variance factor lam = vf k at which C
    takes it: the stated variance counted as n0 = `mle.VCE_PRIOR_DOF` pseudo-residuals, -n0/2 (log lam + 1/lam - 1),
    0 at lam = 1 (the prior `mle.helmert` uses as a floor on a stated variance, here in both directions); a model
    that fits only with a stated sigma several times larger pays for it (zoo flight s72/z036: the position drifting
    with the attitude, its ranges' variance at 26 x the stated, its own fit 65 m off and the answer 45.9 m, was the
    likeliest model by 1 log unit). The first value returned includes that prior."""
    vfs = np.asarray(vfs, dtype=np.float64).reshape(-1, 2)
    biases = biases or [None] * len(sigmas)
    qs: list = [None] * len(sigmas)
    rows = 2 * int(st.has_pix[0].sum()) + int(st.has_range[0].sum())
    for fam in _families(sigmas, rows):  # one `quadratic_forms_stacked` per part of a family (same states)
        K = len(fam)
        models = _correlated.Models.concat([_correlated.problem_models(st, Xs[k], [sigmas[k]], [biases[k]])
                                            for k in fam])
        A = _correlated.rows_in_use(st.take(np.zeros(K, dtype=np.intp)), Xs[fam])
        m = models.Cii.shape[1]
        for k, q in zip(fam, _correlated.quadratic_forms_stacked(models, A, np.ones((K, m)), vfs[fam]), strict=True):
            qs[k] = q
    out = []
    for q, vf, sg in zip(qs, vfs, sigmas, strict=True):
        G = sum(f for f, _, _ in q)
        n0 = np.where([q[0][2] + q[1][2] > 0, q[2][2] > 0], _mle.vce_prior_dof(sg), 0.0)  # groups u, v; range
        logdet = sum(ld for _, ld, _ in q)
        chi2 = float(G[3, 3])
        k = max(chi2 / m, 1.0)
        sign, logdet_n = np.linalg.slogdet(G[:3, :3] / k)
        if sign <= 0:
            out.append((-np.inf, chi2, m))
            continue
        ll = -0.5 * (chi2 / k + m * math.log(k) + logdet + logdet_n + (m - 3) * math.log(2 * math.pi))
        out.append((ll + _variance_prior(vf * k, n0), chi2, m))
    return out


def _variance_prior(lam: np.ndarray, n0: np.ndarray) -> float:
    """The log prior (0 at lam = 1) of the variance factors lam (2,) of the pixel and range groups, each group's
    stated variance counted as n0 (2,) pseudo-residuals (0: no prior), in log lam: its maximum is at lam = 1 and,
    with the rows' likelihood, at (r^T C^-1 r + n0) / (redundancy + n0), the floor `mle.helmert` puts under a
    stated variance."""
    with np.errstate(divide="ignore", invalid="ignore"):
        terms = -n0 / 2 * (np.log(lam) + 1 / lam - 1)
    return float(np.where(n0 > 0, terms, 0.0).sum())


def candidates(sigma: Sigma, bias_deg: float | None = None) -> tuple[list[Sigma], list]:
    """The models weighed by evidence and their boresight bias priors (deg, None: none). sigma under each model of
    the grid of which errors drift x attitude sigma x correlation time (TAU_GRID_S): the stated attitude sigma, or
    ATTITUDE_GRID_DEG where none is stated; the attitude and position errors drifting with one tau; and, where the
    sigma states a position accuracy, the attitude's alone (the position white: a GNSS error that does not wander
    with the attitude must not be modelled as a shared offset; zoo flight z024: 22.5 m tied, 5.2 m white, the white
    family 4.6 log units likelier) or the position's alone (the attitude white: a GNSS drift or multipath step under
    a steady gimbal, `scripts/zoo.py`'s gnss_drift, `scripts/zoo_unseen.py`'s gnss_step). Then the white models (no
    correlation time: the tau -> 0 end of the grid), per attitude sigma without a bias and, given bias_deg (the
    model of `mle`'s first answer: white errors and a bias whose size the flight decides), with a bias of prior phi
    bias_deg for phi in WHITE_BIAS_PHI, the attitude's frame-to-frame part sqrt(1 - phi^2) of the stated one (all
    of it where none is stated). The split is taken also where `mle`'s first answer takes none (where its pixel
    residuals drift). Every model has the same prior: with 21 drifting models against 9 white ones (everything
    stated), the white ones start with 3/10 of the prior."""
    atts = (sigma.attitude_deg,) if sigma.attitude_deg else ATTITUDE_GRID_DEG
    # which errors drift: (attitude, position) both, the attitude alone, the position alone
    kinds = ((True, True), (True, False), (False, True)) if sigma.position_m else ((True, True),)
    models = [(dataclasses.replace(sigma, attitude_tau_s=tau if att_drifts else None,
                                   position_tau_s=tau if pos_drifts else None, attitude_deg=att), None)
              for att_drifts, pos_drifts in kinds for att in atts for tau in TAU_GRID_S]
    split = bool(sigma.attitude_deg)
    for att in atts:
        for phi in (0.0, *(WHITE_BIAS_PHI if bias_deg else ())):
            white_att = att * math.sqrt(1.0 - phi * phi) if split else att
            models.append((dataclasses.replace(sigma, attitude_tau_s=None, position_tau_s=None, attitude_deg=white_att),
                           phi * bias_deg if phi else None))
    return [m[0] for m in models], [m[1] for m in models]


def is_white(sigma: Sigma) -> bool:
    """A candidate without a correlation time (errors independent from frame to frame)."""
    return sigma.attitude_tau_s is None and sigma.position_tau_s is None


def _families(sigmas: list, rows: int) -> list:
    """Index arrays of the sigmas whose models have the same states (`correlated.Models.concat`): both errors
    drifting, the attitude's alone, the position's alone, or both white (no states); each cut into parts of at
    most MODEL_ROWS_AT_ONCE / rows models (rows: the rows of one model's fits side by side, at least one model per
    part), the models fitted side by side at once."""
    kind = np.array([2 * (s.attitude_tau_s is None) + (s.position_tau_s is None) for s in sigmas])
    per = max(1, MODEL_ROWS_AT_ONCE // max(rows, 1))
    return [f[i:i + per] for f in (np.flatnonzero(kind == k) for k in range(4)) for i in range(0, f.size, per)]


def learn_tau(sts: list, X0s: np.ndarray, sigma: Sigma, robust: str | None, vce: bool, tol_m: float,
              max_iterations: int, bias_deg: float | None = None, slips: list | None = None) -> list:
    """Per problem of sts (B = 1 each, without their rejected rows), from its start X0s[i] (3,): the GLS `mle` fit
    under every model of `candidates(sigma, bias_deg)` (correlation time, which errors drift, the white models with
    and without a boresight bias, attitude sigma where unstated), each `admitted` one weighted by its restricted
    likelihood with its variance factors' prior (`log_likelihoods`; equal priors on the models). Each answer is None
    when no model was admitted with an answer; (None, attitude_deg of the likeliest white model, lls, None) where
    the white models hold at least half of the posterior (the first answer stands); else (tau_s of the likeliest
    drifting model (its drifting errors'), its attitude_deg, lls, the `correlated.gls` result tuple of that model
    with the drifting models' posterior mean estimate and mixture covariance (the spread between them included), its
    fit checks and extras, and error_model_tau_s, error_model_attitude_deg, error_model_attitude_tau_s and
    error_model_position_tau_s (NaN: white), error_model_log_likelihoods over TAU_GRID_S at its attitude sigma and
    with the same errors drifting, error_model_spread_m and error_model_within_m (m: the largest standard deviation
    of the models' answers about their mean, and of their own covariances' posterior mean)). lls: {(attitude tau,
    att, position tau), or (None, att, None, bias_deg) for a white model with a bias, or (None, att, None, "slip"):
    log L} of the admitted models. slips: per problem its `slip_segment` (None: no slip candidate), weighed with the
    others less log of the runs searched; where it is the likeliest admitted model the answer is (None, its
    attitude_deg, lls, its `correlated.gls` result with tracker_slip (1,n) and the error-model extras NaN). The
    models' fits of problems with the same rows in use iterate side by side (each as alone: `correlated.gls`). The
    fits are damped GLS on the rows the first solve kept, every row at weight 1 (the robust loss's phases and scale
    guard kept, `correlated.gls`); robust weights updated on the rows' marginal residuals under a correlated C are a
    fixed-point map with no objective, which from starts 1e-6 m apart ended metres to kilometres apart."""
    grid = candidates(sigma, bias_deg)
    slips = slips or [None] * len(sts)
    by_rows: dict[tuple, list[int]] = {}  # the same frames with a pixel and with a range (`Models.concat`: the rest)
    for i, st in enumerate(sts):  # with a slip candidate or without
        by_rows.setdefault((st.n, st.has_pix.tobytes(), st.has_range.tobytes(), slips[i] is None), []).append(i)
    groups = list(by_rows.values())
    out: list = [None] * len(sts)
    while groups:
        g = groups.pop()
        sigmas, biases = list(grid[0]), [list(grid[1]) for _ in g]  # the last candidate each problem's slip
        if slips[g[0]] is not None:
            sigmas.append(dataclasses.replace(sigma, attitude_tau_s=None, position_tau_s=None))
            for b, i in zip(biases, g, strict=True):
                b.append(slips[i])
        try:
            per_problem = fits([sts[i] for i in g], np.asarray([X0s[i] for i in g]), sigmas, robust, vce, tol_m,
                               max_iterations, biases)
        except ValueError:  # the models' states differ (`Models.concat`): one problem at a time
            if len(g) == 1:
                raise
            groups.extend([i] for i in g)
            continue
        for i, f, b in zip(g, per_problem, biases, strict=True):
            out[i] = _mixture(sts[i], sigma, sigmas, f, b)
    return out


def fits(sts: list, X0: np.ndarray, sigmas: list, robust: str | None, vce: bool, tol_m: float,
         max_iterations: int, biases: list | None = None) -> list:
    """Per problem of sts (B = 1 each, the same rows in use) from its start X0[t] (3,): the `correlated.gls` fits
    (`mle.finish`'s tuple over the K sigmas, in their order) under every model of sigmas (with the bias priors
    biases, one per sigma, or per problem a list of them), side by side in parts of at most MODEL_ROWS_AT_ONCE
    rows (`_families`). ValueError where the problems' models differ in their states."""
    K = len(sigmas)
    biases = biases or [None] * K
    per = biases if biases and isinstance(biases[0], list) else [biases] * len(sts)
    rows0 = [_correlated.rows_in_use(st, X0[t]) for t, st in enumerate(sts)]
    per_family = []
    for fam in _families(sigmas, len(sts) * int(rows0[0].shape[0])):
        models = _correlated.Models.concat([_correlated.problem_models(st, X0[t], [sigmas[k] for k in fam],
                                                                      [per[t][k] for k in fam])
                                            for t, st in enumerate(sts)])
        per_family.append((fam, _correlated.gls(sts, X0, models, robust, vce, tol_m, max_iterations, rows0,
                                                prior_dof=_mle.vce_prior_dof(sigmas[fam[0]]))))
    out = []
    for t in range(len(sts)):
        f_t = [None] * 6
        for fam, f in per_family:  # the problem's K fits in the order of sigmas
            sl = slice(t * fam.size, (t + 1) * fam.size)
            for j in range(5):
                if f_t[j] is None:
                    f_t[j] = np.empty((K, *f[j].shape[1:]), dtype=f[j].dtype)
                f_t[j][fam] = f[j][sl]
            if f_t[5] is None:
                f_t[5] = {key: np.empty((K, *v.shape[1:]), dtype=v.dtype) for key, v in f[5].items()}
            for key, v in f[5].items():
                f_t[5][key][fam] = v[sl]
        out.append(tuple(f_t))
    return out


def admitted(stated: Sigma, candidate: Sigma, vf_pixel: float, vf_range: float, scale: float = 1.0) -> bool:
    """Whether a candidate's fit stays within `starts.MAX_OVER_STATED` times the stated sigmas: the range noise,
    the attitude error (the candidate's attitude sigma times the pixel rows' factor; the pixel noise where no
    attitude sigma is stated) and the likelihood's overall scale k of its covariance (`log_likelihoods`; `_mixture`
    passes it for the candidates whose answer would replace the first, drifts and slips: a white model's evidence
    keeps the first answer). A fit that needs more explains those observations away (zoo s0/z162: the ranges'
    variance 121 x the stated, 1,062 m off, the likeliest model; unseen s11/u039, the laser sigma stated 4-6 x too
    small: drifts within 9 x by their factors at k 13-22, 11.0 m off; docs/validation.md, "How the MLE
    got here")."""
    k = _starts.MAX_OVER_STATED
    if not scale <= k * k:
        return False
    if stated.range_m and not vf_range <= k * k:
        return False
    if stated.attitude_deg:
        return candidate.attitude_deg * math.sqrt(vf_pixel) <= k * stated.attitude_deg
    return not stated.pixel_px or vf_pixel <= k * k


def _mixture(st: Stacked, stated: Sigma, sigmas: list, out: tuple, biases: list):
    """`learn_tau`'s answer from the candidates' fits out (`mle.finish`'s tuple over the K sigmas, with their
    boresight biases), over the `admitted` ones."""
    lls: dict[tuple, float] = {}
    fits = []  # (log L, candidate index, its fit)
    X, status = out[0], out[2]
    answered = [k for k in range(len(sigmas)) if status[k] not in (Status.DIVERGED, Status.DEGENERATE)
                and np.isfinite(X[k]).all()]
    vfs = [(float(out[5]["variance_factor_pixel"][k]), float(out[5]["variance_factor_range"][k])) for k in answered]
    lk = log_likelihoods(st, X[answered], [sigmas[k] for k in answered], vfs,
                         [biases[k] for k in answered]) if answered else []
    for k, (ll, chi2, m), vf in zip(answered, lk, vfs, strict=True):
        c, slip = sigmas[k], isinstance(biases[k], _correlated.Slip)
        bias = 0.0 if slip else biases[k] or 0.0
        total = dataclasses.replace(c, attitude_deg=math.hypot(c.attitude_deg or 0.0, bias))
        # the covariance's overall scale limits what can replace the first answer (a drift, a slip) only: a bias
        # alone, without the white attitude error, fits many a bias flight best at k up to 12 (zoo s31/z205)
        scale = max(chi2 / m, 1.0) if slip or not is_white(c) else 1.0
        if not (np.isfinite(ll) and admitted(stated, total, *vf, scale=scale)):
            continue
        key = (c.attitude_tau_s, c.attitude_deg, c.position_tau_s) + (("slip",) if slip else (biases[k],) if biases[k]
                                                                      else ())
        if slip:  # one run of those searched, each a priori as likely: the search's price (look-elsewhere)
            ll = ll - math.log(biases[k].runs)
        lls[key] = ll
        fits.append((ll, k, (out[0][k:k + 1], out[1][k:k + 1], out[2][k:k + 1], out[3][k:k + 1], out[4][k:k + 1],
                             {key: v[k:k + 1] for key, v in out[5].items()})))
    if not fits:
        return None
    ll = np.array([f[0] for f in fits])
    post = np.exp(ll - ll.max())
    post /= post.sum()
    _, k_top, top = fits[int(np.argmax(ll))]
    if isinstance(biases[k_top], _correlated.Slip):  # a tracker slip explains the flight best: its fit
        ex = {**top[5], "tracker_slip": biases[k_top].mask[None], **_no_drift(sigmas[k_top].attitude_deg)}
        return None, sigmas[k_top].attitude_deg, lls, (*top[:5], ex)
    white = np.array([is_white(sigmas[f[1]]) for f in fits])
    if post[white].sum() >= 0.5:  # the evidence is for errors independent from frame to frame
        return None, sigmas[fits[int(np.argmax(np.where(white, ll, -np.inf)))][1]].attitude_deg, lls, None
    # the posterior mixture over the drifting models: the mean, and the covariance with the spread between them
    fits = [f for f, w in zip(fits, white, strict=True) if not w]
    ll, post = ll[~white], post[~white] / post[~white].sum()
    _, k_best, (_, it, status, cond, _, ex) = fits[int(np.argmax(ll))]
    Xs = np.array([f[2][0][0] for f in fits])
    covs = np.array([f[2][4][0] for f in fits])
    Xm = post @ Xs
    d = Xs - Xm
    cov = np.einsum("k,kij->ij", post, covs + d[:, :, None] * d[:, None, :])
    within = np.einsum("k,kij->ij", post, covs)  # the models' own uncertainty; the rest is their answers' spread
    best = sigmas[k_best]
    a_tau, p_tau, att = best.attitude_tau_s, best.position_tau_s, best.attitude_deg
    tau = a_tau if a_tau is not None else p_tau  # the drifting errors' (one tau when both drift)
    ex = {**ex, "error_model_tau_s": np.array([tau]), "error_model_attitude_deg": np.array([att]),
          "error_model_attitude_tau_s": np.array([np.nan if a_tau is None else a_tau]),
          "error_model_position_tau_s": np.array([np.nan if p_tau is None else p_tau]),
          "error_model_log_likelihoods": np.array([[lls.get((t if a_tau else None, att, t if p_tau else None), np.nan)
                                                    for t in TAU_GRID_S]]),
          "error_model_spread_m": uncertainty.ellipsoid(np.einsum("k,ki,kj->ij", post, d, d)[None])[0][:, -1],
          "error_model_within_m": uncertainty.ellipsoid(within[None])[0][:, -1]}
    return tau, att, lls, (Xm[None], it, status, cond, cov[None], ex)


def _no_drift(attitude_deg: float | None) -> dict:
    """The error-model extras of an answer whose errors are modelled white (NaN: no correlation time)."""
    nan = np.array([np.nan])
    return {"error_model_tau_s": nan, "error_model_attitude_deg": np.array([attitude_deg or np.nan]),
            "error_model_attitude_tau_s": nan, "error_model_position_tau_s": nan,
            "error_model_log_likelihoods": np.full((1, len(TAU_GRID_S)), np.nan),
            "error_model_spread_m": nan, "error_model_within_m": nan}
