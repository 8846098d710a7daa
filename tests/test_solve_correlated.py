"""mle with time-correlated attitude and position errors (generalized least squares, `pipeline.solve.correlated`)."""

import dataclasses
import json
import math

import numpy as np
import pytest
from scipy.optimize import least_squares

from pipeline import observation_file
from pipeline.errors import GeometryError, ObservationError
from pipeline.geometry.camera import project
from pipeline.solve import correlated, solve, solve_batch
from pipeline.solve.estimate import Status
from pipeline.solve.observations import Sigma
from pipeline.solve.stacked import Stacked
from pipeline.solve.uncertainty import CHI2_3_95
from support.scenes import PAPER_SIGMA, correlated_problems, paper_batch, paper_problem
from support.zoo import zoo

CORR = dataclasses.replace(PAPER_SIGMA, attitude_tau_s=20.0, position_tau_s=60.0)


@pytest.mark.parametrize("robust", [None, "huber", "cauchy"])
@pytest.mark.parametrize("pixel_px", [0.1, None])  # None: variance component estimation on the whitened rows
def test_tau_to_zero_equals_independent_mle(robust, pixel_px):
    """With correlation times far below the frame spacing (1 s) the off-diagonal covariance vanishes and the
    GLS path must reproduce the independent MLE: estimate, covariance, iterations, residuals."""
    for seed in range(3):
        obs = paper_problem(seed=seed)
        white = dataclasses.replace(PAPER_SIGMA, pixel_px=pixel_px)
        tiny = dataclasses.replace(white, attitude_tau_s=1e-6, position_tau_s=1e-6)
        assert tiny.correlated and not white.correlated
        a = solve("mle", obs, sigma=white, robust=robust, bias_prior_deg=0.0)
        b = solve("mle", obs, sigma=tiny, robust=robust)
        np.testing.assert_allclose(b.position_m, a.position_m, atol=1e-9)
        np.testing.assert_allclose(b.covariance_m2, a.covariance_m2, rtol=1e-9, atol=1e-12)
        np.testing.assert_allclose(b.residuals, a.residuals, atol=1e-9)
        assert b.iterations == a.iterations
        assert b.extras["vce_rounds"] == a.extras["vce_rounds"]


def _hand_covariance(obs, x, sigma):
    """The GLS residual covariance written out element by element (docs/solvers.md), rows u1 v1 u2 v2 ... d1 ..."""
    n = obs.n
    t = obs.t_ns.astype(np.float64) * 1e-9
    att = math.radians(sigma.attitude_deg)
    C = np.zeros((3 * n, 3 * n))
    for i in range(n):
        M = obs.P[i, :, :3]
        f = [np.linalg.norm(np.cross(M[a], M[2])) / (M[2] @ M[2]) for a in (0, 1)]
        Di = np.linalg.norm(x - obs.platform_m[i])
        for j in range(n):
            Mj = obs.P[j, :, :3]
            fj = [np.linalg.norm(np.cross(Mj[a], Mj[2])) / (Mj[2] @ Mj[2]) for a in (0, 1)]
            Dj = np.linalg.norm(x - obs.platform_m[j])
            ka = math.exp(-abs(t[i] - t[j]) / sigma.attitude_tau_s) if sigma.attitude_tau_s else float(i == j)
            kp = math.exp(-abs(t[i] - t[j]) / sigma.position_tau_s) if sigma.position_tau_s else float(i == j)
            for a in (0, 1):
                C[2 * i + a, 2 * j + a] = (sigma.pixel_px ** 2 * (i == j)
                                           + f[a] * fj[a] * (att ** 2 * ka + sigma.position_m ** 2 / (Di * Dj) * kp))
            C[2 * n + i, 2 * n + j] = sigma.range_m ** 2 * (i == j) + sigma.position_m ** 2 * kp
    return C


