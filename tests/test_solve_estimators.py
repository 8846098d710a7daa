"""Estimators against noise-free truth, finite differences, scipy.optimize.least_squares and each other."""

import dataclasses

import numpy as np
import pytest
from scipy.optimize import least_squares

from pipeline.geometry.camera import project
from pipeline.solve import METHODS, solve, solve_batch
from pipeline.solve.estimate import Status
from pipeline.solve.least_squares import normalized_normal_equations
from pipeline.solve.observations import ObservationBatch, Observations, Sigma
from pipeline.solve.stacked import Stacked, pixel_model, range_model, solve_spd
from support.references import normalized_system
from support.scenes import PAPER_SIGMA, paper_batch, paper_problem

NOISE_FREE = Sigma(0.0, 0.0, 0.0, 0.0)


def _with_gaps(obs: Observations) -> Observations:
    pixel = obs.pixel.copy()
    rng = obs.range_m.copy()
    pixel[2] = np.nan
    rng[5] = np.nan
    return dataclasses.replace(obs, pixel=pixel, range_m=rng)


@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("gamma_deg", [10.0, 60.0])
def test_noise_free_recovers_target_to_a_millimetre(method, gamma_deg):
    obs = _with_gaps(paper_problem(gamma_deg=gamma_deg, sigma=NOISE_FREE))
    truth = np.array([0.0, 0.0, 0.0])
    # start the iterative methods away from the answer so that they have to iterate
    opts = {} if method in ("dlt", "los") else {"initial_m": truth + np.array([30.0, -20.0, 15.0])}
    if method == "mle":
        opts["sigma"] = PAPER_SIGMA
    est = solve(method, obs, **opts)
    assert est.converged, est.status
    assert np.linalg.norm(est.position_m - truth) < 1e-3
    if method not in ("dlt", "los"):
        assert est.iterations >= 2


def test_batch_extras_have_per_problem_shapes():
    batch = paper_batch(5, seed=1)
    los = solve_batch("los", batch)
    assert los.extras["points_m"].shape == (5, 10, 3)
    assert los.extras["oracle_error_m"].shape == (5,)
    errs = np.linalg.norm(los.extras["points_m"] - batch.truth_m[:, None, :], axis=-1)
    np.testing.assert_allclose(los.extras["oracle_error_m"], errs.min(axis=1))
    mle = solve_batch("mle", batch)
    assert mle.covariance_m2.shape == (5, 3, 3)
    assert mle.extras["cep50_m"].shape == (5,) and (mle.extras["cep90_m"] > mle.extras["cep50_m"]).all()


def _fd_jacobian(f, X, h=1e-3):
    cols = []
    for k in range(3):
        d = np.zeros(3)
        d[k] = h
        cols.append((f(X + d) - f(X - d)) / (2 * h))
    return np.stack(cols, axis=-1)


def test_pixel_jacobian_matches_finite_differences():
    obs = paper_problem(gamma_deg=40.0, seed=2)
    st = Stacked.from_observations(obs)
    X = np.array([37.0, -21.0, 12.0])
    J, _, ok = pixel_model(st, X[None])
    fd = _fd_jacobian(lambda x: project(obs.P, np.broadcast_to(x, (obs.n, 3))).reshape(-1), X)
    assert ok.all()
    np.testing.assert_allclose(J[0], fd, rtol=1e-6, atol=1e-9)
    # the paper's eq. (10) second row (m4/M3 - m8 M1/M3^2, m2/M3 - m10 M1/M3^2, m6/M3 - m10 M1/M3^2) is wrong
    P = obs.P[0]
    q = P @ np.r_[X, 1.0]
    paper_row2 = np.array([P[1, 0] / q[2] - P[2, 0] * q[0] / q[2] ** 2, P[0, 2] / q[2] - P[2, 2] * q[0] / q[2] ** 2,
                           P[1, 2] / q[2] - P[2, 2] * q[0] / q[2] ** 2])
    assert not np.allclose(paper_row2, fd[1], rtol=1e-3)


