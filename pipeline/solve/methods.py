"""The eight estimators behind `solve`, `solve_batch` and `solve_problems`: option checks, each method's dispatch
to its batched kernel, and for one problem the checks of unusable input and its `Estimate`. One implementation
per estimator: `solve(method, obs)` runs the kernel of `solve_batch` on a batch of one."""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

import numpy as np

from pipeline.errors import GeometryError, ObservationError, RidgelocError, SolverError
from pipeline.solve import correlated as _correlated
from pipeline.solve import fit_checks, least_squares, linear, mle_outputs, uncertainty
from pipeline.solve import learned_tau as _learned
from pipeline.solve import mle as _mle
from pipeline.solve import starts as _starts
from pipeline.solve.estimate import BatchEstimate, Estimate, Status
from pipeline.solve.iterate import start_status
from pipeline.solve.observations import REAL_TIMES_NS, ObservationBatch, Observations, Sigma
from pipeline.solve.stacked import Stacked, pixel_model, range_model
from pipeline.solve_options import METHODS, NOT_IN_CONFIG, OPTIONS

# the keyword options of each method: the config table's, plus what only code can pass (terrain: a function)
_OPTIONS = {m: {o.name for o in OPTIONS[m]} | NOT_IN_CONFIG.get(m, frozenset()) for m in METHODS}
_USES_PIXELS = {"dlt", "vision", "fusion-raw", "fusion", "ridge", "mle"}
#: the white fit's boresight bias beyond this many stated attitude sigmas (the bias's largest prior until a misfit
#: scales it; `mle.DEFAULT_BIAS_PRIOR_DEG` where none is stated) calls the evidence step: under the stated model
#: that happens on < 5 % of flights per axis (a prior of at most N(0, sigma^2), the posterior mean shrunk); a
#: drift whose mean over the flight is large (a random walk, a long correlation time) does it (docs/validation.md,
#: "How the MLE got here")
BIAS_BEYOND_STATED = 2.0


def _check_options(method: str, options: dict) -> dict:
    if method not in METHODS:
        raise ValueError(f"unknown method {method!r}; choose one of {', '.join(METHODS)}")
    unknown = sorted(set(options) - _OPTIONS[method])
    if unknown:
        raise ValueError(f"method {method!r} takes no option(s) {', '.join(unknown)}; it takes "
                         f"{', '.join(sorted(_OPTIONS[method])) or 'none'}")
    o = dict(options)
    tol = float(o.get("tol_m", 1e-4))
    if not tol > 0:
        raise ValueError(f"tol_m must be > 0, got {tol}")
    o["tol_m"] = tol
    it = o.get("max_iterations", 50)
    if isinstance(it, bool) or not isinstance(it, (int, np.integer)) or it < 1:
        raise ValueError(f"max_iterations must be an integer >= 1, got {it!r}")
    o["max_iterations"] = int(it)
    if o.get("hkb", "paper") not in least_squares.HKB_VARIANTS:
        raise ValueError(f"hkb must be one of {least_squares.HKB_VARIANTS}, got {o['hkb']!r}")
    if o.get("k") is not None and not (np.isfinite(o["k"]) and o["k"] >= 0):
        raise ValueError(f"k must be a finite number >= 0, got {o['k']!r}")
    if o.get("robust", _mle.DEFAULT_ROBUST) not in _mle.ROBUST_LOSSES:
        raise ValueError(f"robust must be one of {_mle.ROBUST_LOSSES}, got {o['robust']!r}")
    b = o.get("bias_prior_deg")
    if b is not None and (isinstance(b, bool) or not isinstance(b, (int, float)) or not np.isfinite(b) or b < 0):
        raise ValueError(f"bias_prior_deg must be a finite number >= 0 (0: no bias estimation), got {b!r}")
    t = o.get("terrain")
    if t is not None:
        ok = isinstance(t, (tuple, list)) and len(t) == 2 and callable(t[0])
        sm = t[1] if ok else None
        if not ok or isinstance(sm, bool) or not isinstance(sm, (int, float)) or not (np.isfinite(sm) and sm > 0):
            raise ValueError("terrain must be (fn, sigma_m): fn(e_m, n_m) -> (up_m, dup_de, dup_dn) in the "
                             f"solve's ENU frame and a finite vertical sigma_m > 0, got {t!r}")
        o["terrain"] = (t[0], float(sm))
    s = o.get("sigma")
    if isinstance(s, dict):
        o["sigma"] = Sigma.from_dict(s, "sigma option")
    elif s is not None and not isinstance(s, Sigma):
        raise ValueError(f"sigma must be a Sigma or a dict, got {type(s).__name__}")
    return o


def _initial(options: dict, B: int):
    x0 = options.get("initial_m")
    if x0 is None:
        return None
    x0 = np.asarray(x0, dtype=np.float64)
    if x0.shape == (3,):
        x0 = np.broadcast_to(x0, (B, 3)).copy()
    if x0.shape != (B, 3) or not np.isfinite(x0).all():
        raise ValueError(f"initial_m must be 3 finite numbers or ({B}, 3) of them, got shape {x0.shape}")
    return x0


def _vision(st: Stacked, o: dict):
    """vision's (X (B,3), iterations, status, cond) from initial_m, else from the DLT point: copies of
    o["vision_from_dlt"] where the caller has that answer (`_mle_multistart`: the start methods that begin
    from vision)."""
    x0, init_status = _initial(o, st.size), None
    if x0 is None and "vision_from_dlt" in o:
        return tuple(np.array(a, copy=True) for a in o["vision_from_dlt"])
    if x0 is None:
        x0, init_status, _ = linear.dlt(st, with_condition=False)
    return least_squares.vision(st, x0, o["tol_m"], o["max_iterations"], init_status)