@pytest.mark.parametrize("sigma", [CORR, PAPER_SIGMA], ids=["drifting", "white"])
def test_the_boresight_bias_is_integrated_out_exactly(sigma):
    """The GLS models with a constant boresight bias (prior 0.3 deg: a column f * angle on the u rows, another on
    the v rows): the forms [J|r]^T C^-1 [J|r] and log det C of `quadratic_forms_stacked`, summed over the groups,
    equal the dense ones of the covariance written out with the bias added (C + b^2 a_u a_u^T + b^2 a_v a_v^T)."""
    obs = correlated_problems(1, n=12, seed=4)[0]
    st = Stacked.from_observations(obs)
    x = obs.truth_m + np.array([3.0, -2.0, 1.0])
    b = math.radians(0.3)
    C = _hand_covariance(obs, x, sigma)
    for i in range(obs.n):
        M = obs.P[i, :, :3]
        f = [np.linalg.norm(np.cross(M[a], M[2])) / (M[2] @ M[2]) for a in (0, 1)]
        for j in range(obs.n):
            Mj = obs.P[j, :, :3]
            fj = [np.linalg.norm(np.cross(Mj[a], Mj[2])) / (Mj[2] @ Mj[2]) for a in (0, 1)]
            for a in (0, 1):
                C[2 * i + a, 2 * j + a] += b * b * f[a] * fj[a]
    A = correlated.rows_in_use(st, x)
    models = correlated.problem_models(st, x, [sigma], [0.3])
    q = correlated.quadratic_forms_stacked(models, A[None], np.ones((1, A.shape[0])), np.ones((1, 2)))[0]
    np.testing.assert_allclose(sum(f for f, _, _ in q), A.T @ np.linalg.solve(C, A), rtol=1e-8, atol=1e-10)
    np.testing.assert_allclose(sum(ld for _, ld, _ in q), np.linalg.slogdet(C)[1], rtol=1e-10)


def test_a_tracker_slip_is_integrated_out_exactly():
    """A `Slip` (a constant offset of prior sigma 5 px on the u and v rows of frames 3-7 only) through the same
    Sherman-Morrison columns: the forms and log det equal the dense covariance's with that offset added."""
    obs = correlated_problems(1, n=12, seed=4)[0]
    st = Stacked.from_observations(obs)
    x = obs.truth_m + np.array([3.0, -2.0, 1.0])
    mask = np.zeros(obs.n, dtype=bool)
    mask[3:8] = True
    C = _hand_covariance(obs, x, CORR)
    for i in np.flatnonzero(mask):
        for j in np.flatnonzero(mask):
            for a in (0, 1):
                C[2 * i + a, 2 * j + a] += 25.0
    A = correlated.rows_in_use(st, x)
    models = correlated.problem_models(st, x, [CORR], [correlated.Slip(mask, 5.0, 1)])
    q = correlated.quadratic_forms_stacked(models, A[None], np.ones((1, A.shape[0])), np.ones((1, 2)))[0]
    np.testing.assert_allclose(sum(f for f, _, _ in q), A.T @ np.linalg.solve(C, A), rtol=1e-8, atol=1e-10)
    np.testing.assert_allclose(sum(ld for _, ld, _ in q), np.linalg.slogdet(C)[1], rtol=1e-10)


