"""The weighted MLE: equal weights, scipy agreement, robustness, variance components, covariance, CEP."""

import dataclasses

import numpy as np
import pytest
from scipy.optimize import least_squares

from pipeline.geometry.camera import project
from pipeline.solve import solve, solve_batch
from pipeline.solve.mle import CAUCHY_C, HUBER_C, base_variances, helmert
from pipeline.solve.observations import Sigma
from pipeline.solve.stacked import Stacked
from pipeline.solve.uncertainty import cep_m
from support.scenes import PAPER_SIGMA, paper_batch, paper_problem

UNIT = Sigma(pixel_px=1.0, range_m=1.0, position_m=0.0, attitude_deg=0.0)


def test_mle_with_equal_weights_equals_fusion_raw():
    obs = paper_problem(gamma_deg=20.0, seed=7)
    x0 = solve("vision", obs).position_m
    raw = solve("fusion-raw", obs, initial_m=x0, tol_m=1e-9)
    mle = solve("mle", obs, initial_m=x0, sigma=UNIT, robust=None, estimate_variance_components=False, tol_m=1e-9,
                bias_prior_deg=0.0)
    np.testing.assert_allclose(mle.position_m, raw.position_m, atol=1e-7)


def _weighted_residual(obs, sigma_px_u, sigma_px_v, sigma_r):
    def f(x):
        pix = (obs.pixel - project(obs.P, np.broadcast_to(x, (obs.n, 3))))
        return np.r_[(pix / np.stack([sigma_px_u, sigma_px_v], axis=1)).reshape(-1),
                     (obs.range_m - np.linalg.norm(x - obs.platform_m, axis=1)) / sigma_r]
    return f


@pytest.mark.parametrize("robust, loss, f_scale", [(None, "linear", 1.0), ("huber", "huber", HUBER_C),
                                                   ("cauchy", "cauchy", CAUCHY_C)])
def test_mle_matches_scipy_least_squares_on_the_same_weighted_problem(robust, loss, f_scale):
    obs = paper_problem(gamma_deg=30.0, seed=8)
    pixel = obs.pixel.copy()
    pixel[4] += [25.0, -30.0]  # one mis-tracked frame, so that the robust losses matter
    obs = dataclasses.replace(obs, pixel=pixel)
    x0 = solve("dlt", obs).position_m
    est = solve("mle", obs, robust=robust, estimate_variance_components=False, initial_m=x0, tol_m=1e-9,
                bias_prior_deg=0.0)
    # the a priori sigmas, written out independently of base_variances
    s = PAPER_SIGMA
    D = np.linalg.norm(x0 - obs.platform_m, axis=1)  # camera centre = platform in these scenes
    att = np.deg2rad(s.attitude_deg)
    sig_px = np.sqrt(s.pixel_px ** 2 + 1000.0 ** 2 * (att ** 2 + (s.position_m / D) ** 2))
    sig_r = np.hypot(s.range_m, s.position_m)
    f = _weighted_residual(obs, sig_px, sig_px, np.full(obs.n, sig_r))
    ref = least_squares(f, x0, loss=loss, f_scale=f_scale, jac="3-point", method="trf", xtol=1e-15, ftol=1e-15,
                        gtol=1e-15).x
    np.testing.assert_allclose(est.position_m, ref, atol=1e-5)


def test_base_variances_inflate_pixel_sigma_by_attitude_times_focal_length():
    obs = paper_problem(gamma_deg=30.0, seed=1)
    st = Stacked.from_observations(obs)
    var = base_variances(st, obs.truth_m[None], Sigma(pixel_px=0.1, range_m=2.5, position_m=0.0,
                                                      attitude_deg=0.2))
    expected_px = 0.1 ** 2 + (1000.0 * np.deg2rad(0.2)) ** 2
    np.testing.assert_allclose(var[0, :2 * obs.n], expected_px, rtol=1e-9)
    np.testing.assert_allclose(var[0, 2 * obs.n:], 2.5 ** 2)
    fx, fy = st.focal_px()
    np.testing.assert_allclose(fx, 1000.0, rtol=1e-9)
    np.testing.assert_allclose(fy, 1000.0, rtol=1e-9)


def test_robust_loss_resists_a_wrong_range_and_a_mis_tracked_frame():
    batch = paper_batch(40, gamma_deg=30.0, seed=11)
    pixel, rng = batch.pixel.copy(), batch.range_m.copy()
    rng[:, 3] += 400.0  # a wrong range
    pixel[:, 6] += [60.0, 45.0]  # a mis-tracked frame
    bad = dataclasses.replace(batch, pixel=pixel, range_m=rng)
    clean = np.median(solve_batch("mle", batch).errors_m(batch.truth_m))
    huber = np.median(solve_batch("mle", bad).errors_m(batch.truth_m))
    cauchy = np.median(solve_batch("mle", bad, robust="cauchy").errors_m(batch.truth_m))
    plain = np.median(solve_batch("mle", bad, robust=None).errors_m(batch.truth_m))
    assert plain > 3 * clean
    assert huber < 0.6 * plain
    assert cauchy < 1.5 * clean