def _vision_init(st: Stacked, o: dict):
    """The start of the methods that begin from vision: initial_m (status None), else vision's answer (one that
    hit the iteration limit is still a usable start) and its status."""
    x0 = _initial(o, st.size)
    if x0 is not None:
        return x0, None
    X, _, status, _ = _vision(st, o)
    return X, status


def _boresight_start(st: Stacked) -> np.ndarray:
    """(B,3) range-only's start without pixels: the component-wise median over the ranged frames of the point at
    the laser range along the camera's optical axis (M's third row, to the front); NaN without a range."""
    m3 = st.M[..., 2, :] * st.depth_sign()[..., None]
    axis = m3 / np.linalg.norm(m3, axis=-1, keepdims=True)
    pts = np.where(st.has_range[..., None], st.platform_m + np.where(st.has_range, st.range_m, 0.0)[..., None] * axis,
                   np.nan)
    X = np.full((st.size, 3), np.nan)
    some = st.has_range.any(axis=1)
    X[some] = np.nanmedian(pts[some], axis=1)
    return X


def _range_init(st: Stacked, o: dict):
    """range's start: vision's estimate (the paper's), or with fewer than two pixels the boresight start. (Where
    vision fails on two or more pixels, range keeps its status: the simulation counts those trials as flagged.)"""
    x0, init_status = _vision_init(st, o)
    if init_status is None:  # initial_m given
        return x0, init_status
    few = st.has_pix.sum(axis=1) < 2
    if few.any():
        x0[few] = _boresight_start(st.take(np.flatnonzero(few)))
        init_status = np.asarray(init_status).copy()
        init_status[few] = np.where(np.isfinite(x0[few]).all(axis=1), Status.CLOSED_FORM, Status.DEGENERATE)
    return x0, init_status


def _solve_stacked(method: str, st: Stacked, o: dict, first: tuple | None = None,
                   answers: dict | None = None) -> BatchEstimate:
    """One method's kernel on the batch st; for mle, first is its fit from the default start where the caller has it
    and answers the start estimators' answers for the multistart (`_mle_multistart`)."""
    B = st.size
    tol, itmax = o["tol_m"], o["max_iterations"]
    extras: dict = {}
    cov, it = None, np.zeros(B, dtype=np.int64)  # the closed-form methods' iterations
    if method == "dlt":
        X, status, cond = linear.dlt(st)
    elif method == "los":
        X, status, pts, oracle = linear.los(st)
        cond = np.full(B, np.nan)
        extras = {"points_m": pts, "oracle_error_m": oracle}
    elif method == "vision":
        X, it, status, cond = _vision(st, o)
    elif method == "range":
        x0, init_status = _range_init(st, o)
        X, it, status, cond, flat = least_squares.range_only(st, x0, tol, itmax, init_status)
        extras = {"collinear_platforms": flat}
    elif method == "fusion-raw":
        x0, init_status = _vision_init(st, o)
        X, it, status, cond = least_squares.fusion_raw(st, x0, tol, itmax, init_status)
    elif method in ("fusion", "ridge"):
        x0, init_status = _vision_init(st, o)
        k = o.get("k") if method == "ridge" else None
        hkb = o.get("hkb", "paper") if method == "ridge" and k is None else None
        X, it, status, cond, ex = least_squares.normalized_fusion(st, x0, tol, itmax, init_status, k=k, hkb=hkb)
        extras = {"augmented_component": ex["augmented"]}
        if method == "ridge":
            extras["k"] = ex["k"]
    elif method == "mle":
        if st.size == 1 and o.get("initial_m") is None:
            X, it, status, cond, cov, ex = _mle_multistart(st, o, first, answers)
        else:
            X, it, status, cond, cov, ex = first if first is not None else _mle_dispatch(st, o)
        extras = {**uncertainty.summaries(cov), **ex}
    else:  # pragma: no cover - _check_options rejects it
        raise ValueError(method)
    be = BatchEstimate(method=method, position_m=X, iterations=it, status=status.astype(np.int8),
                       condition_number=cond, covariance_m2=cov, extras=extras)
    return _mark_behind(st, be) if method in _USES_PIXELS else be


def _mark_behind(st: Stacked, be: BatchEstimate) -> BatchEstimate:
    """be with the answers behind a camera with a pixel DEGENERATE and NaN (in place), the flags in extras."""
    behind = _behind_camera(st, be.position_m)
    if behind.any():
        be.status[behind] = Status.DEGENERATE
        be.position_m[behind] = np.nan
    be.extras["behind_camera"] = behind
    return be


def _mle_start(st: Stacked, o: dict):
    """(B,3) starts and their status, the sigma and whether to estimate variance components: the DLT point; where
    fewer than two pixels, or it is not in front of every camera with a pixel (no baseline), the line-of-sight
    median; then, with a terrain prior, the first line of sight met with the terrain."""
    x0 = _initial(o, st.size)
    init_status = None
    if x0 is None:
        near = 1e-3 * (1.0 + st.range_m.max(axis=1, keepdims=True))
        x0, init_status, _ = linear.dlt(st, with_condition=False)
        need = ~np.isfinite(x0).all(axis=1)
        need |= ((st.depths(np.where(need[:, None], 0.0, x0)) <= near) & st.has_pix).any(axis=1)
        if need.any():
            Xl, sl, _, _ = linear.los(st.take(np.flatnonzero(need)))
            x0[need], init_status[need] = Xl, sl
        if o.get("terrain") is not None:
            need = ~np.isfinite(x0).all(axis=1)
            if need.any():
                x0[need], init_status[need] = _terrain_start(st.take(np.flatnonzero(need)), o["terrain"][0])
    return x0, init_status, *_mle_sigma(st, o)


