import json

import numpy as np
import pytest

from pipeline import observation_file
from pipeline.errors import ObservationError
from pipeline.geometry.camera import intrinsics_matrix, look_at_rotation, project, projection_matrix
from pipeline.solve.observations import ObservationBatch, Observations


def _problem(n=4):
    K = intrinsics_matrix(1000, 1000, 300, 200)
    target = np.array([10.0, 20.0, 5.0])
    ang = np.linspace(0, 0.5, n)
    centres = np.stack([4000 * np.cos(ang), 4000 * np.sin(ang), np.full(n, 2000.0)], axis=1)
    P = projection_matrix(K, look_at_rotation(centres, target), centres)
    pix = project(P, np.broadcast_to(target, (n, 3)))
    rng = np.linalg.norm(centres - target, axis=1)
    return Observations(P=P, pixel=pix, platform_m=centres, range_m=rng, truth_m=target)


def test_look_at_projects_target_to_principal_point():
    obs = _problem()
    np.testing.assert_allclose(obs.pixel, np.tile([300.0, 200.0], (obs.n, 1)), atol=1e-9)


def test_json_round_trip(tmp_path):
    obs = _problem()
    d = observation_file.to_dict(obs)
    d["observations"][1]["pixel"] = None
    d["observations"][2]["range_m"] = None
    path = tmp_path / "obs.json"
    path.write_text(json.dumps(d))
    back = observation_file.load(path)
    assert back.has_pixel.tolist() == [True, False, True, True]
    assert back.has_range.tolist() == [True, True, False, True]
    np.testing.assert_array_equal(back.P, obs.P)


@pytest.mark.parametrize("mutate, match", [
    (lambda d: d["observations"][0].update(P=[[1, 2, 3]]), "must be 3x4"),
    (lambda d: d["observations"][0].update(pixel=[1.0]), "pixel must be"),
    (lambda d: d["observations"][0].update(range_m=-5.0), "positive"),
    (lambda d: d["observations"][0].update(platform_m=[1.0, 2.0]), "platform_m must be"),
    (lambda d: d["observations"][0].update(bogus=1), "unknown key"),
    (lambda d: d.update(sigma={"pixel": 1}), "unknown key"),
    (lambda d: d.update(observations=[]), "non-empty"),
])
def test_bad_json_gets_clear_error(tmp_path, mutate, match):
    d = observation_file.to_dict(_problem())
    mutate(d)
    path = tmp_path / "bad.json"
    path.write_text(json.dumps(d))
    with pytest.raises(ObservationError, match=match) as info:
        observation_file.load(path)
    assert str(path) in str(info.value)


def test_not_json_and_missing_file(tmp_path):
    bad = tmp_path / "x.json"
    bad.write_text("{not json")
    with pytest.raises(ObservationError, match="not valid JSON"):
        observation_file.load(bad)
    with pytest.raises(ObservationError, match="file not found"):
        observation_file.load(tmp_path / "nope.json")


def test_non_finite_and_mismatched_lengths():
    obs = _problem()
    with pytest.raises(ObservationError, match="infinite"):
        Observations(P=obs.P, pixel=obs.pixel, platform_m=obs.platform_m, range_m=np.r_[np.inf, obs.range_m[1:]])
    with pytest.raises(ObservationError, match="mismatched"):
        Observations(P=obs.P, pixel=obs.pixel[:2], platform_m=obs.platform_m, range_m=obs.range_m)
    with pytest.raises(ObservationError, match="NaN"):
        Observations(P=obs.P, pixel=obs.pixel, platform_m=obs.platform_m * np.nan, range_m=obs.range_m)


def test_batch_stack_and_unstack():
    a, b = _problem(), _problem()
    batch = ObservationBatch.stack([a, b])
    assert batch.size == 2 and batch.n == a.n
    np.testing.assert_array_equal(batch.problem(1).pixel, b.pixel)