def test_gls_minimizes_the_correlated_cost_and_reports_its_covariance():
    obs = correlated_problems(1, seed=3)[0]
    est = solve("mle", obs, sigma=CORR, robust=None, tol_m=1e-9)
    # the GLS starts from the white fit (the same sigmas, no correlation times) and builds C there, once
    white = dataclasses.replace(CORR, attitude_tau_s=None, position_tau_s=None)
    x0 = solve("mle", obs, sigma=white, robust=None, bias_prior_deg=0.0, tol_m=1e-9).position_m
    C = _hand_covariance(obs, x0, CORR)
    L = np.linalg.cholesky(C)

    def f(x):
        pix = (obs.pixel - project(obs.P, np.broadcast_to(x, (obs.n, 3)))).reshape(-1)
        rng = obs.range_m - np.linalg.norm(x - obs.platform_m, axis=1)
        return np.linalg.solve(L, np.r_[pix, rng])

    ref = least_squares(f, x0, method="lm", xtol=1e-14, ftol=1e-14, gtol=1e-14)
    # The cost is flat along the long axis (8e-5 m moves it by 3e-10), so where scipy stops there depends on the
    # BLAS kernel (mm apart): compare in the estimate's own metric, where the flat direction weighs little.
    d = est.position_m - ref.x
    assert d @ np.linalg.solve(est.covariance_m2, d) < 1e-6
    assert f(est.position_m) @ f(est.position_m) <= ref.fun @ ref.fun + 1e-9
    x, h = est.position_m, 1e-2  # central differences of the whitened residuals at the estimate
    Jw = np.stack([(f(x + h * e) - f(x - h * e)) / (2 * h) for e in np.eye(3)], axis=1)
    np.testing.assert_allclose(est.covariance_m2, np.linalg.inv(Jw.T @ Jw), rtol=1e-5)


def test_coverage_of_the_95_percent_ellipsoid_under_gauss_markov_errors():
    """400 problems on the paper's arc, frames 1 s apart, attitude (0.2 deg, tau 20 s) and position (5 m,
    tau 60 s) errors Gauss-Markov: with the correlation times the 95 % ellipsoid holds about 95 % of the
    errors; assuming independence (no bias, issue 12's fit checks only) it holds fewer; told nothing, the
    default (boresight bias from the flight, fit checks) holds at least 90 %."""
    probs = correlated_problems(400, seed=11)
    cover = {}
    for label, sigma, opts in (("independent", PAPER_SIGMA, {"bias_prior_deg": 0.0}), ("correlated", CORR, {}),
                               ("default", PAPER_SIGMA, {})):
        d2 = []
        for obs in probs:
            est = solve("mle", obs, sigma=sigma, robust=None, **opts)
            e = est.position_m - obs.truth_m
            d2.append(e @ np.linalg.solve(est.covariance_m2, e))
        cover[label] = float(np.mean(np.array(d2) <= CHI2_3_95))
    assert 0.90 <= cover["correlated"] <= 0.99, cover
    assert cover["independent"] < 0.8, cover
    assert cover["default"] >= 0.9, cover


def test_attitude_only_correlation_coverage():
    probs = correlated_problems(300, seed=12, position_tau_s=None)
    sigma = dataclasses.replace(PAPER_SIGMA, attitude_tau_s=20.0)
    d2 = []
    for obs in probs:
        est = solve("mle", obs, sigma=sigma)  # the default loss: the white fit's weights held in the GLS
        e = est.position_m - obs.truth_m
        d2.append(e @ np.linalg.solve(est.covariance_m2, e))
    assert 0.90 <= np.mean(np.array(d2) <= CHI2_3_95) <= 0.99


def test_sigma_keys_round_trip_and_validation(tmp_path):
    obs = correlated_problems(1, seed=1)[0]
    obs = dataclasses.replace(obs, sigma=CORR)
    path = tmp_path / "obs.json"
    observation_file.save(obs, path)
    doc = json.loads(path.read_text())
    assert doc["sigma"]["attitude_tau_s"] == 20.0 and doc["sigma"]["position_tau_s"] == 60.0
    back = observation_file.load(path)
    assert back.sigma == CORR
    np.testing.assert_array_equal(back.t_ns, obs.t_ns)
    assert solve("mle", back, bias_prior_deg=0.0).position_m == pytest.approx(
        solve("mle", obs, bias_prior_deg=0.0).position_m, abs=1e-9)
    with pytest.raises(ObservationError, match="attitude_tau_s"):
        Sigma.from_dict({"attitude_tau_s": -1.0})
    assert not Sigma(attitude_deg=0.2).correlated
    assert not Sigma(attitude_deg=0.2, attitude_tau_s=0.0).correlated
    assert not Sigma(attitude_deg=0.0, attitude_tau_s=20.0, position_tau_s=60.0).correlated