def test_a_stated_sigma_is_not_shrunk_to_nothing_by_a_few_rows():
    """The pixel sigma unstated (variance components on), the range sigma stated, three ranges per problem: the
    ranges' factor from three rows alone came out at 0.022 or below on 5 % of the problems and left 8 in 1,000 far
    outside their ellipsoid (e^T C^-1 e > 20); with the stated sigma counted as VCE_PRIOR_DOF residuals where
    the rows would shrink it, it stays near 1 and every problem is inside."""
    b = paper_batch(1000, n=10, gamma_deg=30.0, seed=5)
    r = b.range_m.copy()
    r[:, 3:] = np.nan
    b = dataclasses.replace(b, range_m=r, sigma=dataclasses.replace(PAPER_SIGMA, pixel_px=None))
    be = solve_batch("mle", b)
    e = be.position_m - b.truth_m
    nees = np.einsum("bi,bij,bj->b", e, np.linalg.inv(be.covariance_m2), e)
    assert (nees <= 20.0).all()
    assert np.quantile(be.extras["variance_factor_range"], 0.05) > 0.3


def test_the_variance_component_prior_only_keeps_a_stated_sigma_from_shrinking():
    """`helmert` with the prior: a group whose rows say it is worse than stated keeps their factor (the admission
    rule and the loss must see it: zoo flight s5/z124's two bad ranges); one they say is better moves toward 1 by
    the prior's weight; an unstated group (prior 0) takes its rows' factor."""
    q = np.array([[30.0, 0.3], [30.0, 0.3]])
    red = np.array([[3.0, 3.0], [3.0, 3.0]])
    f, usable = helmert(q, red, None, np.array([4.0, 4.0]))
    np.testing.assert_allclose(f[0], [10.0, (0.3 + 4.0) / 7.0])
    assert usable.all()
    f0, _ = helmert(q, red, None, 0.0)
    np.testing.assert_allclose(f0, q / red)
    vf = np.array([[2.0, 0.5], [2.0, 0.5]])  # at the current factors the same rows give the same absolute factor
    fv, _ = helmert(q / vf, red, vf, np.array([4.0, 4.0]))
    np.testing.assert_allclose(fv * vf, f)


def test_variance_component_estimation_recovers_the_sensor_sigmas():
    batch = paper_batch(300, gamma_deg=40.0, seed=12)
    unknown = dataclasses.replace(batch, sigma=Sigma())  # no sigmas: start from 1 px, 1 m, then estimate
    be = solve_batch("mle", unknown, robust=None)
    assert (be.extras["vce_rounds"] > 0).all()
    s = PAPER_SIGMA
    true_px = np.sqrt(s.pixel_px ** 2 + (1000 * np.deg2rad(s.attitude_deg)) ** 2 + (1000 * s.position_m / 5000) ** 2)
    true_r = np.hypot(s.range_m, s.position_m)
    est_px = np.sqrt(np.median(be.extras["variance_factor_pixel"]))
    est_r = np.sqrt(np.median(be.extras["variance_factor_range"]))
    assert est_px == pytest.approx(true_px, rel=0.15)
    assert est_r == pytest.approx(true_r, rel=0.2)


def test_covariance_is_consistent_with_the_actual_errors():
    batch = paper_batch(1500, gamma_deg=30.0, seed=13)
    be = solve_batch("mle", batch, robust=None, estimate_variance_components=False,
                     bias_prior_deg=0.0)
    err = be.position_m - batch.truth_m
    # Mahalanobis distances of the errors follow chi-square(3) when the covariance is right: mean 3
    d2 = np.einsum("bi,bij,bj->b", err, np.linalg.inv(be.covariance_m2), err)
    assert 2.4 < np.mean(d2) < 3.6
    horiz = np.linalg.norm(err[:, :2], axis=1)
    assert abs(np.mean(horiz <= be.extras["cep50_m"]) - 0.5) < 0.06
    assert abs(np.mean(horiz <= be.extras["cep90_m"]) - 0.9) < 0.04


@pytest.mark.parametrize("cov", [np.diag([4.0, 4.0]), np.diag([9.0, 1.0]), np.array([[5.0, 3.5], [3.5, 4.0]]),
                                 np.diag([100.0, 0.01])])
def test_cep_matches_monte_carlo(cov):
    rng = np.random.default_rng(0)
    e = rng.multivariate_normal([0.0, 0.0], cov, size=400_000)
    r = np.linalg.norm(e, axis=1)
    for p in (0.5, 0.9):
        got = cep_m(cov[None], p)[0]
        assert got == pytest.approx(np.quantile(r, p), rel=0.01)


def test_cep_of_a_circular_gaussian_is_analytic():
    sigma = 3.0
    got = cep_m(np.diag([sigma ** 2] * 2)[None], 0.5)[0]
    assert got == pytest.approx(sigma * np.sqrt(2 * np.log(2)), rel=1e-9)


def test_single_mle_reports_covariance_ellipsoid_and_cep():
    obs = paper_problem(gamma_deg=30.0, seed=2)
    est = solve("mle", obs, bias_prior_deg=0.0)
    d = est.to_dict(obs.truth_m)
    assert np.array(d["covariance_m2"]).shape == (3, 3)
    ax = np.array(d["ellipsoid"]["semi_axes_1sigma_m"])
    np.testing.assert_allclose(np.sort(ax ** 2), np.linalg.eigvalsh(est.covariance_m2), rtol=1e-9)
    assert d["cep50_m"] < d["cep90_m"]
    assert d["robust"] == "redescending"