def _mle_sigma(st: Stacked, o: dict):
    """The mle's sigma (the option's, else the observations') and whether to estimate variance components."""
    sigma = o.get("sigma") or st.sigma
    vce = o.get("estimate_variance_components")
    if vce is None:
        vce = sigma.pixel_px is None or sigma.range_m is None
    return sigma, bool(vce)


def _terrain_start(st: Stacked, fn) -> tuple[np.ndarray, np.ndarray]:
    """(B,3) starts and their status: the first pixel's line of sight met with the terrain fn (Newton on the
    distance t along the ray, from the terrain below the camera); NaN and DEGENERATE where it does not meet it
    in front of the camera."""
    b = np.arange(st.size)
    k = np.argmax(st.has_pix, axis=1)  # the first frame with a pixel
    M, uv1 = st.M[b, k], np.concatenate([st.pix[b, k], np.ones((st.size, 1))], axis=1)
    c = -np.linalg.solve(M, st.p4[b, k][..., None])[..., 0]
    d = np.linalg.solve(M, uv1[..., None])[..., 0] * np.sign(np.linalg.det(M))[:, None]  # in front: depth > 0
    d = d / np.linalg.norm(d, axis=1, keepdims=True)
    t = np.zeros(st.size)
    todo = np.flatnonzero(st.has_pix.any(axis=1))
    for _ in range(50):
        if not todo.size:
            break
        x = c[todo] + t[todo, None] * d[todo]
        up, de, dn = (np.asarray(v, dtype=np.float64).reshape(-1) for v in fn(x[:, 0], x[:, 1]))
        f = x[:, 2] - up
        df = d[todo, 2] - de * d[todo, 0] - dn * d[todo, 1]
        ok = np.isfinite(f) & np.isfinite(df) & (df != 0)
        dt = -f[ok] / df[ok]
        t[todo[ok]] += dt
        more = np.zeros(todo.size, dtype=bool)
        more[ok] = np.abs(dt) >= 1e-6 * (1.0 + np.abs(t[todo[ok]]))
        todo = todo[more]
    X = c + t[:, None] * d
    good = st.has_pix.any(axis=1) & (t > 0) & np.isfinite(X).all(axis=1)
    X[~good] = np.nan
    return X, np.where(good, Status.CONVERGED, Status.DEGENERATE).astype(np.int8)


def _mle_dispatch(st: Stacked, o: dict):
    """`mle.mle` on the batch; for one problem whose sigma has correlation times (a non-diagonal residual
    covariance) that white fit, then the GLS fit of the configured model from it (`_configured_tau`); else the
    error model chosen by evidence (`_with_learned_tau`) where the residuals drift, the chi-square is too small,
    the variance components need a stated sigma beyond 3 x or the boresight bias comes out beyond
    BIAS_BEYOND_STATED x the stated attitude sigma; where the chi-square is too large, only a tracker slip's."""
    x0, init_status, sigma, vce = _mle_start(st, o)
    robust, tol, itmax = o.get("robust", _mle.DEFAULT_ROBUST), o["tol_m"], o["max_iterations"]
    bias_deg, size_unknown = _mle.bias_prior_deg(sigma, o)  # configured correlation times win, even vanishing ones
    configured = False
    if sigma.correlated:
        if st.t_ns is None:
            raise ValueError("mle with time-correlated errors (sigma attitude_tau_s / position_tau_s) needs the "
                             "frames' timestamps: use solve() per problem; solve_batch() has no t_ns")
        if not start_status(x0, init_status)[1][0]:  # an unusable start: the white fit reports it
            configured = bool(_correlated.problem_models(st, x0[0], [sigma]).correlated[0])
        if configured and o.get("terrain") is not None:
            raise ValueError("mle: the terrain option is not available with time-correlated errors (sigma "
                             "attitude_tau_s / position_tau_s)")
    white = dataclasses.replace(sigma, attitude_tau_s=None, position_tau_s=None)
    if configured:  # the configured error model wins: no boresight bias (the GLS has none), even when asked for
        res = _mle.mle(st, x0, white, robust, vce, tol, itmax, init_status, None, False)
        return _configured_tau(st, o, res, sigma, vce)
    res = _mle.mle(st, x0, white, robust, vce, tol, itmax, init_status, bias_deg, size_unknown, o.get("terrain"))
    beyond = np.zeros(st.size, dtype=bool)
    if bias_deg and size_unknown:
        with np.errstate(invalid="ignore"):
            beyond = (np.abs(res[5]["bias_deg"]) > BIAS_BEYOND_STATED * bias_deg).any(axis=1)
    res = _bias_refit(st, o, x0, init_status, white, vce, res, bias_deg, size_unknown)
    return _with_learned_tau(st, o, res, white, vce, size_unknown, bias_deg, beyond)


def _configured_tau(st: Stacked, o: dict, res: tuple, sigma, vce: bool) -> tuple:
    """One problem's answer under the configured correlation times from its white fit res (`mle.mle` with the
    marginal variances, no bias, B = 1): the damped GLS fit (`correlated.gls`, the fit of each learned candidate)
    from the white answer on the rows it kept, with its robust weights held (`_held`), finished by `_drift_answer`
    (a GLS that diverges or is degenerate reports that status); res where the white fit has no answer."""
    if not np.isfinite(res[0]).all():
        return res
    sub = _learned.without_rejected(st, res[5]["rejected"][0])
    models = _correlated.problem_models(sub, res[0][0], [sigma])
    fit = _correlated.gls([sub], res[0], models, o.get("robust", _mle.DEFAULT_ROBUST), vce, o["tol_m"],
                          o["max_iterations"], weights=_held(res[5], o)[None], prior_dof=_mle.vce_prior_dof(sigma))
    return _drift_answer(st, res, fit)


