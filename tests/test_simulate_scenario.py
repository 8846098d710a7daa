"""The simulation's scenario generator and config, on their own (no estimators)."""

import math
from pathlib import Path

import numpy as np
import pytest

from pipeline.errors import ConfigError
from pipeline.geometry.camera import project
from pipeline.simulate.config import GeometryConfig, NoiseConfig, SimulationConfig
from pipeline.simulate.scenario import generate, intersection_angle_deg, observation_angle_deg, platform_path_m

CONFIGS = Path(__file__).resolve().parent.parent / "configs"


def _noise_free(**geometry) -> SimulationConfig:
    return SimulationConfig(trials=3, noise=NoiseConfig(0.0, 0.0, 0.0, "independent", 0.0),
                            geometry=GeometryConfig(**geometry))


def _los_angle_deg(a: np.ndarray, b: np.ndarray) -> float:
    return math.degrees(math.acos(a @ b / np.linalg.norm(a) / np.linalg.norm(b)))


@pytest.mark.parametrize("path", ["arc", "straight"])
@pytest.mark.parametrize("angle", [10.0, 35.0, 80.0])
def test_noise_free_observations_are_exact(path, angle):
    cfg = _noise_free(path=path)
    t = generate(cfg, angle)
    b = t.batch
    # The requested intersection angle, measured independently from the first and last lines of sight.
    assert _los_angle_deg(-b.platform_m[0, 0], -b.platform_m[0, -1]) == pytest.approx(angle, abs=1e-9)
    # The target projects onto the measured pixel (the image centre: the target is locked in view) ...
    np.testing.assert_allclose(project(b.P, np.zeros((*b.P.shape[:2], 3))), b.pixel, atol=1e-9)
    np.testing.assert_allclose(b.pixel, np.broadcast_to([300.0, 200.0], b.pixel.shape), atol=1e-9)
    # ... and the ranges are the distances from the platform to the target.
    np.testing.assert_allclose(b.range_m, np.linalg.norm(b.platform_m, axis=-1), rtol=1e-12)
    np.testing.assert_array_equal(b.truth_m, np.zeros((3, 3)))


def test_arc_keeps_height_and_slant_distance():
    g = GeometryConfig(n_observations=7)
    s = platform_path_m(g, 50.0)
    np.testing.assert_allclose(np.linalg.norm(s, axis=1), 5000.0)
    np.testing.assert_allclose(s[:, 2], 2000.0)
    assert observation_angle_deg(g) == pytest.approx(66.42, abs=0.005)  # the paper's theta
    # evenly spaced: all consecutive chords equal
    chords = np.linalg.norm(np.diff(s, axis=0), axis=1)
    np.testing.assert_allclose(chords, chords[0])


def test_straight_path_is_a_level_line_with_midpoint_at_the_slant_distance():
    s = platform_path_m(GeometryConfig(path="straight", n_observations=11), 40.0)
    np.testing.assert_allclose(s[:, 1:], np.broadcast_to(s[0, 1:], (11, 2)))  # y and z constant
    assert np.linalg.norm(s[5]) == pytest.approx(5000.0)
    assert intersection_angle_deg(s) == pytest.approx(40.0)
    assert np.linalg.matrix_rank(s - s.mean(axis=0), tol=1e-6) == 1  # collinear


def test_noise_has_the_configured_size_and_enters_where_it_happens():
    cfg = SimulationConfig(trials=4000, geometry=GeometryConfig(n_observations=5))
    t = generate(cfg, 30.0)
    b = t.batch
    true_range = np.linalg.norm(t.platform_true_m, axis=1)
    assert np.std(b.platform_m - t.platform_true_m) == pytest.approx(5.0, rel=0.03)
    # the range is measured from the TRUE platform position
    assert np.std(b.range_m - true_range) == pytest.approx(2.5, rel=0.03)
    # the pixel is projected through the TRUE camera
    assert np.std(b.pixel - [300.0, 200.0]) == pytest.approx(0.1, rel=0.03)
    # the attitude the estimators see is off by 0.2 deg per axis: the noisy optical axis misses the target by
    # the two off-axis components (a Rayleigh distribution of scale 0.2 deg, mean 0.2 * sqrt(pi / 2))
    axis_seen = b.P[..., 2, :3]  # third row of K R = R's third row = the optical axis in the world frame
    los = -t.platform_true_m
    cosang = np.einsum("bni,ni->bn", axis_seen, los) / np.linalg.norm(axis_seen, axis=-1) / np.linalg.norm(los, axis=-1)
    miss_deg = np.degrees(np.arccos(np.clip(np.abs(cosang), -1, 1)))
    # the seen pose also has the position error, which moves the line by up to ~5 m / 5 km = 0.06 deg
    assert np.mean(miss_deg) == pytest.approx(0.2 * math.sqrt(math.pi / 2), rel=0.08)
    assert np.std(np.degrees(t.attitude_error_rad)) == pytest.approx(0.2, rel=0.03)


