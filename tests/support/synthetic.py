"""A synthetic flight group like the paper's flight experiments (section 3.2), solved by every estimator.

Test and benchmark support, not part of the package: for the outputs' tests, the batch benchmark and a demo run
(`python scripts/demo_run.py OUTDIR` writes a whole run folder for six groups shaped like the paper's Table 3):
a curving, climbing leg about 5 km from the target at an observation angle of 66.42 deg off nadir, a 600 x 400 px
camera kept on the target, noise as in the paper (pixel 1 px, range 5 m, position 2 m, attitude 0.2 deg). Not a
replacement for the simulation (`ridgeloc simulate`), which follows the paper's protocol exactly.
"""

from __future__ import annotations

import time

import numpy as np
from scipy.spatial.transform import Rotation

from pipeline.errors import RidgelocError
from pipeline.geometry.camera import intrinsics_matrix, look_at_rotation, project, projection_matrix
from pipeline.geometry.rays import intersection_angle_deg as los_angle_deg
from pipeline.results import GroupResult
from pipeline.solve.observations import Observations, Sigma

DEFAULT_ORIGIN_LLA = (28.2282, 112.9388, 60.0)  # WGS84, ellipsoid height: an arbitrary site


def synthetic_observations(*, seed: int = 0, intersection_angle_deg: float = 40.0, n_frames: int = 16,
                           slant_range_m: float = 5000.0, off_nadir_deg: float = 66.42, speed_m_s: float = 60.0,
                           sigma: Sigma | None = None) -> tuple[Observations, np.ndarray]:
    """Observations of one straight leg and the true target (3,) m in the same ENU frame."""
    rng = np.random.default_rng(seed)
    sigma = sigma or Sigma(pixel_px=1.0, range_m=5.0, position_m=2.0, attitude_deg=0.2)
    target = np.array([35.0, -20.0, 12.0]) + rng.normal(0, 10, 3) * [1, 1, 0.2]
    height = slant_range_m * np.cos(np.radians(off_nadir_deg))
    ground = slant_range_m * np.sin(np.radians(off_nadir_deg))
    half = ground * np.tan(np.radians(intersection_angle_deg) / 2)
    heading = rng.uniform(0, 2 * np.pi)
    along = np.array([np.cos(heading), np.sin(heading), 0.0])
    across = np.array([-np.sin(heading), np.cos(heading), 0.0])
    s = np.linspace(-half, half, n_frames)
    # a curving, climbing leg: a straight level one would leave the range-only solution free to turn about it
    u = s / max(half, 1.0)
    centre = (target + ground * across + np.array([0, 0, height]) + s[:, None] * along
              - (0.12 * ground * u ** 2)[:, None] * across)
    centre[:, 2] += 120.0 * u + rng.normal(0, 3, n_frames).cumsum() * 0.3
    K = intrinsics_matrix(1400.0, 1400.0, 300.0, 200.0)
    R_true = look_at_rotation(centre, target)
    R_true = Rotation.from_rotvec(rng.normal(0, np.radians(0.3), (n_frames, 3))).as_matrix() @ R_true  # jitter
    pixel = project(projection_matrix(K, R_true, centre), np.broadcast_to(target, (n_frames, 3)))
    pixel += rng.normal(0, sigma.pixel_px or 0.0, pixel.shape)
    att_err = Rotation.from_rotvec(rng.normal(0, np.radians(sigma.attitude_deg or 0.0), (n_frames, 3))).as_matrix()
    centre_meas = centre + rng.normal(0, sigma.position_m or 0.0, centre.shape)
    P = projection_matrix(K, att_err @ R_true, centre_meas)
    rng_m = np.linalg.norm(target - centre, axis=1) + rng.normal(0, sigma.range_m or 0.0, n_frames)
    t_ns = (np.abs(s - s[0]) / speed_m_s * 1e9).astype(np.int64)
    obs = Observations(P=P, pixel=pixel, platform_m=centre_meas, range_m=rng_m, t_ns=t_ns, sigma=sigma,
                       truth_m=target)
    return obs, target


def solve_all(obs: Observations, methods=None) -> tuple[dict, float]:
    """Every estimator that succeeds on `obs` (a failing one is left out) and the wall seconds it took."""
    from pipeline.solve import METHODS, solve

    t0 = time.perf_counter()
    estimates = {}
    for m in methods or METHODS:
        try:
            estimates[m] = solve(m, obs)
        except RidgelocError:
            continue
    return estimates, time.perf_counter() - t0


def synthetic_group(name: str, *, seed: int = 0, intersection_angle_deg: float = 40.0, n_frames: int = 16,
                    origin_lla: tuple[float, float, float] = DEFAULT_ORIGIN_LLA, methods=None,
                    truth_known: bool = True) -> GroupResult:
    """A solved synthetic group (see the module docstring)."""
    t0 = time.perf_counter()
    obs, target = synthetic_observations(seed=seed, intersection_angle_deg=intersection_angle_deg,
                                         n_frames=n_frames)
    t_obs = time.perf_counter() - t0
    estimates, t_solve = solve_all(obs, methods)
    return GroupResult(
        name=name, origin_lla=origin_lla, observations=obs, estimates=estimates,
        truth_m=target if truth_known else None,
        intersection_angle_deg=los_angle_deg(obs.platform_m, target),
        timings_s={"synthesize": t_obs, "solve": t_solve},
        settings={"synthetic": {"seed": seed, "intersection_angle_deg": intersection_angle_deg,
                                "n_frames": n_frames}},
    )


# The paper's Table 3: intersection angle (deg) and observation count of its six flight groups.
TABLE3_GROUPS = ((53.97, 16), (24.03, 17), (24.36, 34), (31.42, 11), (46.46, 18), (36.41, 11))


def demo_run(outdir) -> None:
    """Write a complete run output folder for six synthetic groups shaped like the paper's Table 3."""
    from pipeline.report.outputs import write_run_outputs

    results = [synthetic_group(f"group{i + 1}", seed=i, intersection_angle_deg=a, n_frames=n)
               for i, (a, n) in enumerate(TABLE3_GROUPS)]
    write_run_outputs(outdir, results, [], {"demo": "python scripts/demo_run.py " + str(outdir)})