def _held(ex: dict, o: dict) -> np.ndarray:
    """(3,n) the white fit's (extras ex, B = 1) final robust weights of the u, v and range rows, from its residuals
    as it weighed them (`White.adjust` reports its own residuals where no bias mixture moved them: a configured
    correlation time has no bias)."""
    E = ex["residual_sigmas"][0].T[..., None]  # (3,n,1)
    w = _mle._cost_weights(np.where(np.isfinite(E), E, 0.0), o.get("robust", _mle.DEFAULT_ROBUST))[1]
    return np.ones(E.shape[:2]) if w is None else w[..., 0]


def _bias_refit(st: Stacked, o: dict, x0: np.ndarray, init_status, sigma, vce: bool, res: tuple, bias_deg,
                size_unknown: bool) -> tuple:
    """The independent-error fit res (`mle.mle` from x0 with the bias prior bias_deg) refitted without the bias
    where the bias came out far beyond the stated attitude sigma."""
    robust, tol, itmax = o.get("robust", _mle.DEFAULT_ROBUST), o["tol_m"], o["max_iterations"]
    if bias_deg and size_unknown:
        # the stated attitude sigma is the largest bias: a bias estimated far beyond it (as the learned drift
        # model's limit) is the bias explaining the pixels away, not a bias of this flight; refit without it
        far = np.abs(res[5]["bias_deg"]).max(axis=1) > _starts.MAX_OVER_STATED * bias_deg
        if far.any():
            idx = np.flatnonzero(far)
            sub = st.take(idx)
            r2 = _mle.mle(sub, x0[idx], sigma, robust, vce, tol, itmax, None if init_status is None
                          else init_status[idx], None, False, o.get("terrain"))
            # the error model is wrong here either way: the covariance keeps the spread between the two answers
            # (the between-model term of a model average), so that the refit claims no accuracy it lacks, and
            # the GNSS error shared by the segment (position_m^2 I) the bias's answer carries (`mle.mle`)
            d = res[0][idx] - r2[0]
            d = np.where(np.isfinite(d), d, 0.0)
            shared = (sigma.position_m or 0.0) ** 2 * np.eye(3)
            r2 = (*r2[:4], r2[4] + shared + d[:, :, None] * d[:, None, :], r2[5])
            res = _replace_rows(res, r2, idx)
    return res


def _with_learned_tau(st: Stacked, o: dict, res: tuple, sigma, vce: bool, size_unknown: bool,
                      bias_deg: float | None, beyond: np.ndarray) -> tuple:
    """res with each problem's answer replaced by the learned drift model's (`learned_tau.learn_tau` with res's
    model, white errors and a boresight bias of prior bias_deg, among the candidates; `_learned_answer`) where
    the first fit's residuals drift (at lag 1 or over blocks of frames, the batch-means test: a slow drift under
    white noise shows in the second only), its chi-square is below its lower CHI2_ALPHA tail (the stated errors
    do not show from frame to frame: they are slow, or smaller), its variance components need a stated sigma
    beyond `starts.MAX_OVER_STATED` times (the rule every candidate is held to, `learned_tau.admitted`: a white
    fit that puts the ranges' sigma at 17 x the stated explains them away) or its boresight bias came out beyond
    BIAS_BEYOND_STATED x the stated attitude sigma (beyond (B,) bool: the mean of a drift larger than the stated
    attitude error), it has real and distinct timestamps (frames that repeat a time are at one instant, which no
    correlation time can tell apart) and the configured sigma gives no correlation time; not with a terrain prior
    (the drift model takes none). Where only the chi-square is above its upper CHI2_ALPHA tail (a misfit), the
    evidence's answer is taken only if it is a tracker slip: a drift that absorbs a misfit claims an accuracy the
    flight lacks where the stated sigmas are simply too small (docs/validation.md, "How the MLE got here")."""
    if st.t_ns is None or not size_unknown or o.get("terrain") is not None:
        return res
    ex, t = res[5], st.t_ns
    span = t.max(axis=1) - t.min(axis=1) if t.shape[1] > 1 else np.zeros(st.size, dtype=np.int64)
    p = np.where(np.isfinite(ex["chi2_p"]), ex["chi2_p"], 0.5)
    too_small, too_large = p > 1.0 - fit_checks.CHI2_ALPHA, p < fit_checks.CHI2_ALPHA
    inadmissible = np.array([not _learned.admitted(sigma, sigma, float(vp), float(vr)) for vp, vr in
                             zip(ex["variance_factor_pixel"], ex["variance_factor_range"], strict=True)])
    flagged = (ex["drift_pixel"] | ex["drift_range"] | ex["block_drift_pixel"] | ex["block_drift_range"] | too_small
               | inadmissible | beyond)
    distinct = (np.diff(np.sort(t, axis=1), axis=1) > 0).all(axis=1)  # a drift has no time between repeated times
    need = np.flatnonzero(np.isfinite(res[0]).all(axis=1) & (span >= REAL_TIMES_NS) & distinct & (flagged | too_large))
    if not need.size:
        return res
    sts = [_learned.without_rejected(st.take(np.array([b])), ex["rejected"][b]) for b in need]
    slips = [_learned.slip_segment(s, ex["residual_sigmas"][b], ex["residuals"][b]) for s, b in zip(sts, need,
                                                                                                    strict=True)]
    learned = _learned.learn_tau(sts, res[0][need], sigma, o.get("robust", _mle.DEFAULT_ROBUST), vce, o["tol_m"],
                                 o["max_iterations"], bias_deg, slips)
    for b, got in zip(need, learned, strict=True):
        if not flagged[b] and (got is None or got[3] is None or "tracker_slip" not in got[3][5]):
            continue  # a misfit alone: only a tracker slip's answer replaces the first
        row = _row(res, b)
        answer = _learned_answer(st.take(np.array([b])), row, got)
        if answer is not row:  # the drift model's answer was kept
            res = _replace_rows(res, answer, np.array([b]))
    return res


