"""Observations at key frames (pipeline/sync/key_frames.py, select.py): the range interpolated at a key frame's
time against the closed form of a straight fly-by, its stated error against the true one, and when the planner
observes at key frames."""

import numpy as np
import pytest

from pipeline.errors import ConfigError, InputError
from pipeline.flight_config import ObservationSelection, load_flight_config
from pipeline.ingest.model import FrameSeries, RangeSeries
from pipeline.sync.key_frames import frames_to_decode, interpolate_ranges, key_frame_observations, range_curvature
from pipeline.sync.select import plan_observations

NS = 1_000_000_000
T0 = 1_700_000_000 * NS


def flyby(t_s, v=30.0, miss_m=300.0, t_closest_s=30.0):
    """Range (m) and its second derivative (m/s^2) of a platform flying a straight line at v m/s past a point,
    miss_m at its closest: r = sqrt(miss^2 + (v (t - tc))^2), r'' = v^2 miss^2 / r^3."""
    r = np.hypot(miss_m, v * (np.asarray(t_s) - t_closest_s))
    return r, v * v * miss_m * miss_m / r ** 3


def video(seconds, fps=30, gop=30, first_key=0):
    """Frame times (ns, telemetry clock) and key-frame flags: a key frame every `gop` frames from `first_key`."""
    k = np.arange(seconds * fps)
    return T0 + k * NS // fps, (k - first_key) % gop == 0


def shots(t_s, range_m, valid=None):
    return RangeSeries(t_ns=(T0 + np.round(np.asarray(t_s) * NS)).astype(np.int64), range_m=np.asarray(range_m),
                       valid=np.ones(len(t_s), bool) if valid is None else np.asarray(valid))


