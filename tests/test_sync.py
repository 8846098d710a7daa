import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from pipeline.errors import ConfigError, InputError
from pipeline.geometry.camera import intrinsics_matrix, project
from pipeline.geometry.frames import enu_from_lla
from pipeline.geometry.pose import frame_poses
from pipeline.ingest.model import AttitudeSeries, FlightLog, FrameSeries, GimbalSeries, PositionSeries, RangeSeries
from pipeline.sync import assemble_observations, frame_states, interpolate_linear, interpolate_rotations, nearest_within
from pipeline.sync.select import plan_observations

T0 = 1_700_000_000_000_000_000  # UNIX ns: large, to catch float precision loss


def _wxyz(rot):
    q = rot.as_quat()
    return np.c_[q[:, 3], q[:, :3]]


def test_linear_interpolation_keeps_ns_precision_and_never_extrapolates():
    t = T0 + np.array([0, 1_000_000_000, 2_000_000_000], dtype=np.int64)
    v = np.array([[0.0, 10.0], [1.0, 20.0], [3.0, 40.0]])
    q = T0 + np.array([-1, 250_000_000, 1_500_000_000, 1_999_999_999, 2_000_000_001], dtype=np.int64)
    out, inside = interpolate_linear(t, v, q)
    np.testing.assert_array_equal(inside, [False, True, True, True, False])
    np.testing.assert_allclose(out[1:4], [[0.25, 12.5], [2.0, 30.0], [3.0 - 2e-9, 40.0 - 2e-8]], rtol=0, atol=1e-12)
    assert np.isnan(out[[0, 4]]).all()


def test_slerp_halfway_between_two_yaws():
    t = T0 + np.array([0, 2_000_000_000], dtype=np.int64)
    rots = Rotation.from_euler("z", [[10.0], [50.0]], degrees=True)
    q, inside = interpolate_rotations(t, _wxyz(rots), T0 + np.array([1_000_000_000, 500_000_000]))
    assert inside.all()
    yaw = Rotation.from_quat(q[:, [1, 2, 3, 0]]).as_euler("ZYX", degrees=True)[:, 0]
    np.testing.assert_allclose(yaw, [30.0, 20.0], atol=1e-9)


def test_nearest_within_tolerance():
    src = np.array([0, 100, 200, 300], dtype=np.int64)
    np.testing.assert_array_equal(nearest_within(src, np.array([-5, 49, 51, 190, 330, 360]), 55),
                                  [0, 0, 1, 2, 3, -1])
    np.testing.assert_array_equal(nearest_within(src[:0], np.array([1]), 30), [-1])


def _frames(t_video_ns):
    return FrameSeries(t_ns=np.asarray(t_video_ns, dtype=np.int64), index=np.arange(len(t_video_ns)))


def test_plan_range_times_nearest_frame_with_clock_offsets():
    # 25 Hz bursts of 3 frames around each second; video clock = telemetry - 5 s; laser clock 30 ms late
    video_offset = 5_000_000_000
    burst = np.array([-40, 0, 40]) * 1_000_000
    t_video = np.concatenate([T0 - video_offset + k * 1_000_000_000 + burst for k in range(4)])
    shots_tel = T0 + np.arange(5) * 1_000_000_000 + 7_000_000  # 7 ms after a frame; the last has no frame
    ranges = RangeSeries(t_ns=(shots_tel + 30_000_000).astype(np.int64), range_m=np.array([100.0, -1, 120, 130, 140]),
                         valid=np.array([True, True, False, True, True]))
    plan = plan_observations(_frames(t_video), ranges, video_offset_ns=video_offset, range_offset_ns=-30_000_000,
                             frame_tolerance_s=0.015)
    np.testing.assert_array_equal(plan.frame_index, [1, 4, 7, 10])
    np.testing.assert_array_equal(plan.t_ns, T0 + np.arange(4) * 1_000_000_000)
    # negative and flagged-invalid ranges are never used, but the frame stays an observation
    np.testing.assert_array_equal(np.isnan(plan.range_m), [False, True, True, False])
    assert plan.range_m[0] == 100.0 and plan.range_m[3] == 130.0
    assert any("no video frame" in n for n in plan.notes)


def test_plan_frames_mode_attaches_nearest_valid_range():
    t_video = T0 + np.arange(10) * 40_000_000
    ranges = RangeSeries(t_ns=T0 + np.array([5_000_000, 200_000_000]), range_m=np.array([50.0, 60.0]),
                         valid=np.array([True, True]))
    plan = plan_observations(_frames(t_video), ranges, mode="frames", frame_indices=[0, 5, 9], max_range_gap_s=0.03)
    np.testing.assert_array_equal(plan.frame_index, [0, 5, 9])
    np.testing.assert_allclose(plan.range_m, [50.0, 60.0, np.nan])
    with pytest.raises(InputError, match="not in the video"):
        plan_observations(_frames(t_video), ranges, mode="frames", frame_indices=[42])
    with pytest.raises(InputError, match="no observation frames"):
        plan_observations(_frames(t_video + 10**12), ranges)


def _log(alt_datum="ellipsoid"):
    t = T0 + np.arange(0, 11) * 1_000_000_000
    lat = 30.0 + np.linspace(0, 0.01, 11)
    body = Rotation.from_euler("ZYX", np.c_[np.linspace(0, 20, 11), np.zeros(11), np.zeros(11)], degrees=True)
    gim = Rotation.from_euler("ZYX", np.c_[np.zeros(11), np.full(11, -60.0), np.zeros(11)], degrees=True)
    return FlightLog(path="mem", position=PositionSeries(t, lat, np.full(11, 114.0), np.full(11, 2000.0), alt_datum),
                     attitude=AttitudeSeries(t, _wxyz(body)),
                     gimbal=GimbalSeries(t, _wxyz(gim), np.ones(11, dtype=bool)))