def test_solve_batch_refuses_correlated_sigma_clearly():
    batch = paper_batch(4, seed=2)
    with pytest.raises(ValueError, match="solve\\(\\) per problem"):
        solve_batch("mle", batch, sigma=CORR)
    # the independent batch path is untouched
    assert np.isfinite(solve_batch("mle", batch).position_m).all()


def test_robust_gls_is_continuous_at_vanishing_correlation():
    """A correlation of 2e-9 between neighbouring frames (tau 0.05 s, frames 1 s apart) takes the GLS path (the
    white fit, then the GLS fit with the white fit's robust weights held); its Huber estimate must be the
    independent Huber estimate: to 1e-6 m where both evaluate the distances in C at the same point (here: both
    started at the independent answer), within 1e-3 m from the default start (the white fit evaluates them at
    its start, the GLS at the white answer; the independent estimate itself moves by 5e-4 m between the two)."""
    tiny = dataclasses.replace(PAPER_SIGMA, attitude_tau_s=0.05, position_tau_s=0.05)
    for seed in range(3):
        obs = paper_problem(seed=seed)
        a = solve("mle", obs, robust="huber", bias_prior_deg=0.0)
        b = solve("mle", obs, sigma=tiny, robust="huber")
        np.testing.assert_allclose(b.position_m, a.position_m, atol=1e-3)
        np.testing.assert_allclose(b.covariance_m2, a.covariance_m2, rtol=1e-3)
        at = {"initial_m": a.position_m[None], "tol_m": 1e-9}
        a = solve("mle", obs, robust="huber", bias_prior_deg=0.0, **at)
        b = solve("mle", obs, sigma=tiny, robust="huber", **at)
        np.testing.assert_allclose(b.position_m, a.position_m, atol=1e-6)
        np.testing.assert_allclose(b.covariance_m2, a.covariance_m2, rtol=1e-6)
        np.testing.assert_allclose(b.residuals, a.residuals, atol=1e-6)


def test_robust_gls_resists_a_gross_range_error():
    """One laser range 3 km long, correlated attitude and position errors: the white fit rejects it and the GLS
    fits the rows it kept at its weights, keeping the estimate near the truth and its covariance honest; without a
    robust loss the range drags it hundreds of metres."""
    errs, d2s = [], []
    for obs in correlated_problems(40, seed=21):
        rng = obs.range_m.copy()
        rng[4] += 3000.0
        obs = dataclasses.replace(obs, range_m=rng)
        est = solve("mle", obs, sigma=CORR)
        e = est.position_m - obs.truth_m
        errs.append(np.linalg.norm(e))
        d2s.append(e @ np.linalg.solve(est.covariance_m2, e))
        assert est.converged
    # without a robust loss the range drags the fit (sigma0^2 in the tens of thousands: since issue 19 that is
    # reported as not determined rather than as an answer)
    with pytest.raises(GeometryError, match="not determined"):
        solve("mle", obs, sigma=CORR, robust=None)
    assert np.median(errs) < 20.0
    assert np.mean(np.array(d2s) <= CHI2_3_95) >= 0.85


def test_correlation_times_without_real_timestamps_is_an_error():
    obs = paper_problem(seed=2)
    obs = dataclasses.replace(obs, t_ns=np.arange(obs.n, dtype=np.int64))  # the default: frame numbers, in ns
    with pytest.raises(ObservationError, match="real timestamps"):
        solve("mle", obs, sigma=CORR)
    solve("mle", obs)  # without correlation times the timestamps are not used