def test_interpolated_range_and_its_stated_error_match_the_closed_form_of_a_fly_by():
    t_shot = np.arange(0.0, 61.0)  # one shot a second, noise-free
    r_shot, _ = flyby(t_shot)
    t_frames, key = video(61, first_key=15)  # key frames half-way between the shots
    kp = key_frame_observations(t_frames, key, (T0 + t_shot * NS).astype(np.int64), np.ones(61, bool), r_shot,
                                tolerance_ns=NS // 2, max_gap_ns=3 * NS // 2)
    # the last shot's key frame, half a second after it, has no shot after it: observed without a range
    assert kp.frame_pos.size == 61 and np.isfinite(kp.range_m[:-1]).all() and np.isnan(kp.range_m[-1])
    t_key = (t_frames[kp.frame_pos[:-1]] - T0) / NS
    np.testing.assert_allclose(t_key, t_shot[:-1] + 0.5)
    truth, curvature = flyby(t_key)
    error = kp.range_m[:-1] - truth
    # linear interpolation of a convex curve overshoots by r'' h^2 / 8 to second order (h = 1 s)
    assert (error > 0).all()
    np.testing.assert_allclose(error, curvature / 8, rtol=0.08)
    assert error.max() == pytest.approx(30.0 ** 2 / 300.0 / 8, rel=0.02)  # 0.375 m at the closest point
    # the stated error, from the shots' own curvature (a quadratic over 7 shots), is the true one within 10 %, and
    # within 30 % at the ends, where the fits' windows are one-sided
    ratio = kp.range_error_m[:-1] / np.abs(error)
    assert (np.abs(ratio[2:-2] - 1) < 0.10).all() and (np.abs(ratio - 1) < 0.30).all(), ratio


def test_curvature_of_noisy_shots_and_their_scatter():
    rng = np.random.default_rng(3)
    t = np.arange(0.0, 121.0)
    r, _ = flyby(t, v=35.0, miss_m=2000.0, t_closest_s=60.0)
    noisy = r + rng.normal(0, 1.0, t.size)
    t_ns = (T0 + t * NS).astype(np.int64)
    q = (T0 + (t[5:-5] + 0.5) * NS).astype(np.int64)
    c, rms = range_curvature(t_ns, noisy, q)
    _, truth = flyby(t[5:-5] + 0.5, v=35.0, miss_m=2000.0, t_closest_s=60.0)
    # 7 shots a second apart: the curvature's noise is sqrt(4 / 84) sigma = 0.22 m/s^2
    assert np.std(c - truth) == pytest.approx(0.22, rel=0.25)
    assert np.median(rms) == pytest.approx(1.0, rel=0.15)
    assert np.isnan(range_curvature(t_ns[:4], noisy[:4], q[:2])[0]).all()


def test_interpolation_takes_a_shot_at_the_time_itself_and_refuses_wide_gaps():
    t = np.array([0, 10, 30], dtype=np.int64) * NS
    r, before, after = interpolate_ranges(t, np.array([100.0, 110.0, 150.0]),
                                          np.array([-1, 0, 5 * NS, 10 * NS, 20 * NS, 31 * NS]), 15 * NS)
    np.testing.assert_allclose(r, [np.nan, 100.0, 105.0, 110.0, np.nan, np.nan])
    np.testing.assert_allclose(before[1:4], [0.0, 5.0, 0.0])
    np.testing.assert_allclose(after[1:4], [0.0, 5.0, 0.0])


def test_frames_to_decode_counts_each_group_of_pictures_once():
    key = np.zeros(90, bool)
    key[[0, 30, 60]] = True
    assert frames_to_decode([15], key) == 16
    assert frames_to_decode([15, 20, 45], key) == 21 + 16
    assert frames_to_decode([0, 30, 60], key) == 3
    assert frames_to_decode([], key) == 0


def _plan(seconds, gop, r_shot, t_shot, valid=None, **kw):
    t_frames, key = video(seconds, gop=gop)
    frames = FrameSeries(t_ns=t_frames, index=np.arange(t_frames.size))
    return plan_observations(frames, shots(t_shot, r_shot, valid), keyframe=key, **kw)


def test_auto_observes_at_key_frames_where_they_come_as_often_as_the_shots_and_the_range_is_smooth():
    rng = np.random.default_rng(1)
    t_shot = np.arange(60) + 0.5  # the laser fires mid-GOP, a key frame each second
    r = flyby(t_shot, v=35.0, miss_m=5000.0)[0] + rng.normal(0, 1.0, 60)
    plan = _plan(60, 30, r, t_shot)
    assert plan.at_key_frames and plan.n == 59  # the first shot's key frame has no shot before it
    assert (plan.frame_index % 30 == 0).all() and np.isfinite(plan.range_m).all()
    assert np.nanpercentile(plan.range_error_m, 90) < 0.1  # r'' = 0.25 m/s^2: 0.03 m, plus the estimate's noise
    assert "observations at key frames (auto): 59 of 60 laser shots" in plan.notes[0]
    assert "59 frames to decode instead of 960" in plan.notes[0]
    np.testing.assert_array_equal(plan.range_t_ns, plan.t_ns)  # each range stands at its frame's time
    exact = _plan(60, 30, r, t_shot, at_key_frames=False)
    assert not exact.at_key_frames and exact.n == 60 and exact.range_error_m is None
    assert (exact.frame_index % 30 == 15).all()


def test_auto_keeps_the_shots_own_frames_and_says_why():
    rng = np.random.default_rng(2)
    t_shot = np.arange(60) + 0.5
    r = flyby(t_shot, v=35.0, miss_m=5000.0)[0] + rng.normal(0, 1.0, 60)
    sparse = _plan(60, 60, r, t_shot)  # a key frame every 2 s: half the shots would lose their observation
    assert not sparse.at_key_frames and sparse.n == 60
    assert "but only 30 of the 60 shots have a key frame of their own within 0.5 s" in sparse.notes[-1]
    # a close fly-by measured to 5 cm: 0.37 m of interpolation error is not small against the range's noise
    r_close = flyby(t_shot, v=30.0, miss_m=300.0)[0] + rng.normal(0, 0.05, 60)
    close = _plan(60, 30, r_close, t_shot)
    assert not close.at_key_frames and "the range is not smooth enough" in close.notes[-1]
    forced = _plan(60, 30, r_close, t_shot, at_key_frames=True)  # as asked, with the error stated
    assert forced.at_key_frames and "observations.at_key_frames" in forced.notes[0]
    assert np.nanmax(forced.range_error_m) == pytest.approx(0.375, rel=0.1)
    # every frame a key frame: nothing to save, nothing said
    t_frames, _ = video(60)
    every = plan_observations(FrameSeries(t_ns=t_frames, index=np.arange(t_frames.size)), shots(t_shot, r),
                              keyframe=np.ones(t_frames.size, bool))
    assert not every.at_key_frames and not every.notes
    # invalid shots count as observations in both plans; a gap of two seconds is not interpolated across
    valid = np.ones(60, bool)
    valid[[20, 40]] = False
    gaps = _plan(60, 30, r, t_shot, valid, at_key_frames=True, range_interpolation_gap_s=1.5)
    assert gaps.n == 59 and int(np.isnan(gaps.range_m).sum()) == 4


def test_forced_key_frames_without_any_within_tolerance_is_an_input_error():
    t_shot = np.arange(10) + 0.5
    with pytest.raises(InputError, match=r"no laser shot has a key frame within 0\.2 s"):
        _plan(10, 30, np.full(10, 1000.0), t_shot, at_key_frames=True, key_frame_tolerance_s=0.2)


def test_config_switch(tmp_path):
    assert ObservationSelection().at_key_frames == "auto"
    for name in ("a.tlog", "v.mp4"):
        (tmp_path / name).write_bytes(b"x")
    p = tmp_path / "f.yaml"
    p.write_text("name: f\nfiles: {telemetry: [a.tlog], video: v.mp4}\ntarget: {frame_index: 0, pixel: [1, 2]}\n"
                 "observations: {at_key_frames: true, key_frame_tolerance_s: 0.25}\n")
    sel = load_flight_config(p).observations
    assert sel.at_key_frames is True and sel.key_frame_tolerance_s == 0.25
    p.write_text(p.read_text().replace("at_key_frames: true", "at_key_frames: sometimes"))
    with pytest.raises(ConfigError, match="at_key_frames"):
        load_flight_config(p)