def _replace_rows(res: tuple, sub: tuple, idx: np.ndarray) -> tuple:
    """The mle answers res (X, it, status, cond, cov, extras) with problems idx replaced by sub's; an extra only
    one of them has is absent (`_absent`) for the other's problems."""
    out = [a.copy() for a in res[:5]]
    for a, b in zip(out, sub[:5], strict=True):
        a[idx] = b
    ex = {}
    for k in {**res[5], **sub[5]}:  # res's keys, then sub's others
        old, new = res[5].get(k), sub[5].get(k)
        like = old if old is not None else new
        dtype, fill = _absent(like.dtype) if old is None or new is None else (np.result_type(old, new), None)
        ex[k] = np.empty((res[0].shape[0], *like.shape[1:]), dtype=dtype)
        ex[k][...] = old if old is not None else fill
        ex[k][idx] = new if new is not None else fill
    return (*out, ex)


def _absent(dtype: np.dtype) -> tuple:
    """(dtype, value) that marks an extra a problem lacks: False for a flag, None for an object, else NaN."""
    return {"b": (np.dtype(bool), False), "O": (np.dtype(object), None)}.get(dtype.kind, (np.dtype(np.float64), np.nan))


def _mle_multistart(st: Stacked, o: dict, first: tuple | None = None, answers: dict | None = None):
    """`_mle_dispatch` on one problem, never an answer that explains the pixels away (`starts`; docs/solvers.md):
    if the default start's fit does, mle runs again from every other estimator's answer and keeps the fit of the
    lowest common robust cost among those that do not; when all do, DEGENERATE with the reason in
    `not_determined`. Other estimators' answers outside the kept fit's 99.9 % ellipsoid are listed (`disagree`).
    first: the default start's fit where the caller has it; answers: {method: BatchEstimate (B = 1)} of start
    estimators solved with the mle's tol_m and max_iterations and no other option, not solved again."""
    res = _mle_dispatch(st, o) if first is None else first
    npix = int(st.has_pix[0].sum())
    cands = {}
    plain = {"tol_m": o["tol_m"], "max_iterations": o["max_iterations"]}
    for name in _starts.START_METHODS:
        be = (answers or {}).get(name)
        if be is None:
            if name in ("vision", "fusion", "range") and "vision_from_dlt" not in plain:  # each begins from it
                plain["vision_from_dlt"] = _vision(st, plain)
            try:
                be = _solve_stacked(name, st, plain)
            except (ValueError, np.linalg.LinAlgError):  # pragma: no cover - the kernels report failures as statuses
                continue
        X, s = be.position_m[0], int(be.status[0])
        if np.isfinite(X).all() and s not in (Status.DEGENERATE, Status.DIVERGED) and (
                name != "range" or s == Status.CONVERGED):
            cands[name] = X
    finite = bool(np.isfinite(res[0][0]).all())
    why = _starts.explains_away(res[5], npix) if finite else "no estimate"
    runs = [("default", res, why)]
    if why is not None:
        tried = [res[0][0]] if finite else []
        for name, c in cands.items():
            if all(np.linalg.norm(c - t) > _starts.SAME_START_M for t in tried):
                r = _mle_dispatch(st, {**o, "initial_m": c[None]})
                ok = bool(np.isfinite(r[0][0]).all()) and not _behind_camera(st, r[0])[0]
                runs.append((name, r, _starts.explains_away(r[5], npix) if ok else "no estimate"))
                tried.append(c)
    good = [(n, r) for n, r, w in runs if w is None]
    points = np.array([c for c in cands.values()] or [res[0][0]])
    consensus = np.median(points, axis=0) if np.isfinite(points).all() else res[0][0]
    sigma = o.get("sigma") or st.sigma
    costs = {}
    if good:
        yard = _starts.yardstick(st, sigma, np.array([r[0][0] for _, r in good]), consensus)
        costs = {n: float(c) for (n, _), c in zip(good, yard, strict=True)}
        # another start's fit replaces the default start's only where it fits clearly better (ties: the default)
        k = int(np.argmin(yard))
        if good[0][0] == "default" and not yard[k] < yard[0] - _starts.CLEARLY_BETTER * max(yard[0], 1.0):
            k = 0
        name, res = good[k]
        reason = None
    else:  # none: not determined (a default fit with no estimate keeps its own status and reason)
        name, reason = "default", runs[0][2] if finite else None
    X, it, status, cond, cov, ex = res
    ex = dict(ex)
    if reason is not None and np.isfinite(X[0]).all():
        X, cov = np.full_like(X, np.nan), np.full_like(cov, np.nan)
        status = np.full_like(status, Status.DEGENERATE)
    dis = _starts.disagreement(X[0], cov[0], cands) if np.isfinite(X[0]).all() else {}
    ex["starts"] = np.array([{"chosen": name, "not_determined": reason,
                              "refits": {n: w or "fitted" for n, _, w in runs[1:]}, "yardstick": costs,
                              "candidates": {k: {"position_m": v.tolist(), "chi2_vs_mle": dis.get(k)}
                                             for k, v in cands.items()},
                              "disagree": sorted(k for k, v in dis.items() if v > _starts.DISAGREE_CHI2)}],
                            dtype=object)
    return X, it, status, cond, cov, ex


def _learned_answer(st: Stacked, res: tuple, got) -> tuple:
    """One problem's answer (st, B = 1) from its first answer res and `learned_tau.learn_tau`'s got for it: the
    drift model's where the evidence is for a drift (`learned_tau`: the white models hold less than half of the
    admitted models' posterior), its attitude sigma times the pixel group's variance factor (variance components
    scale the whole pixel covariance); else res itself."""
    if got is None or got[3] is None:
        return res
    exg = got[3][5]
    exg = {**exg, "error_model_attitude_deg": exg["error_model_attitude_deg"] * np.sqrt(exg["variance_factor_pixel"])}
    return _drift_answer(st, res, (*got[3][:5], exg))