def test_frame_states_interpolate_and_flag_outside():
    log = _log()
    q = T0 + np.array([2_500_000_000, 20_000_000_000])
    s = frame_states(log, q)
    np.testing.assert_array_equal(s.inside, [True, False])
    np.testing.assert_allclose(s.lat_deg[0], 30.0025, atol=1e-12)
    yaw = Rotation.from_quat(s.body_quat_wxyz[:1, [1, 2, 3, 0]]).as_euler("ZYX", degrees=True)[0, 0]
    assert yaw == pytest.approx(5.0)
    assert s.yaw_in_vehicle_frame[0]
    with pytest.raises(ConfigError, match="geoid_separation_m"):
        frame_states(_log("amsl"), q)
    s2 = frame_states(_log("amsl"), q, geoid_separation_m=-20.0)
    assert s2.alt_m[0] == pytest.approx(1980.0)


def test_assembled_observation_projects_the_true_target_with_lens_and_lever_arms():
    log = _log()
    origin = (30.0, 114.0, 0.0)
    K = intrinsics_matrix(1200.0, 1200.0, 300.0, 200.0)
    s = frame_states(log, T0 + np.array([1_000_000_000, 4_200_000_000, 9_000_000_000]))
    # A ground point: project it through an independently built camera for frame 0 is what the geometry tests
    # cover; here check that assembly keeps the pixel/range pairing and undistortion consistent with P.
    dist = [-0.1, 0.02, 0.0, 0.0, 0.0]
    target = enu_from_lla(30.02, 114.0, 0.0, origin)
    poses = frame_poses(s.lat_deg, s.lon_deg, s.alt_m, s.body_quat_wxyz, s.gimbal_quat_wxyz, s.yaw_in_vehicle_frame,
                        origin, R_optical_from_gimbal=np.array([[0, 1, 0], [0, 0, 1], [1, 0, 0.0]]),
                        lever_camera_m=[0.5, 0, 0.2], lever_rangefinder_m=[0.5, 0.1, 0.2])
    obs0 = assemble_observations(poses, s.t_ns, np.zeros((3, 2)), np.full(3, np.nan), K=K, dist=dist)
    ideal = project(obs0.P, np.broadcast_to(target, (3, 3)))
    from pipeline.geometry.lens import distort_pixels
    seen = distort_pixels(ideal, K, dist)
    rng = np.array([np.nan, 2500.0, 2600.0])
    obs = assemble_observations(poses, s.t_ns, seen, rng, K=K, dist=dist, truth_m=target)
    np.testing.assert_allclose(obs.pixel, ideal, atol=1e-6)
    np.testing.assert_array_equal(obs.has_range, [False, True, True])
    # the laser origin sits 0.1 m to the right of the camera, the camera 0.5 m ahead of the antenna
    np.testing.assert_allclose(np.linalg.norm(poses.laser_m - poses.camera_m, axis=1), 0.1, atol=1e-6)
    np.testing.assert_allclose(np.linalg.norm(poses.camera_m - poses.antenna_m, axis=1), np.hypot(0.5, 0.2), atol=1e-6)


def test_plan_bursts_one_observation_per_burst_even_without_a_logged_shot():
    burst = np.array([-80, -40, 0, 40, 80]) * 1_000_000
    centres = T0 + np.array([0, 3, 6]) * 1_000_000_000
    t_video = np.concatenate([c + burst for c in centres])
    # a shot on the 2nd frame of burst 0, none logged for burst 1, an invalid one on burst 2's centre
    ranges = RangeSeries(t_ns=np.array([centres[0] - 40_000_000, centres[2]]), range_m=np.array([900.0, 950.0]),
                         valid=np.array([True, False]))
    plan = plan_observations(_frames(t_video), ranges, mode="bursts", frame_tolerance_s=0.01,
                             max_range_gap_s=0.05)
    np.testing.assert_array_equal(plan.frame_index, [1, 7, 12])
    np.testing.assert_allclose(plan.range_m, [900.0, np.nan, np.nan])


def test_plan_bursts_warns_when_the_clock_puts_every_shot_outside_its_burst():
    """Bursts are recorded around the 1 Hz laser shots that trigger them. A video_start a few seconds off (written
    to the minute, say) moves every burst between two shots: the plan keeps its observations but loses all ranges,
    and must say why rather than let the run answer from vision alone in silence."""
    burst = np.array([-80, -40, 0, 40, 80]) * 1_000_000
    centres = T0 + np.arange(6) * 3 * 1_000_000_000
    shots = T0 + np.arange(-2, 20) * 1_000_000_000  # 1 Hz, every shot valid
    ranges = RangeSeries(t_ns=shots, range_m=np.full(shots.size, 900.0), valid=np.ones(shots.size, bool))
    t_video = np.concatenate([c + burst for c in centres]) - T0  # the video clock starts at T0
    right = plan_observations(_frames(t_video), ranges, mode="bursts", video_offset_ns=T0)
    assert np.isfinite(right.range_m).all() and right.warnings == []
    off = plan_observations(_frames(t_video), ranges, mode="bursts", video_offset_ns=T0 - 2_316_000_000)
    assert off.n == 6 and not np.isfinite(off.range_m).any()
    assert len(off.warnings) == 1 and "only 0 of 6 bursts" in off.warnings[0]
    assert "clock.video_start" in off.warnings[0]


def test_the_bursts_check_takes_no_bursts_quietly():
    import numpy as np

    from pipeline.sync.select import _bursts_without_shots

    assert _bursts_without_shots(np.array([], dtype=np.int64), np.array([1, 2], dtype=np.int64), 0, 0.1) == []