@pytest.mark.parametrize("name", ["z029", "z087"])
def test_the_configured_fit_does_not_jump_when_its_start_moves_by_a_micrometre(name):
    """Zoo flights z029 and z087 told a long correlation time (320 s) for attitude and position alike (a model
    their position errors do not follow): from the dlt point and three starts 1e-6 m away the answers agree to
    1e-6 m and converge. Before the configured fit was the learned one's (white fit, then damped GLS with the
    white fit's weights held) its weights were updated from the rows' marginal residuals: the answers moved by
    30 m (z029) and 730 m (z087) and z087's ended at the iteration limit."""
    f = zoo().flight(name)
    obs = dataclasses.replace(f.obs, sigma=dataclasses.replace(f.obs.sigma, attitude_tau_s=320.0,
                                                               position_tau_s=320.0))
    x0 = solve("dlt", obs).position_m
    ests = [solve("mle", obs, initial_m=(x0 + 1e-6 * d / np.linalg.norm(d))[None])
            for d in [np.ones(3), *np.random.default_rng(3).normal(size=(3, 3))]]
    X = np.array([e.position_m for e in ests])
    assert all(e.converged for e in ests)
    assert np.linalg.norm(X[1:] - X[0], axis=1).max() < 1e-6


def test_rejected_rows_are_reported_at_the_returned_position():
    """The configured path fits the rows its white fit kept; the range and the pixel that fit rejected are reported
    with their residuals (observed - predicted; u, v in order) at the GLS answer (the position returned), not at
    the white fit's."""
    obs = correlated_problems(1, seed=21)[0]
    rng, pix = obs.range_m.copy(), obs.pixel.copy()
    rng[4] += 3000.0
    pix[7] += (400.0, -250.0)
    obs = dataclasses.replace(obs, range_m=rng, pixel=pix)
    est = solve("mle", obs, sigma=CORR)
    got = {(r["frame"], r["residual"]): r["value"] for r in est.extras["rejected"]}
    assert set(got) == {(4, "range"), (7, "u"), (7, "v")}, got
    assert abs(got[4, "range"] - (rng[4] - np.linalg.norm(est.position_m - obs.platform_m[4]))) < 1e-6
    predicted = project(obs.P[7], est.position_m)
    assert abs(got[7, "u"] - (pix[7, 0] - predicted[0])) < 1e-6
    assert abs(got[7, "v"] - (pix[7, 1] - predicted[1])) < 1e-6


def test_a_failed_configured_fit_is_no_white_answer(monkeypatch):
    """Where the configured model's GLS fit is degenerate, mle says so: it does not fall back to the white fit's
    answer as if it were the configured model's."""
    real = correlated.gls

    def degenerate(*a, **k):
        X, it, status, cond, cov, ex = real(*a, **k)
        return np.full_like(X, np.nan), it, np.full_like(status, Status.DEGENERATE), cond, cov, ex

    obs = paper_problem(seed=1)
    assert solve("mle", obs, sigma=CORR).converged
    monkeypatch.setattr(correlated, "gls", degenerate)
    with pytest.raises(GeometryError):
        solve("mle", obs, sigma=CORR)


def test_skipping_the_second_phase_changes_no_answer(monkeypatch):
    """A fit with fixed weights skips the redescending phase where the scale guard rescaled nothing and the first
    phase converged (the loss does not change its objective); a fit that hit the iteration limit goes on as
    before. Against the fit without the skip: the same status, the position within the stopping tolerance,
    also with an iteration limit small enough to stop the first phase (review of 7c2496f: it had stopped there)."""
    obs = paper_problem(seed=4)
    st = Stacked.from_observations(obs)
    X0 = obs.truth_m[None] + 20.0
    models = correlated.problem_models(st, X0[0], [CORR])
    for itmax in (3, 4, 50):
        got = correlated.gls([st], X0, models, "redescending", False, 1e-4, itmax)
        with monkeypatch.context() as mp:
            mp.setattr(correlated.Correlated, "fixed_weights", False)
            ref = correlated.gls([st], X0, models, "redescending", False, 1e-4, itmax)
        assert got[2][0] == ref[2][0], (itmax, got[2], ref[2])
        assert np.linalg.norm(got[0][0] - ref[0][0]) <= 1e-4, itmax