def _drift_answer(st: Stacked, res: tuple, fit: tuple) -> tuple:
    """One problem's answer (st, B = 1) from the GLS fit of a drift model (learned or configured) on the rows its
    white fit res kept: fit's, with the rows res rejected (left out of the fit's data) rejected, their residuals
    at fit's position (standardized by the white fit's sigmas of those rows), and the iterations of both."""
    Xg, it, status, cond, cov, exg = fit
    ex = res[5]
    out = dict(exg)
    rej = ex["rejected"]
    out["rejected"] = rej | exg["rejected"]
    if rej.any() and np.isfinite(Xg).all():
        r = np.concatenate([pixel_model(st, Xg)[1].reshape(1, -1, 2), range_model(st, Xg)[1][..., None]], axis=2)
        with np.errstate(divide="ignore", invalid="ignore"):
            isd = np.where(ex["residuals"] != 0, ex["residual_sigmas"] / ex["residuals"], 0.0)
        out["residuals"] = np.where(rej, r, exg["residuals"])
        out["residual_sigmas"] = np.where(rej, r * isd, exg["residual_sigmas"])
    return Xg, it + res[1], status, cond, cov, out


def _behind_camera(st: Stacked, X: np.ndarray) -> np.ndarray:
    ok = np.isfinite(X).all(axis=1)
    depth = st.depths(np.where(ok[:, None], X, 0.0))
    return ok & ((depth <= 0) & st.has_pix).any(axis=1)


def solve_batch(method: str, batch: ObservationBatch, **options) -> BatchEstimate:
    """Solve B problems with one estimator; problems it cannot solve get status DEGENERATE or DIVERGED and NaN."""
    o = _check_options(method, options)
    if o.get("terrain") is not None:
        raise ValueError("solve_batch: the terrain option takes one problem's ENU frame; use solve() per problem")
    if not isinstance(batch, ObservationBatch):
        raise TypeError(f"solve_batch wants an ObservationBatch, got {type(batch).__name__}")
    x0 = _initial(o, batch.size)  # validated once; chunks get their rows
    # degenerate problems produce inf/NaN on the way to their status: expected, not worth a warning
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        st = Stacked.from_batch(batch)
        if batch.size <= CHUNK:
            return _solve_stacked(method, st, o)
        parts = []
        for lo in range(0, batch.size, CHUNK):
            idx = np.arange(lo, min(lo + CHUNK, batch.size))
            parts.append(_solve_stacked(method, st.take(idx), o if x0 is None else {**o, "initial_m": x0[idx]}))
        return _concatenate(parts)


#: problems solved together: the kernels' temporaries (a few per n x CHUNK plane) stay in the CPU caches and
#: below the allocator's mmap threshold; problems are independent, so the answers do not depend on it
CHUNK = 2048


def _concatenate(parts: list[BatchEstimate]) -> BatchEstimate:
    first = parts[0]
    fields = ("position_m", "iterations", "status", "condition_number", "covariance_m2")
    return BatchEstimate(first.method, *(None if getattr(first, f) is None else
                                         np.concatenate([getattr(p, f) for p in parts]) for f in fields),
                         {k: np.concatenate([p.extras[k] for p in parts]) for k in first.extras})


# ---- single problem: clear errors for unusable input --------------------------------------------------------

def _check_inputs(method: str, obs: Observations, st: Stacked, o: dict) -> None:
    has_pix, has_rng = st.has_pix[0], st.has_range[0]
    npix = int(np.count_nonzero(has_pix))
    nrng = int(np.count_nonzero(has_rng))
    nboth = int(np.count_nonzero(has_pix & has_rng))
    has_init = o.get("initial_m") is not None
    if method != "range" or not has_init:  # range starts from vision, which projects through P
        bad = np.flatnonzero(~linear.finite_cameras(st)[0])
        if bad.size:
            raise ObservationError(f"frame(s) {bad.tolist()}: the left 3x3 block of P is singular, not a finite "
                                   "camera")
    if method == "los":
        if nboth == 0:
            raise ObservationError("los needs at least one frame with both a target pixel and a range")
        return
    if method == "mle":
        sigma = o.get("sigma") or obs.sigma
        span_ns = int(obs.t_ns.max() - obs.t_ns.min()) if sigma.correlated and obs.n > 1 else None
        if span_ns is not None and span_ns < REAL_TIMES_NS:
            raise ObservationError(f"mle: the sigma gives correlation times (attitude_tau_s, position_tau_s) but "
                                   f"the frames' t_ns span only {span_ns} ns: they need real timestamps (without "
                                   "t_ns the frames are numbered 0, 1, 2, ... ns)")
        if span_ns is not None and len(np.unique(obs.t_ns)) < obs.n:
            raise ObservationError(f"mle: the sigma gives correlation times (attitude_tau_s, position_tau_s) but "
                                   f"{obs.n - len(np.unique(obs.t_ns))} frame(s) repeat another's t_ns: errors "
                                   "correlated in time need one time per frame (remove the repeated rows, or the "
                                   "correlation times)")
        terrain = int(o.get("terrain") is not None)
        if not has_init and npix < 2 and nboth == 0 and not (terrain and npix):
            # ranges alone do fix a point (range does), but so poorly along one axis that the problem is far from
            # linear there and the linearized covariance is no honest ellipse (docs/solvers.md, range)
            raise ObservationError(f"mle starts from the linear intersection (two or more pixels) or a line of "
                                   f"sight (a pixel and a range in one frame); there are {npix} pixel(s) and "
                                   f"no frame with both (ranges alone: see range, which gives no covariance)")
        if 2 * npix + nrng + terrain < 3:
            raise ObservationError(f"mle needs at least three observations (2 per pixel, 1 per range, 1 for the "
                                   f"terrain), got {2 * npix + nrng + terrain}")
        return
    needs_pixels = method in ("dlt", "vision") or not has_init
    if needs_pixels and npix < 2 and method != "range":  # range without pixels starts from the ranges
        what = method if method in ("dlt", "vision") else f"{method} (initialised from vision)"
        raise ObservationError(f"{what} needs at least two frames with a target pixel, got {npix}")
    if needs_pixels and npix >= 2:
        centres = -np.linalg.solve(st.M[0, has_pix], st.p4[0, has_pix][:, :, None])[:, :, 0]
        spread = np.sqrt(((centres - centres.mean(axis=0)) ** 2).sum(axis=1).max())
        if spread <= 1e-6 * (1.0 + np.abs(centres).max()):
            raise GeometryError("all frames with a target pixel share one camera position: no baseline to "
                                "intersect the lines of sight")
    if method == "range":
        if nrng < 3:
            raise ObservationError(f"range needs at least three laser ranges, got {nrng}")
        s = obs.platform_m[has_rng]
        sv = np.linalg.svd(s - s.mean(axis=0), compute_uv=False)
        if sv[0] <= 1e-6 * (1.0 + np.abs(s).max()):
            raise GeometryError("all ranged frames share one platform position: ranges from one point do not "
                                "locate the target")
        if sv[1] <= 1e-9 * sv[0]:
            raise GeometryError("the platform positions of the ranged frames are collinear: ranges cannot fix "
                                "the rotation of the target about that line")
    if method in ("fusion-raw", "fusion", "ridge") and nrng == 0:  # without ranges their answer is vision's
        raise ObservationError(f"{method} fuses pixels with ranges but there are no ranges; use vision")


