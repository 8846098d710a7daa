"""The MLE's terrain prior `terrain=(fn, sigma_m)`: a single view without a range meets the terrain, the prior
shrinks a weak geometry's vertical uncertainty, the option's checks."""

import numpy as np
import pytest

from pipeline.solve import methods, solve, solve_batch
from pipeline.solve.observations import Observations, Sigma
from support.scenes import paper_batch

F_PX, CX, CY = 1000.0, 640.0, 360.0
K = np.array([[F_PX, 0.0, CX], [0.0, F_PX, CY], [0.0, 0.0, 1.0]])


def _camera(centre, look_at):
    """P (3,4) of a camera at centre looking at look_at (image x to the right, y down)."""
    z = np.asarray(look_at, float) - centre
    z /= np.linalg.norm(z)
    x = np.cross(z, [0.0, 0.0, 1.0])
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    R = np.stack([x, y, z])  # world -> camera rows
    return K @ np.hstack([R, -(R @ centre)[:, None]]), R


def _ray_plane(centre, R, uv, a, b, c):
    """The point where the line of sight through pixel uv meets the plane up = a e + b n + c (by hand)."""
    d = R.T @ np.linalg.solve(K, [uv[0], uv[1], 1.0])
    t = (c + a * centre[0] + b * centre[1] - centre[2]) / (d[2] - a * d[0] - b * d[1])
    return centre + t * d


def _plane(a, b, c):
    def fn(e_m, n_m):
        e, n = np.asarray(e_m, float), np.asarray(n_m, float)
        return a * e + b * n + c, np.full(e.shape, a), np.full(n.shape, b)
    return fn


SIGMAS = [Sigma(pixel_px=1.0, range_m=1.0, position_m=0.0, attitude_deg=0.0),
          Sigma(pixel_px=1.0, range_m=1.0, position_m=2.0, attitude_deg=0.5)]


@pytest.mark.parametrize("sigma", SIGMAS)
@pytest.mark.parametrize("a, b, c", [(0.0, 0.0, 12.0), (0.08, -0.05, -7.0)])
def test_one_view_without_range_meets_the_terrain(sigma, a, b, c):
    centre = np.array([30.0, -40.0, 150.0])
    P, R = _camera(centre, [300.0, 200.0, 0.0])
    uv = np.array([700.0, 410.0])
    obs = Observations(P=P[None], pixel=uv[None], platform_m=centre[None], range_m=np.array([np.nan]), sigma=sigma)
    truth = _ray_plane(centre, R, uv, a, b, c)
    est = solve("mle", obs, terrain=(_plane(a, b, c), 2.0))
    np.testing.assert_allclose(est.position_m, truth, atol=1e-3)
    # from a start off the ray and off the terrain, the iteration itself gets there
    far = solve("mle", obs, terrain=(_plane(a, b, c), 2.0), initial_m=truth + np.array([20.0, -15.0, 10.0]))
    np.testing.assert_allclose(far.position_m, truth, atol=1e-3)
    assert est.covariance_m2 is not None and np.isfinite(est.covariance_m2).all()
    # the vertical is held by the prior alone: its variance (2 m)^2, plus the shared GNSS offset's the mle adds
    # to the covariance when the bias's size is learned (position_m^2), bounds the vertical variance
    assert 0.0 < est.covariance_m2[2, 2] <= 2.0 ** 2 + sigma.position_m ** 2 + 1e-9


def test_without_the_terrain_one_view_is_refused():
    centre = np.array([0.0, 0.0, 100.0])
    P, _ = _camera(centre, [200.0, 0.0, 0.0])
    obs = Observations(P=P[None], pixel=np.array([[640.0, 360.0]]), platform_m=centre[None],
                       range_m=np.array([np.nan]), sigma=SIGMAS[0])
    with pytest.raises(Exception, match="mle"):
        solve("mle", obs)


def test_the_prior_shrinks_a_weak_geometrys_vertical_covariance():
    rng = np.random.default_rng(3)
    target = np.array([400.0, 250.0, 20.0])
    centres = np.array([[0.0, 0.0, 120.0], [1.5, 1.0, 120.0], [3.0, 2.0, 120.5]])  # a short baseline, no ranges
    Ps, pix = [], []
    for cen in centres:
        P, _ = _camera(cen, target + rng.normal(0, 5, 3))
        q = P @ np.r_[target, 1.0]
        Ps.append(P)
        pix.append(q[:2] / q[2] + rng.normal(0, 0.5, 2))
    obs = Observations(P=np.array(Ps), pixel=np.array(pix), platform_m=centres, range_m=np.full(3, np.nan),
                       sigma=SIGMAS[0])
    free = solve("mle", obs)
    held = solve("mle", obs, terrain=(_plane(0.0, 0.0, 20.0), 1.0))
    assert free.covariance_m2[2, 2] > 25.0  # weak: the baseline hardly fixes the depth
    assert held.covariance_m2[2, 2] < 1.0
    assert np.linalg.norm(held.position_m - target) < np.linalg.norm(free.position_m - target)


def test_the_option_is_listed_checked_and_refused_by_the_batch():
    assert "terrain" in methods._OPTIONS["mle"]
    centre = np.array([0.0, 0.0, 100.0])
    P, _ = _camera(centre, [200.0, 0.0, 0.0])
    obs = Observations(P=P[None], pixel=np.array([[640.0, 360.0]]), platform_m=centre[None],
                       range_m=np.array([np.nan]), sigma=SIGMAS[0])
    for bad in [(_plane(0, 0, 0), 0.0), (_plane(0, 0, 0), np.nan), ("not callable", 1.0), (_plane(0, 0, 0),)]:
        with pytest.raises(ValueError, match="terrain"):
            solve("mle", obs, terrain=bad)
    with pytest.raises(ValueError, match="terrain"):
        solve_batch("mle", paper_batch(2, seed=0), terrain=(_plane(0, 0, 0), 1.0))
