"""Every input an estimator cannot use gets its own clear error, never a bare numpy exception."""

import dataclasses

import numpy as np
import pytest

import pipeline.solve.iterate as iterate_mod
from pipeline.errors import GeometryError, ObservationError, SolverError
from pipeline.geometry.camera import intrinsics_matrix, look_at_rotation, project, projection_matrix
from pipeline.solve import METHODS, solve, solve_batch
from pipeline.solve.estimate import Status
from pipeline.solve.iterate import iterate
from pipeline.solve.observations import ObservationBatch, Observations
from pipeline.solve.stacked import Stacked
from support.scenes import paper_problem


@pytest.fixture
def obs():
    return paper_problem(gamma_deg=30.0, seed=1)


def _drop(obs, pixels=(), ranges=()):
    pixel, rng = obs.pixel.copy(), obs.range_m.copy()
    pixel[list(pixels)] = np.nan
    rng[list(ranges)] = np.nan
    return dataclasses.replace(obs, pixel=pixel, range_m=rng)


def test_vision_needs_two_pixels(obs):
    one = _drop(obs, pixels=range(1, obs.n))
    for method in ("vision", "dlt"):
        with pytest.raises(ObservationError, match="at least two frames with a target pixel, got 1"):
            solve(method, one)
    with pytest.raises(ObservationError, match="initialised from vision"):
        solve("fusion", one)
    # with an initial value the fused estimators do not need the vision start
    est = solve("fusion-raw", one, initial_m=[5.0, 5.0, 5.0])
    assert est.converged


def test_the_fusions_refuse_a_problem_without_ranges(obs):
    """Without a range, fusion-raw's stacked system is vision's alone (its answer was vision's, called a fusion):
    it refuses as fusion and ridge do, from vision's start or a given one; with ranges it solves."""
    from pipeline.solve.methods import solve_problems

    no_ranges = _drop(obs, ranges=range(obs.n))
    for method in ("fusion-raw", "fusion", "ridge"):
        with pytest.raises(ObservationError, match=f"^{method} fuses pixels with ranges but there are no ranges"):
            solve(method, no_ranges)
        with pytest.raises(ObservationError, match="there are no ranges"):
            solve(method, no_ranges, initial_m=obs.truth_m)
    refused, solved = solve_problems([no_ranges, obs], ["fusion-raw"])  # the path of `run` and `locate`
    assert isinstance(refused["fusion-raw"], ObservationError) and solved["fusion-raw"].converged


def test_ranges_without_pixels_still_give_range(obs):
    """Issue 12: a file with laser ranges but no pixels. range-only (the paper's start is vision's estimate)
    starts from the ranges along the optical axes (the rangefinder is boresighted) and solves, reaching the
    same point as from vision's start; mle, whose linearized covariance would not be honest on ranges alone,
    says so."""
    blind = _drop(obs, pixels=range(obs.n))
    est = solve("range", blind)
    assert est.converged
    np.testing.assert_allclose(est.position_m, solve("range", obs).position_m, atol=1e-3)
    with pytest.raises(ObservationError, match=r"mle starts from .*\(ranges alone: see range"):
        solve("mle", blind)
    # the batched path takes the same start
    be = solve_batch("range", ObservationBatch.stack([blind, blind]))
    np.testing.assert_allclose(be.position_m, np.stack([est.position_m] * 2), atol=1e-6)
    for method in ("dlt", "vision", "fusion"):
        with pytest.raises(ObservationError, match="at least two frames with a target pixel, got 0"):
            solve(method, blind)


def test_range_only_needs_three_ranges(obs):
    with pytest.raises(ObservationError, match="at least three laser ranges, got 2"):
        solve("range", _drop(obs, ranges=range(2, obs.n)))


def test_los_needs_a_frame_with_pixel_and_range(obs):
    bad = _drop(obs, pixels=range(0, obs.n, 2), ranges=range(1, obs.n, 2))
    with pytest.raises(ObservationError, match="both a target pixel and a range"):
        solve("los", bad)


def test_fusion_needs_ranges(obs):
    with pytest.raises(ObservationError, match="no ranges; use vision"):
        solve("ridge", _drop(obs, ranges=range(obs.n)))


def test_mle_needs_a_start_and_three_observations(obs):
    with pytest.raises(ObservationError, match="mle starts from"):
        solve("mle", _drop(obs, pixels=range(1, obs.n), ranges=range(obs.n)))
    with pytest.raises(ObservationError, match="at least three observations"):
        solve("mle", _drop(obs, pixels=range(obs.n), ranges=range(2, obs.n)), initial_m=[0.0, 0.0, 0.0])


def test_non_finite_and_mismatched_inputs(obs):
    with pytest.raises(ObservationError, match="NaN"):
        Observations(P=obs.P * np.nan, pixel=obs.pixel, platform_m=obs.platform_m, range_m=obs.range_m)
    with pytest.raises(ObservationError, match="infinite"):
        Observations(P=obs.P, pixel=obs.pixel + np.inf, platform_m=obs.platform_m, range_m=obs.range_m)
    with pytest.raises(ObservationError, match="mismatched lengths"):
        Observations(P=obs.P, pixel=obs.pixel, platform_m=obs.platform_m, range_m=obs.range_m[:-1])