def solve(method: str, obs: Observations, **options) -> Estimate:
    """Solve one problem with one estimator (options: docs/solvers.md). Raises ObservationError for unusable input,
    GeometryError where the geometry does not determine the target, SolverError where the iteration diverged; an
    estimate that reached max_iterations has status MAX_ITERATIONS (converged False)."""
    if not isinstance(obs, Observations):
        raise TypeError(f"solve wants an Observations, got {type(obs).__name__}")
    got = solve_problems([obs], [method], {method: options})[0][method]
    if isinstance(got, Exception):
        raise got
    return got


def _estimate(method: str, obs: Observations, st: Stacked, o: dict, be: BatchEstimate) -> Estimate:
    """One problem's answer be (B = 1) as `solve` returns it, or the error `solve` raises for it."""
    X, it, cond = be.position_m[0], int(be.iterations[0]), float(be.condition_number[0])
    status = Status(int(be.status[0]))
    info = {k: v[0] for k, v in be.extras.items()}
    if status == Status.DEGENERATE:
        starts = info.get("starts")
        if starts is not None and starts["not_determined"]:
            raise GeometryError(f"mle: not determined by this flight: every start's fit explains the pixels away "
                                f"({starts['not_determined']})")
        if method in _USES_PIXELS and info["behind_camera"]:
            raise GeometryError(f"{method}: the estimate lies behind the camera of a frame with a target "
                                "pixel (check the marked pixels, and the camera's conventions with `ridgeloc check`)")
        if method == "range" and info["collinear_platforms"]:
            raise GeometryError("range: the ranged platform positions lie on a straight line within their position "
                                f"noise (sigma {obs.sigma.position_m or 0:g} m, chi-square test at 95 %): ranges "
                                "cannot fix the rotation of the target about that line")
        raise GeometryError(f"{method}: the geometry does not determine the target (design matrix rank "
                            f"deficient, condition number {cond:.3g}); more baseline or other observations "
                            "are needed")
    if status == Status.DIVERGED:
        raise SolverError(f"{method}: the iteration diverged after {it} iterations "
                          "(the estimate ran away or became non-finite)")
    extras = {}
    if method == "los":
        extras["points_m"] = [None if not np.isfinite(p).all() else p.tolist() for p in info["points_m"]]
        oracle = float(info["oracle_error_m"])
        if np.isfinite(oracle):
            extras["oracle_error_m"] = oracle
    for key in ("augmented_component", "k"):
        if key in info:
            extras[key] = float(info[key])
    if method == "mle":
        extras.update({
            "cep50_m": float(info["cep50_m"]), "cep90_m": float(info["cep90_m"]),
            "ellipsoid": uncertainty.ellipsoid_json(info["ellipsoid_semi_axes_1sigma_m"], info["ellipsoid_axes"]),
            "variance_factors": {"pixel": float(info["variance_factor_pixel"]),
                                 "range": float(info["variance_factor_range"])},
            "sigma0_sq": float(info["sigma0_sq"]),
            "vce_rounds": int(info["vce_rounds"]),
            "robust": o.get("robust", _mle.DEFAULT_ROBUST),
        })
        if "starts" in info:
            extras["starts"] = info["starts"]
        if "rejected" in info:  # the batched kernel's fit checks, bias, rejected rows and learned error model
            extras.update(mle_outputs.problem_extras(info, obs.t_ns))
    cov = None if be.covariance_m2 is None else be.covariance_m2[0]
    return Estimate(method=method, position_m=X, iterations=it, status=status,
                    residuals=_residuals(method, st, X), condition_number=cond, covariance_m2=cov, extras=extras)


#: the errors `solve` raises for a problem it cannot solve (`solve_problems` returns them per problem)
SOLVE_ERRORS = (RidgelocError, ValueError, np.linalg.LinAlgError)