def test_range_jacobian_matches_finite_differences():
    obs = paper_problem(gamma_deg=40.0, seed=2)
    st = Stacked.from_observations(obs)
    X = np.array([37.0, -21.0, 12.0])
    J, r, _ = range_model(st, X[None])
    fd = _fd_jacobian(lambda x: np.linalg.norm(x - obs.platform_m, axis=1), X)
    np.testing.assert_allclose(J[0], fd, rtol=1e-7, atol=1e-10)
    np.testing.assert_allclose(r[0], obs.range_m - np.linalg.norm(X - obs.platform_m, axis=1))


def _scipy_fit(residual, x0):
    return least_squares(residual, x0, method="lm", jac="3-point", xtol=1e-15, ftol=1e-15, gtol=1e-15).x


@pytest.mark.parametrize("method", ["vision", "range", "fusion-raw"])
def test_gauss_newton_matches_scipy_least_squares(method):
    obs = paper_problem(gamma_deg=40.0, seed=5)

    def pix_res(x):
        return (obs.pixel - project(obs.P, np.broadcast_to(x, (obs.n, 3)))).reshape(-1)

    def rng_res(x):
        return obs.range_m - np.linalg.norm(x - obs.platform_m, axis=1)

    residual = {"vision": pix_res, "range": rng_res,
                "fusion-raw": lambda x: np.r_[pix_res(x), rng_res(x)]}[method]
    x0 = solve("vision", obs).position_m if method != "vision" else solve("dlt", obs).position_m
    est = solve(method, obs, initial_m=x0, tol_m=1e-9)
    ref = _scipy_fit(residual, x0)
    # range alone is weak along one direction (smallest curvature ~1e-3 m^-2 here): a 1e-4 m move changes the cost
    # by ~1e-11 of 69 m^2, at its rounding, where scipy's ftol test stops wherever rounding leaves it; there
    # compare the costs, which ours must not exceed
    cost = 0.5 * float(residual(est.position_m) @ residual(est.position_m))
    assert cost <= 0.5 * float(residual(ref) @ residual(ref)) * (1 + 1e-12)
    # scipy stops where its ftol / xtol tests say (within a few 1e-6 m of the minimum, by its version and the BLAS
    # kernel); ours must match it to 1e-5 m and, above, cost no more
    np.testing.assert_allclose(est.position_m, ref, atol=1e-3 if method == "range" else 1e-5)


def test_dlt_is_the_algebraic_least_squares_of_the_normalised_rows():
    obs = paper_problem(gamma_deg=30.0, seed=1)
    est = solve("dlt", obs)
    # independent check: at the DLT point the reprojection error is of the noise size, and the DLT point is
    # a fixed point of nothing else: it differs from the geometric (vision) optimum but only by metres
    assert np.abs(est.residuals).max() < 20
    vis = solve("vision", obs)
    assert 0 < np.linalg.norm(est.position_m - vis.position_m) < 50


@pytest.mark.parametrize("gamma_deg", [1.0, 30.0])
def test_dlt_is_the_smallest_singular_vector_of_the_normalised_system(gamma_deg):
    # an independent construction (SVD of A, not eigh of A^T A), at a small angle where the two smallest
    # singular values are close
    batch = paper_batch(5, gamma_deg=gamma_deg, seed=9)
    be = solve_batch("dlt", batch)
    for b in range(5):
        obs = batch.problem(b)
        c = obs.platform_m.mean(axis=0)
        sc = max(np.sqrt(((obs.platform_m - c) ** 2).sum(axis=1).mean()), 1.0)
        T = np.block([[sc * np.eye(3), c[:, None]], [np.zeros((1, 3)), np.ones((1, 1))]])
        rows = []
        for P, (u, v) in zip(obs.P @ T, obs.pixel, strict=True):
            rows += [u * P[2] - P[0], v * P[2] - P[1]]
        A = np.array(rows)
        A /= np.linalg.norm(A, axis=1, keepdims=True)
        x = np.linalg.svd(A)[2][-1]
        np.testing.assert_allclose(be.position_m[b], c + sc * x[:3] / x[3], rtol=0, atol=1e-6)
        np.testing.assert_allclose(solve("dlt", obs).position_m, be.position_m[b], rtol=0, atol=1e-8)