def test_accumulating_attitude_is_a_random_walk():
    cfg = SimulationConfig(trials=4000, noise=NoiseConfig(attitude_model="accumulating"))
    err_deg = np.degrees(generate(cfg, 30.0).attitude_error_rad)
    std = err_deg.std(axis=(0, 2))  # per frame
    np.testing.assert_allclose(std, 0.2 * np.sqrt(np.arange(1, 11)), rtol=0.06)
    steps = np.diff(err_deg, axis=1)
    assert abs(np.corrcoef(steps[:, 0, 0], steps[:, 1, 0])[0, 1]) < 0.06  # independent increments


def test_constant_attitude_is_one_bias_per_trial():
    cfg = SimulationConfig(trials=50, noise=NoiseConfig(attitude_model="constant"))
    err = generate(cfg, 30.0).attitude_error_rad
    np.testing.assert_array_equal(err, np.broadcast_to(err[:, :1], err.shape))


def test_generation_is_deterministic_per_seed_and_angle():
    cfg = SimulationConfig(trials=20)
    a, b = generate(cfg, 20.0).batch, generate(cfg, 20.0).batch
    np.testing.assert_array_equal(a.P, b.P)
    np.testing.assert_array_equal(a.range_m, b.range_m)
    other = generate(cfg.replace(seed=cfg.seed + 1), 20.0).batch
    assert not np.array_equal(a.range_m, other.range_m)
    # an angle's trials do not depend on which other angles are in the config
    c = generate(cfg.replace(angles_deg=(20.0,)), 20.0).batch
    np.testing.assert_array_equal(a.pixel, c.pixel)


def test_all_shipped_configs_load():
    paths = sorted(CONFIGS.glob("simulation_*.yaml"))
    assert {p.stem for p in paths} >= {"simulation_table2", "simulation_straight", "simulation_accumulating_attitude",
                                       "simulation_n5", "simulation_n20", "simulation_slant2km",
                                       "simulation_slant10km"}
    default = SimulationConfig.load(CONFIGS / "simulation_table2.yaml")
    assert default.replace(name="x") == SimulationConfig(name="x", description=default.description)
    for p in paths:
        SimulationConfig.load(p)


@pytest.mark.parametrize("text, match", [
    ("trials: 10\ngeometry:\n  pathh: arc\n", r"unknown key\(s\) geometry\.pathh"),
    ("trials: ten\n", r"'trials' must be an integer, got str"),
    ("noise:\n  range_m: [1]\n", r"'noise\.range_m' must be a finite number"),
    ("noise:\n  attitude_model: walk\n", r"'noise\.attitude_model' must be one of"),
    ("methods: [vision, ridgee]\n", r"'methods\[1\]' must be one of .* got 'ridgee' \(did you mean 'ridge'\?\)"),
    ("noise:\n  range_m: -2.5\n", r"'noise\.range_m' must be >= 0, got -2\.5 \(did you mean 2\.5\?\)"),
    ("angles_deg: [10, 150]\n", r"not reachable"),
    ("geometry:\n  height_m: 6000\n", r"height_m"),
    ("- 1\n- 2\n", r"top level must be a mapping"),
    ("a: [\n", r"not valid YAML"),
])
def test_config_errors_name_the_file_and_the_problem(tmp_path, text, match):
    path = tmp_path / "bad.yaml"
    path.write_text(text)
    with pytest.raises(ConfigError, match=match) as info:
        SimulationConfig.load(path)
    assert str(path) in str(info.value)