def solve_problems(problems: Sequence[Observations], methods: Sequence[str], options: dict | None = None
                   ) -> list[dict]:
    """Every method of `methods` on each of several problems (a flight's targets), options {method: options}: per
    problem {method: its `Estimate`, or the error (`SOLVE_ERRORS`) `solve` raises}, in the order of `methods`:
    `solve`'s answers, each kernel run once per group of problems that stack (`_groups`), mle's first fit too."""
    obs_list = list(problems)
    for obs in obs_list:
        if not isinstance(obs, Observations):
            raise TypeError(f"solve_problems wants Observations, got {type(obs).__name__}")
    out: list[dict] = [{} for _ in obs_list]
    sts = [Stacked.from_observations(obs) for obs in obs_list]
    ok: dict[str, tuple[dict, list[int]]] = {}  # method -> (options, the problems that pass its checks)
    for m in methods:
        try:
            o = _check_options(m, dict((options or {}).get(m) or {}))
        except ValueError as exc:
            for r in out:
                r[m] = exc
            continue
        todo = []
        for i, (obs, st) in enumerate(zip(obs_list, sts, strict=True)):
            try:
                _check_inputs(m, obs, st, o)
                todo.append(i)
            except SOLVE_ERRORS as exc:
                out[i][m] = exc
        ok[m] = (o, todo)
    answers: dict[str, dict[int, BatchEstimate]] = {}
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        for m, (o, todo) in ok.items():
            if m == "mle":
                continue
            answers[m] = _solve_grouped(m, sts, todo, out, lambda st, m=m, o=o: _solve_stacked(m, st, o))
        if "mle" in ok:
            o, todo = ok["mle"]
            plain = {"tol_m": o["tol_m"], "max_iterations": o["max_iterations"]}
            reuse = [m for m in _starts.START_METHODS if m in ok and ok[m][0] == plain]
            for i, first in _mle_first_fits(sts, todo, o, out).items():
                try:
                    answers.setdefault("mle", {})[i] = _solve_stacked(
                        "mle", sts[i], o, first, {m: answers[m][i] for m in reuse if i in answers[m]})
                except SOLVE_ERRORS as exc:
                    out[i]["mle"] = exc
    for m, per in answers.items():
        o = ok[m][0]
        for i, be in per.items():
            try:
                out[i][m] = _estimate(m, obs_list[i], sts[i], o, be)
            except SOLVE_ERRORS as exc:
                out[i][m] = exc
    return [{m: r[m] for m in methods if m in r} for r in out]


def _groups(sts: list[Stacked], todo: list[int]) -> list[list[int]]:
    """The problems of `todo` in groups that stack (the same number of frames, sigma and presence of a truth)."""
    groups: dict[tuple, list[int]] = {}  # in the order of their first problem
    for i in todo:
        groups.setdefault((sts[i].n, sts[i].sigma, sts[i].truth_m is None), []).append(i)
    return list(groups.values())


def _row(res, b: int):
    """Problem b of a BatchEstimate or of an mle answer (X, it, status, cond, cov, extras: the fields of a
    BatchEstimate in their order), as one of one (copies)."""
    be = isinstance(res, BatchEstimate)
    parts = (res.position_m, res.iterations, res.status, res.condition_number, res.covariance_m2,
             res.extras) if be else res
    row = (*(None if a is None else a[b:b + 1].copy() for a in parts[:5]),
           {k: v[b:b + 1].copy() for k, v in parts[5].items()})
    return BatchEstimate(res.method, *row) if be else row


def _solve_grouped(name: str, sts: list[Stacked], todo: list[int], out: list[dict], fn, batched=None) -> dict:
    """{problem: fn's answer for it (B = 1)} for the problems of todo: fn (a Stacked -> an answer of its problems,
    a BatchEstimate or an mle tuple) once per group (`_groups`) where batched(the group's first Stacked) allows
    (default: always); one problem at a time otherwise, or where a group's call raises (the error then goes to
    its problem in out under `name`): the kernels report a problem's failure as its status, but a problem can
    still raise (a singular matrix LAPACK refuses), and then it alone gets the error."""
    got = {}
    for g in _groups(sts, todo):
        if len(g) > 1 and (batched is None or batched(sts[g[0]])):
            try:
                res = fn(_correlated.stack_problems([sts[i] for i in g]))
                got.update({i: _row(res, b) for b, i in enumerate(g)})
                continue
            except SOLVE_ERRORS:
                pass
        for i in g:
            try:
                got[i] = fn(sts[i])
            except SOLVE_ERRORS as exc:
                out[i][name] = exc
    return got


def _mle_first_fits(sts: list[Stacked], todo: list[int], o: dict, out: list[dict]) -> dict[int, tuple]:
    """{problem: its mle fit from the default start (`_mle_dispatch`'s tuple, B = 1)}, by groups where they stack."""
    def batched(st):
        return not (_mle_sigma(st, o)[0].correlated or o.get("terrain") is not None or o.get("initial_m") is not None)

    return _solve_grouped("mle", sts, todo, out, lambda st: _mle_dispatch(st, o), batched)


def _residuals(method: str, st: Stacked, X: np.ndarray) -> np.ndarray:
    """Observed minus predicted of the observations the method used: pixels (px, u v interleaved), then ranges (m)."""
    if not np.isfinite(X).all():
        return np.zeros(0)
    parts = []
    if method in _USES_PIXELS or method == "los":
        _, r, _ = pixel_model(st, X[None])
        parts.append(r[0, np.repeat(st.has_pix[0], 2)])
    if method not in ("dlt", "vision"):
        _, r, _ = range_model(st, X[None])
        parts.append(r[0, st.has_range[0]])
    return np.concatenate(parts)


def unsolved_status(exc: Exception) -> str:
    """The status of an estimator that did not solve, from its error: degenerate, insufficient_data or diverged."""
    if isinstance(exc, GeometryError):
        return "degenerate"
    if isinstance(exc, ObservationError):
        return "insufficient_data"
    return "diverged"
