"""The MLE on error models nobody stated (issue 12): the redescending default, rejected observations, the
boresight bias and the fit checks."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from pipeline.solve import fit_checks, solve, solve_batch
from pipeline.solve.mle import REDESCEND_A_PIXEL, REDESCEND_B, _redescending, base_variances, pixel_pair_redescending
from pipeline.solve.observations import Observations
from pipeline.solve.stacked import Stacked
from support.scenes import PAPER_SIGMA, paper_batch, paper_problem


def test_redescending_loss_is_quadratic_then_flat():
    e = np.linspace(-12.0, 12.0, 4801)
    rho, w = _redescending(e)
    core = np.abs(e) <= 3.0
    np.testing.assert_allclose(rho[core], 0.5 * e[core] ** 2)
    assert (w[core] == 1).all() and (w[np.abs(e) >= REDESCEND_B] == 0).all()
    # rho' = w e: the derivative of rho matches the weight everywhere (continuous, no kink)
    np.testing.assert_allclose(np.gradient(rho, e)[1:-1], (w * e)[1:-1], atol=2e-3)
    assert np.ptp(rho[np.abs(e) >= REDESCEND_B]) == 0


def test_default_costs_nothing_on_clean_data():
    """Gaussian noise, model known (no bias): the default's median error within 5 % of the squared loss's."""
    batch = paper_batch(1500, n=10, gamma_deg=30.0, seed=5)
    default = solve_batch("mle", batch, bias_prior_deg=0.0)
    plain = solve_batch("mle", batch, robust=None, bias_prior_deg=0.0)
    ratio = np.median(default.errors_m(batch.truth_m)) / np.median(plain.errors_m(batch.truth_m))
    assert ratio < 1.05
    assert default.extras["rejected"].sum() < 0.001 * default.extras["rejected"].size


def test_gross_range_outliers_get_zero_weight_and_are_listed():
    obs = paper_problem(n=20, gamma_deg=40.0, seed=2)
    bad = [3, 11]
    rng = obs.range_m.copy()
    rng[bad] += [300.0, -280.0]
    dirty = dataclasses.replace(obs, range_m=rng)
    est = solve("mle", dirty)
    rej = est.extras["rejected"]
    assert [(r["frame"], r["residual"]) for r in rej] == [(3, "range"), (11, "range")]
    assert rej[0]["t_ns"] == int(obs.t_ns[3]) and rej[0]["value"] == pytest.approx(300.0, abs=30.0)
    assert abs(rej[1]["sigmas"]) > REDESCEND_B
    # zero weight: the answer is the fit without those two shots
    rng_clean = rng.copy()
    rng_clean[bad] = np.nan
    clean = solve("mle", dataclasses.replace(obs, range_m=rng_clean))
    np.testing.assert_allclose(est.position_m, clean.position_m, atol=0.05)
    # the Huber loss bounds their pull but keeps it
    huber = solve("mle", dirty, robust="huber")
    assert np.linalg.norm(huber.position_m - clean.position_m) > 10 * np.linalg.norm(est.position_m - clean.position_m)


def _biased(obs: Observations, du_px: float, dv_px: float) -> Observations:
    return dataclasses.replace(obs, pixel=obs.pixel + np.array([du_px, dv_px]))


def test_boresight_bias_is_estimated_and_keeps_the_ellipsoid_honest():
    """A constant pixel offset (a boresight bias of the camera) on a wide arc with ranges: estimated with a
    posterior sigma well below the prior, and the truth stays inside the 95 % ellipsoid, unlike without it."""
    sigma = dataclasses.replace(PAPER_SIGMA, attitude_deg=0.05)
    inside, inside_nobias, errs = [], [], []
    for seed in range(30):
        obs = dataclasses.replace(paper_problem(n=30, gamma_deg=90.0, seed=seed, sigma=sigma), sigma=sigma)
        biased = _biased(obs, 1000 * np.deg2rad(0.15), -1000 * np.deg2rad(0.1))  # f = 1000 px
        est = solve("mle", biased, bias_prior_deg=0.2)
        b = est.extras["boresight_bias"]
        errs.append((b["u_deg"] - 0.15, b["v_deg"] + 0.1))
        assert b["u_sigma_deg"] < 0.1
        for est_, out in ((est, inside), (solve("mle", biased, bias_prior_deg=0.0), inside_nobias)):
            e = est_.position_m - obs.truth_m
            out.append(e @ np.linalg.solve(est_.covariance_m2, e) < 7.81)
    assert np.mean(inside) >= 0.85 and np.mean(inside_nobias) < 0.5
    assert abs(np.mean(errs, axis=0)[0]) < 0.03


def test_lag1_autocorrelation_finds_drift_and_not_white_noise():
    rng = np.random.default_rng(0)
    n, b = 40, 500
    white = rng.normal(size=(3, n, b))
    ar = np.empty_like(white)
    ar[:, 0] = white[:, 0]
    for i in range(1, n):
        ar[:, i] = 0.8 * ar[:, i - 1] + 0.6 * white[:, i]
    use = np.ones((3, n, b), dtype=bool)
    rho_w, pairs = fit_checks.lag1_autocorrelation(white, use, slice(0, 2))
    rho_a, _ = fit_checks.lag1_autocorrelation(ar, use, slice(0, 2))
    assert abs(np.mean(rho_w)) < 0.03 and np.mean(fit_checks.acf_significant(rho_w, pairs)) < 0.05
    assert np.mean(rho_a) == pytest.approx(0.8, abs=0.05) and fit_checks.acf_significant(rho_a, pairs).all()
    assert fit_checks.acf_inflation(np.array([0.8]), np.array([True]))[0] == pytest.approx(9.0)


def test_batch_means_see_a_slow_drift_under_white_noise_that_lag1_misses():
    """Video-rate residuals: white noise (variance 1) plus a slow AR(1) drift (lag-1 0.998, variance 0.03). The
    lag-1 autocorrelation is about 0.03, mostly below its two standard errors; the means over blocks of 30 frames
    vary about 1.8 times as much as white noise's, as the autocovariance sum says, and the test sees it on most
    problems (the drift's own slowness makes the ratio vary from problem to problem)."""
    rng = np.random.default_rng(1)
    n, b, a, v = 900, 200, 0.998, 0.03
    white = rng.normal(size=(3, n, b))
    drift = np.empty_like(white)
    drift[:, 0] = rng.normal(size=(3, b)) * np.sqrt(v)
    for i in range(1, n):
        drift[:, i] = a * drift[:, i - 1] + np.sqrt(v * (1 - a * a)) * rng.normal(size=(3, b))
    use = np.ones((3, n, b), dtype=bool)
    use[:, 7::9, : b // 2] = False  # drop-outs: blocks are of consecutive used frames
    e = white + drift
    rho, pairs = fit_checks.lag1_autocorrelation(e, use, slice(0, 2))
    lag1_rate = np.mean(fit_checks.acf_significant(rho, pairs))
    ratio, blocks = fit_checks.batch_means_ratio(e, use, slice(0, 2))
    k = 30  # floor(sqrt(900))
    gamma = lambda h: (1.0 if h == 0 else 0.0) + v * a ** abs(h)  # noqa: E731
    expected = sum(gamma(i - j) for i in range(k) for j in range(k)) / k / (1.0 + v)
    full = ratio[b // 2:]  # no drop-outs: exactly k-frame blocks
    assert np.mean(full) == pytest.approx(expected, rel=0.1)
    blocks_rate = np.mean(fit_checks.batch_means_significant(ratio, blocks))
    assert lag1_rate < 0.3 and blocks_rate > 0.6, (lag1_rate, blocks_rate)
    w_ratio, w_blocks = fit_checks.batch_means_ratio(white, use, slice(0, 2))
    assert np.mean(w_ratio) == pytest.approx(1.0, abs=0.05)
    assert np.mean(fit_checks.batch_means_significant(w_ratio, w_blocks)) < 0.05
    assert (fit_checks.batch_means_inflation(np.array([3.0, 0.5, 500.0]), np.array([True, True, True]))
            == [3.0, 1.0, fit_checks.MAX_ACF_INFLATION]).all()


def test_a_run_of_mistracked_frames_is_an_outlying_segment_not_drift():
    """Five consecutive frames of 40 mistracked by 5 sigma (one direction per problem; white errors otherwise):
    the plain lag-1 autocorrelation of the residuals calls nearly every problem drifting; the fit checks leave
    runs of frames beyond the full-weight zone out of the lag-1 test, and call few."""
    assert (fit_checks.outlying_runs(np.array([[1, 0, 1, 1, 0, 1, 1, 1, 0, 1]], dtype=bool).T)[:, 0]
            == [0, 0, 1, 1, 0, 1, 1, 1, 0, 0]).all()
    B, n, run = 300, 40, slice(12, 17)
    b = paper_batch(B, n, 30.0, seed=3)
    sd = np.sqrt(base_variances(Stacked.from_batch(b), b.truth_m, b.sigma)[:, :2 * n].reshape(B, n, 2))
    theta = np.random.default_rng(4).uniform(0.0, 2.0 * np.pi, B)
    pixel = b.pixel.copy()
    pixel[:, run] += 5.0 * np.stack([np.cos(theta), np.sin(theta)], axis=1)[:, None, :] * sd[:, run]
    ex = solve_batch("mle", dataclasses.replace(b, pixel=pixel)).extras
    e = ex["residual_sigmas"].transpose(2, 1, 0)
    plain = fit_checks.acf_significant(*fit_checks.lag1_autocorrelation(e, np.ones(e.shape, dtype=bool), slice(0, 2)))
    assert plain.mean() > 0.9
    assert ex["drift_pixel"].mean() < 0.25  # 0.61 when the run counted in the lag-1 test


def test_misfit_is_said_in_words_and_inflates_the_covariance():
    """Pixel noise 3x what the sigma says, variance components off: the chi-square test fails, the message
    says so and the covariance grows."""
    told = dataclasses.replace(PAPER_SIGMA, attitude_deg=0.0, position_m=0.5, pixel_px=1.0)
    obs = paper_problem(n=30, gamma_deg=60.0, seed=4, sigma=dataclasses.replace(told, pixel_px=3.0))
    obs = dataclasses.replace(obs, sigma=told)
    est = solve("mle", obs, estimate_variance_components=False, bias_prior_deg=0.0)
    fit = est.extras["fit"]
    assert not fit["consistent"] and fit["p_value"] < 0.01
    assert "larger than the error model says" in fit["message"] and "inflated" in fit["message"]
    assert fit["covariance_inflation"] > 2
    clean = paper_problem(n=30, gamma_deg=60.0, seed=4, sigma=told)
    fit = solve("mle", clean, estimate_variance_components=False, bias_prior_deg=0.0).extras["fit"]
    assert fit["consistent"] and fit["message"] is None and fit["covariance_inflation"] == pytest.approx(1.0)


def test_drifting_errors_get_a_correlation_time_learned_from_the_flight():
    """Gauss-Markov attitude (0.2 deg, tau 20 s) and position (5 m, tau 60 s) errors, frames 1 s apart, the
    sigma without correlation times: the residuals drift, the MLE picks a tau by likelihood (generalized least
    squares) and its 95 % ellipsoid holds the truth about as often as with the true correlation times."""
    from support.scenes import correlated_problems

    inside, taus = [], []
    for obs in correlated_problems(40, seed=7):
        est = solve("mle", obs)
        e = est.position_m - obs.truth_m
        inside.append(e @ np.linalg.solve(est.covariance_m2, e) <= 7.81)
        if "error_model" in est.extras:
            model = est.extras["error_model"]
            taus.append(model["attitude_tau_s"] or model["position_tau_s"])
            assert est.extras["fit"]["autocorrelation_pixel"] is not None
    assert len(taus) >= 20 and 10.0 <= np.median(taus) <= 80.0
    assert np.mean(inside) >= 0.85


def test_a_pixel_is_weighted_whole_by_its_2d_length():
    """The pixel pair's loss is rho(|e|) of the 2-D residual: its gradient is w(|e|) e in both coordinates, full
    weight inside REDESCEND_A_PIXEL, none from REDESCEND_B; a frame far off in u alone loses v too."""
    rng = np.random.default_rng(3)
    eu, ev = rng.normal(0.0, 3.0, 500), rng.normal(0.0, 3.0, 500)
    w = pixel_pair_redescending(eu, ev)[1]
    h = 1e-6
    grad_u = (pixel_pair_redescending(eu + h, ev)[0] - pixel_pair_redescending(eu - h, ev)[0]) / (2 * h)
    np.testing.assert_allclose(grad_u, w * eu, atol=1e-5)
    length = np.hypot(eu, ev)
    assert (w[length <= REDESCEND_A_PIXEL] == 1).all() and (w[length >= REDESCEND_B] == 0).all()
    assert ((w > 0) & (w < 1)).any()
    obs = paper_problem(n=20, gamma_deg=40.0, seed=4, sigma=dataclasses.replace(PAPER_SIGMA, pixel_px=0.5))
    pixel = obs.pixel.copy()
    pixel[5, 0] += 60.0  # far off in u only: ~17 sigma of the ~3.5 px pixel scatter
    est = solve("mle", dataclasses.replace(obs, pixel=pixel))
    assert sorted((r["frame"], r["residual"]) for r in est.extras["rejected"]) == [(5, "u"), (5, "v")]


def test_the_bias_is_reported_in_degrees_when_the_sigmas_were_stated_too_small():
    """Frame-to-frame attitude error 0.3 deg told as 0.2 deg (the fit checks flag it and scale the model) and a
    0.3 deg bias about the camera's vertical axis: the reported bias is that angle, not one shrunk by the
    misfit's scale."""
    told = dataclasses.replace(PAPER_SIGMA, pixel_px=0.5)
    batch = paper_batch(200, n=40, gamma_deg=90.0, sigma=dataclasses.replace(told, attitude_deg=0.3), seed=6)
    b = np.deg2rad(0.3) * 1000.0  # f = 1000 px
    biased = dataclasses.replace(batch, pixel=batch.pixel + np.array([b, 0.0]), sigma=told)
    ex = solve_batch("mle", biased).extras
    assert np.mean(~ex["consistent"]) > 0.8
    assert abs(np.median(ex["bias_deg"][:, 0]) - 0.3) < 0.08  # measured 0.25 (shrunk to the prior); 0.17 unscaled


@pytest.mark.parametrize("robust", ["redescending", None])
def test_what_mle_reports_belongs_to_the_position_it_returns(robust):
    """The residuals (and so the weights, chi-square and covariance built from them) are those at the returned
    position, even with a coarse tolerance that ends the iteration on a long step (no bias, no variance
    components: nothing moves the position after the iteration)."""
    from pipeline.solve.stacked import pixel_model

    b = paper_batch(200, seed=5)
    be = solve_batch("mle", b, tol_m=0.5, estimate_variance_components=False, bias_prior_deg=0.0, robust=robust)
    _, r, ok = pixel_model(Stacked.from_batch(b), be.position_m)
    reported = be.extras["residuals"][:, :, :2].reshape(200, -1)
    assert np.abs(np.where(ok, reported - r, 0.0)).max() < 1e-9


def test_the_bias_averaged_answer_is_converged_and_its_residuals_are_at_it():
    """The default mle (bias size averaged by the flight's evidence, after the iteration): its answer is the
    mixture's solution to tol_m, and the residuals it reports are those at the returned position with the
    reported mean bias (f * angle in u and v) removed."""
    from pipeline.solve.stacked import pixel_model

    b = paper_batch(200, seed=5)
    coarse, fine = (solve_batch("mle", b, tol_m=tol) for tol in (1e-4, 1e-7))
    assert np.abs(coarse.position_m - fine.position_m).max() < 1e-3  # a few tol_m: both converged
    st = Stacked.from_batch(b)
    _, r, ok = pixel_model(st, coarse.position_m)
    fx, fy = st.focal_px()
    bias_rad = np.deg2rad(coarse.extras["bias_deg"])
    offset_px = np.stack([fx * bias_rad[:, :1], fy * bias_rad[:, 1:]], axis=-1).reshape(200, -1)
    reported = coarse.extras["residuals"][:, :, :2].reshape(200, -1)
    assert np.abs(np.where(ok, reported - (r - offset_px), 0.0)).max() < 1e-4  # px; pixel sigma ~3 px