def test_los_with_lever_arm_uses_camera_centre_and_range_sphere():
    obs = paper_problem(gamma_deg=30.0, sigma=NOISE_FREE)
    # laser 3 m to the side of the camera: ranges measured from the laser position
    platform = obs.platform_m + np.array([0.0, 0.0, 3.0])
    rng = np.linalg.norm(platform - obs.truth_m, axis=1)
    moved = dataclasses.replace(obs, platform_m=platform, range_m=rng)
    est = solve("los", moved)
    pts = np.array(est.extras["points_m"])
    np.testing.assert_allclose(pts, np.zeros_like(pts), atol=1e-6)


def test_ridge_with_k_zero_equals_fusion():
    obs = paper_problem(gamma_deg=20.0, seed=4)
    a = solve("fusion", obs)
    b = solve("ridge", obs, k=0.0)
    np.testing.assert_array_equal(a.position_m, b.position_m)
    assert a.iterations == b.iterations
    c = solve("ridge", obs, k=0.05)
    assert np.linalg.norm(c.position_m - a.position_m) > 1e-6


def _paper_step_by_hand(obs, X0, ridge_k=None):
    """Eqs. (36)-(39) / (43)-(45) written out directly, for one iteration of one problem (no gaps)."""
    n = obs.n
    F = project(obs.P, np.broadcast_to(X0, (n, 3))).reshape(-1)
    H = np.zeros((2 * n, 3))
    for i in range(n):
        m = obs.P[i]
        M1, M2, M3 = m @ np.r_[X0, 1.0]
        H[2 * i] = m[0, :3] / M3 - m[2, :3] * M1 / M3 ** 2
        H[2 * i + 1] = m[1, :3] / M3 - m[2, :3] * M2 / M3 ** 2
    d0 = np.linalg.norm(X0 - obs.platform_m, axis=1)
    h = (X0 - obs.platform_m) / d0[:, None]
    dpsi = obs.pixel.reshape(-1) - F
    dphi = obs.range_m - d0
    Max, Min, mx, mn = dpsi.max(), dpsi.min(), dphi.max(), dphi.min()
    T = np.block([[H / (Max - Min), np.full((2 * n, 1), -Min / (Max - Min))],
                  [h / (mx - mn), np.full((n, 1), -mn / (mx - mn))]])
    dPhi = np.r_[(dpsi - Min) / (Max - Min), (dphi - mn) / (mx - mn)]
    TtT = T.T @ T
    beta_ls = np.linalg.solve(TtT, T.T @ dPhi)
    if ridge_k is None:
        return beta_ls, T, dPhi
    t = np.linalg.matrix_rank(T)
    m = 3 * n
    delta0 = dPhi @ (np.eye(m) - T @ np.linalg.inv(TtT) @ T.T) @ dPhi / (m - t)
    k = t * delta0 / (beta_ls @ TtT @ beta_ls)
    return np.linalg.solve(TtT + k * np.eye(4), T.T @ dPhi), k


