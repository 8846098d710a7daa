"""Flight.poses: every target of a flight asks for the same observation times; the poses are computed once per
time and given again row for row, equal to a fresh computation (sample flight three_targets). The flight's
truth file is read once for all its targets too."""

from pathlib import Path

import numpy as np

from pipeline.flight import Flight
from pipeline.flight_config import load_flight_config

CONFIG = Path(__file__).resolve().parents[1] / "configs" / "flights" / "three_targets.yaml"
FIELDS = ("R_enu0_from_optical", "camera_m", "laser_m", "antenna_m")


def _fresh(config, t_ns):
    with Flight.open(config) as f:
        return f.poses(t_ns)


def test_poses_asked_again_are_the_first_answer_and_new_times_are_computed():
    config = load_flight_config(CONFIG)
    with Flight.open(config) as flight:
        t = flight.require_plan().t_ns
        span = flight.telemetry_span_ns()
        outside = np.array([span[0] - 10**9, span[1] + 10**9], dtype=np.int64)
        first, inside = flight.poses(np.r_[outside[:1], t])  # a time outside first: no pose, a row of inside
        assert not inside[0] and inside[1:].all()
        again, _ = flight.poses(t)
        picked = t[[5, 1, 1, 9]]  # any order, repeated times
        sub, sub_inside = flight.poses(picked)
        calls = []
        real_states = flight.states
        flight.states = lambda *a, **k: calls.append(a) or real_states(*a, **k)
        mixed = np.r_[t[:3] + 123_456_789, outside, t[4:6]]  # new times, outside ones and remembered ones
        got, got_inside = flight.poses(mixed)
        flight.poses(mixed)  # all remembered now
        none, none_inside = flight.poses(outside)
    assert len(calls) == 1  # only the call with new times interpolated the telemetry
    for name in FIELDS:
        np.testing.assert_array_equal(getattr(again, name), getattr(first, name))
        np.testing.assert_array_equal(getattr(sub, name), getattr(first, name)[[5, 1, 1, 9]])
    ref, ref_inside = _fresh(config, mixed)
    np.testing.assert_array_equal(got_inside, ref_inside)
    np.testing.assert_array_equal(got_inside, [True] * 3 + [False] * 2 + [True] * 2)
    for name in FIELDS:
        np.testing.assert_array_equal(getattr(got, name), getattr(ref, name))
    assert sub_inside.all() and none is None and not none_inside.any()


def test_a_flight_with_three_targets_interpolates_its_telemetry_and_reads_its_truth_once(monkeypatch):
    from pipeline import target_stage
    from pipeline.run import process_group

    calls, truth_reads = [], []
    real, real_truth = Flight.states, target_stage.truth_file_targets
    monkeypatch.setattr(Flight, "states", lambda self, t, log=None: calls.append(len(t)) or real(self, t, log))
    monkeypatch.setattr(target_stage, "truth_file_targets", lambda c: truth_reads.append(c) or real_truth(c))
    result = process_group(load_flight_config(CONFIG))
    assert len(result.targets) == 3 and not result.failed
    assert calls == [len(result.targets[0].tracking["t_ns"])]  # the observation times, once for every target
    assert len(truth_reads) == 1 and all(r.truth_m is not None for r in result.targets)