def test_coincident_camera_positions(obs):
    K = intrinsics_matrix(1000, 1000, 300, 200)
    c = np.tile([0.0, -4500.0, 2000.0], (obs.n, 1))
    P = projection_matrix(K, look_at_rotation(c, np.zeros(3)), c)
    same = Observations(P=P, pixel=project(P, np.zeros((obs.n, 3))), platform_m=c,
                        range_m=np.full(obs.n, np.linalg.norm(c[0])))
    with pytest.raises(GeometryError, match="one camera position"):
        solve("vision", same)
    with pytest.raises(GeometryError, match="share one platform position"):
        solve("range", same, initial_m=[1.0, 1.0, 1.0])
    # a pixel and a range from one position do locate the target: the fused estimators cope
    est = solve("mle", same)
    assert np.linalg.norm(est.position_m) < 1e-3


def test_collinear_platforms_for_range_only(obs):
    n = obs.n
    s = np.stack([np.linspace(-400, 400, n), np.full(n, -4500.0), np.full(n, 2000.0)], axis=1)
    line = dataclasses.replace(obs, platform_m=s, range_m=np.linalg.norm(s, axis=1))
    with pytest.raises(GeometryError, match="collinear"):
        solve("range", line)


def test_target_behind_the_cameras(obs):
    K = intrinsics_matrix(1000, 1000, 300, 200)
    c = obs.platform_m
    # cameras looking away from the target still "see" its projection through P, from behind
    away = 2 * c - obs.truth_m
    P = projection_matrix(K, look_at_rotation(c, away), c)
    pix = project(P, np.broadcast_to(obs.truth_m, (obs.n, 3)))
    behind = dataclasses.replace(obs, P=P, pixel=pix)
    for method in ("dlt", "vision", "fusion-raw"):
        with pytest.raises(GeometryError, match="behind the camera"):
            solve(method, behind)
    # mle starts from the lines of sight instead, so its answer (a poor fit) stays in front of the cameras
    est = solve("mle", behind)
    assert (Stacked.from_observations(behind).depths(est.position_m[None]) > 0).all()


def test_a_flipped_projection_matrix_is_not_behind(obs):
    flipped = dataclasses.replace(obs, P=-obs.P)  # P and -P are the same camera
    np.testing.assert_allclose(solve("vision", flipped).position_m, solve("vision", obs).position_m, atol=1e-9)
    np.testing.assert_allclose(solve("los", flipped).position_m, solve("los", obs).position_m, atol=1e-9)


def test_singular_projection_matrix(obs):
    P = obs.P.copy()
    P[3, :, :3] = 0.0
    with pytest.raises(ObservationError, match="not a finite camera"):
        solve("vision", dataclasses.replace(obs, P=P))


@pytest.mark.parametrize("method", [m for m in METHODS if m not in ("dlt", "los")])
def test_divergence_raises_solver_error(obs, method, monkeypatch):
    monkeypatch.setattr(iterate_mod, "DIVERGENCE_FACTOR", 1e-9)
    with pytest.raises(SolverError, match="diverged"):
        solve(method, obs, initial_m=[50.0, 50.0, 50.0])


def test_driver_flags_exploding_and_non_finite_steps(obs):
    st = Stacked.from_observations(obs)

    def doubling(sub, X):
        return X * 10.0 + 1.0, np.zeros(len(X), dtype=bool), {}

    _, it, status, _ = iterate(st, np.array([[1.0, 1.0, 1.0]]), doubling, 1e-4, 50)
    assert status[0] == Status.DIVERGED and it[0] < 50

    def nan_step(sub, X):
        return np.full_like(X, np.nan), np.zeros(len(X), dtype=bool), {}

    _, it, status, _ = iterate(st, np.array([[1.0, 1.0, 1.0]]), nan_step, 1e-4, 50)
    assert status[0] == Status.DIVERGED and it[0] == 1


def test_batch_survives_broken_frames_and_problems(obs):
    P = obs.P.copy()
    P[2] = 0.0  # not a camera at all
    pixel = obs.pixel.copy()
    pixel[2] = np.nan
    broken = dataclasses.replace(obs, P=P, pixel=pixel)
    batch = ObservationBatch.stack([obs, broken])
    los = solve_batch("los", batch)
    assert np.isnan(los.extras["points_m"][1, 2]).all() and np.isfinite(los.position_m).all()
    for method in METHODS:
        be = solve_batch(method, batch)
        assert np.isfinite(be.position_m[0]).all()


def test_range_only_on_a_noisy_straight_line_is_degenerate():
    # positions on a straight line plus their 5 m noise: collinear within the noise -> flagged, not answered
    rng = np.random.default_rng(5)
    base = paper_problem(gamma_deg=30.0, seed=1)
    n = base.n
    line = np.stack([np.linspace(-1500, 1500, n), np.full(n, -4583.0), np.full(n, 2000.0)], axis=1)
    problems = []
    for _ in range(40):
        meas = line + rng.normal(0.0, 5.0, line.shape)
        rng_m = np.linalg.norm(line, axis=1) + rng.normal(0.0, 2.5, n)
        problems.append(dataclasses.replace(base, platform_m=meas, range_m=rng_m))
    be = solve_batch("range", ObservationBatch.stack(problems), initial_m=np.zeros(3))
    assert be.extras["collinear_platforms"].mean() > 0.8
    assert (be.status[be.extras["collinear_platforms"]] == Status.DEGENERATE).all()
    flagged = int(np.flatnonzero(be.extras["collinear_platforms"])[0])
    with pytest.raises(GeometryError, match="straight line within their position noise"):
        solve("range", problems[flagged], initial_m=np.zeros(3))
    # a 30 deg arc is not collinear within the noise
    arc = solve_batch("range", ObservationBatch.stack([paper_problem(gamma_deg=30.0, seed=s) for s in range(20)]))
    assert not arc.extras["collinear_platforms"].any()