def test_normalized_fusion_and_ridge_follow_the_paper_equations():
    obs = paper_problem(gamma_deg=20.0, seed=6)
    X0 = np.array([20.0, -10.0, 5.0])
    beta, T_hand, dPhi_hand = _paper_step_by_hand(obs, X0)
    T, dPhi, rows = normalized_system(Stacked.from_observations(obs), X0[None])
    np.testing.assert_allclose(T[0], T_hand, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(dPhi[0], dPhi_hand, rtol=1e-9, atol=1e-12)
    assert rows[0] == 3 * obs.n
    one = solve("fusion", obs, initial_m=X0, max_iterations=1)
    np.testing.assert_allclose(one.position_m, X0 + beta[:3], atol=1e-8)
    beta_r, k = _paper_step_by_hand(obs, X0, ridge_k=True)
    one_r = solve("ridge", obs, initial_m=X0, max_iterations=1)
    np.testing.assert_allclose(one_r.extras["k"], k, rtol=1e-8)
    np.testing.assert_allclose(one_r.position_m, X0 + beta_r[:3], atol=1e-8)


def test_min_equal_max_is_guarded():
    # a single range: max = min for the range block; the step must still be finite
    obs = paper_problem(gamma_deg=30.0, seed=2)
    rng = np.full(obs.n, np.nan)
    rng[3] = obs.range_m[3]
    one = dataclasses.replace(obs, range_m=rng)
    for method in ("fusion", "ridge"):
        est = solve(method, one, max_iterations=200)
        assert np.isfinite(est.position_m).all()


def test_textbook_hkb_variant_runs_and_differs():
    obs = paper_problem(gamma_deg=20.0, seed=4)
    a = solve("ridge", obs, hkb="paper", max_iterations=3)
    b = solve("ridge", obs, hkb="textbook", max_iterations=3)
    assert a.extras["k"] > 0 and b.extras["k"] > 0
    assert np.linalg.norm(a.position_m - b.position_m) > 1e-9


def test_max_iterations_is_reported_not_hidden():
    obs = paper_problem(gamma_deg=10.0, seed=1)
    est = solve("vision", obs, max_iterations=1, initial_m=[100.0, 100.0, 100.0])
    assert est.status == Status.MAX_ITERATIONS and not est.converged
    assert est.to_dict()["converged"] is False


def test_unknown_method_and_option():
    obs = paper_problem()
    with pytest.raises(ValueError, match="unknown method"):
        solve("magic", obs)
    with pytest.raises(ValueError, match="takes no option"):
        solve("vision", obs, hkb="paper")
    with pytest.raises(ValueError, match="hkb must be"):
        solve("ridge", obs, hkb="other")


def test_batch_flags_degenerate_problems_without_raising():
    good = paper_problem(gamma_deg=30.0, seed=1)
    # straight, level flight line: range-only cannot fix the rotation about it
    n = good.n
    s = np.stack([np.linspace(-400, 400, n), np.full(n, -4500.0), np.full(n, 2000.0)], axis=1)
    rng = np.linalg.norm(s, axis=1)
    line = Observations(P=good.P, pixel=good.pixel, platform_m=s, range_m=rng, truth_m=np.zeros(3))
    batch = ObservationBatch.stack([good, line])
    be = solve_batch("range", batch, initial_m=np.array([[1.0, 2.0, 3.0], [1.0, 2.0, 3.0]]))
    assert be.status[0] == Status.CONVERGED and be.status[1] == Status.DEGENERATE
    assert np.isnan(be.position_m[1]).all() and np.isfinite(be.position_m[0]).all()


def test_small_dense_solvers_match_lapack():
    rng = np.random.default_rng(3)
    for k in (3, 4):
        A = rng.normal(size=(50, 8, k))
        N = np.swapaxes(A, 1, 2) @ A
        g = rng.normal(size=(50, k))
        x, singular = solve_spd(N, g)
        assert not singular.any()
        np.testing.assert_allclose(x, np.linalg.solve(N, g[..., None])[..., 0], rtol=1e-9, atol=1e-12)
    N[0, :, 0] = N[0, 0, :] = 0.0  # a dependent column
    assert solve_spd(N, g)[1][0] and not solve_spd(N, g)[1][1:].any()


def test_normalized_normal_equations_equal_t_transpose_t():
    batch = paper_batch(4, gamma_deg=20.0, seed=2)
    pixel = batch.pixel.copy()
    pixel[0, 3] = np.nan
    batch = dataclasses.replace(batch, pixel=pixel)
    st = Stacked.from_batch(batch)
    X = batch.truth_m + np.array([3.0, -2.0, 1.0])
    T, dPhi, rows = normalized_system(st, X)
    N, g, dd, rows2 = normalized_normal_equations(st, X)
    np.testing.assert_allclose(N, np.swapaxes(T, 1, 2) @ T, rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(g, (np.swapaxes(T, 1, 2) @ dPhi[..., None])[..., 0], rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(dd, (dPhi * dPhi).sum(axis=1), rtol=1e-10)
    np.testing.assert_array_equal(rows, rows2)
