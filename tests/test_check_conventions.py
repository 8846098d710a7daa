"""`ridgeloc check` and `ridgeloc run` on flights written in other vehicles' conventions
(pipeline/synth/conventions.py): every mistake is named with the config lines that fix it, and run refuses the
flight with a one-line reason; the right configs pass and locate the target. Plus the pieces: orientation frames,
clock keys, the clusters."""

import csv
import datetime
import json
import math
import re
from pathlib import Path

import numpy as np
import pytest

from pipeline.check.geometry import cluster, meet_undetermined_warning, range_bias_problem
from pipeline.check.report import check_flight, format_check
from pipeline.cli import main as cli_main
from pipeline.errors import InputError
from pipeline.flight_config import Clock, load_flight_config
from pipeline.ingest.frames import (
    ORIENTATION_FRAMES,
    euler_zyx_from_quat_wxyz,
    quat_ned_frd_from_enu_flu,
    quat_ned_frd_from_frame,
    quat_ned_from_frd_euler,
    rotation_from_quat_wxyz,
)
from pipeline.run import process_group
from pipeline.synth.conventions import CASES, case_config, write_flights

# the tiny flights' noise (attitude and gimbal 0.02 deg, GNSS 0.3 m, laser 1 m) bounds the error as in
# tests/test_run_e2e.py: 4 sigma_3d = 15.4 m
BOUND_M = 15.4


@pytest.fixture(scope="session")
def flights(tmp_path_factory):
    return write_flights(tmp_path_factory.mktemp("conventions"))


@pytest.mark.parametrize("case", CASES, ids=[c.name for c in CASES])
def test_check_names_the_fix_and_run_refuses(flights, case):
    cfg = load_flight_config(case_config(flights[case.flight], case))
    res = check_flight(cfg, clock=False)
    text = format_check(res)
    if case.expect is None:
        assert res.problems == [], text
        r = process_group(cfg)
        assert r.errors_m()["mle"] < BOUND_M
        return
    assert any(case.expect in p for p in res.problems), text
    if case.refused:
        with pytest.raises(InputError) as exc:
            process_group(cfg)
        message = str(exc.value)
        assert "\n" not in message and case.expect in message, message


def test_check_command_exit_status(flights, capsys):
    wrong = next(c for c in CASES if c.name == "ros_frd_default")
    right = next(c for c in CASES if c.name == "tlog_right")
    assert cli_main(["check", "--no-clock", str(case_config(flights[wrong.flight], wrong))]) == 1
    out = capsys.readouterr().out
    assert "frame: frd_ned" in out and "gimbal" in out and "intrinsics" in out and "overlap" in out
    assert cli_main(["check", str(case_config(flights[right.flight], right))]) == 0
    assert "consistent" in capsys.readouterr().out.splitlines()[-1]


def test_inspect_takes_a_flight_config(flights, capsys):
    case = next(c for c in CASES if c.name == "ros_optical_no_camera")
    assert cli_main(["inspect", str(case_config(flights[case.flight], case))]) == 0
    out = capsys.readouterr().out
    assert "read as optical_enu" in out and "CameraInfo" in out and "geometry" not in out


def test_inspect_gives_the_first_frames_time(capsys):
    """The frames line names the first frame's UTC time: the video offset plus the first frame's time on the video
    clock (group1's frames CSV starts 5.56 s after the video clock's zero), the first time of the span line."""
    config = Path(__file__).resolve().parents[1] / "configs" / "flights" / "group1.yaml"
    cfg = load_flight_config(config)
    with open(cfg.files.frames_csv, newline="") as f:
        first_pts_ns = int(next(csv.DictReader(f))["pts_ns"])
    assert first_pts_ns > 0  # the frames do not start at the video clock's zero
    first = (datetime.datetime(1970, 1, 1, tzinfo=datetime.timezone.utc)
             + datetime.timedelta(microseconds=(cfg.clock.offset_ns("video") + first_pts_ns) // 1000))
    utc = first.isoformat(timespec="milliseconds").replace("+00:00", "Z")
    assert cli_main(["inspect", str(config)]) == 0
    lines = capsys.readouterr().out.splitlines()
    i = next(i for i, line in enumerate(lines) if line.strip().startswith("frames "))
    assert lines[i].endswith(f"(first frame at {utc})"), lines[i]
    assert lines[i + 1].split() == ["span", utc, "..", lines[i + 1].split()[-1]]


def test_a_batch_goes_on_past_a_refused_flight(flights, tmp_path, capsys):
    bad = case_config(flights["ros_frd_ned"], next(c for c in CASES if c.name == "ros_frd_default"))
    good = case_config(flights["tlog"], next(c for c in CASES if c.name == "tlog_right"))
    (tmp_path / "run.yaml").write_text(f"groups: [{bad}, {good}]\n")
    assert cli_main(["run", str(tmp_path / "run.yaml"), "-o", str(tmp_path / "out"), "-q", "--no-figures"]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "ros_frd_default" in err[0] and "frame: frd_ned" in err[0]
    assert (tmp_path / "out" / "tlog_right").is_dir() and not (tmp_path / "out" / "ros_frd_default").exists()


# ---- the pieces ------------------------------------------------------------------------------------------------


# A gimbal looking east and 30 deg below the horizon (ZYX yaw 90 deg, pitch -30 deg, roll 0), by hand. With
# c = cos 30 = sqrt(3)/2 and s = sin 30 = 1/2 its FRD axes in NED (north, east, down):
#   forward f = (0, c, s)   (east, tilted down);   right r = (-1, 0, 0)   (south);
#   down    d = f x r = (0, -s, c)   (tilted back, west).
# An orientation `<body>_<world>` rotates body axes into world axes: its matrix's columns are the body axes in
# world coordinates. FLU = (f, -r, -d); REP-103 optical = (r, d, f); ENU coordinates of a NED vector
# (n, e, d) are (e, n, -d).
C, S = math.sqrt(3) / 2, 0.5
R_NED_FROM_FRD = np.array([[0.0, -1, 0], [C, 0, -S], [S, 0, C]])
HAND = {  # frame -> R_world_from_body, columns written from the axes above
    "frd_ned": [[0.0, -1, 0], [C, 0, -S], [S, 0, C]],  # f, r, d
    "frd_enu": [[C, 0, -S], [0, -1, 0], [-S, 0, -C]],  # f = (c, 0, -s), r = (0, -1, 0), d = (-s, 0, -c)
    "flu_ned": [[0.0, 1, 0], [C, 0, S], [S, 0, -C]],  # f, -r = (1, 0, 0), -d = (0, s, -c)
    "flu_enu": [[C, 0, S], [0, 1, 0], [-S, 0, C]],  # f, -r = (0, 1, 0), -d = (s, 0, c)
    "optical_ned": [[-1.0, 0, 0], [0, -S, C], [0, C, S]],  # r, d, f
    "optical_enu": [[0.0, -S, C], [-1, 0, 0], [0, -C, -S]],  # r, d, f in ENU
}
# The same FRD -> NED rotation as a quaternion, by hand: q_yaw(90) * q_pitch(-30) with q_yaw = (cos 45, 0, 0,
# sin 45), q_pitch = (cos 15, 0, -sin 15, 0); their product (w1 w2, -z1 y2, w1 y2, w2 z1) is
# sqrt(1/2) (cos 15, sin 15, -sin 15, cos 15).
Q_NED_FROM_FRD = math.sqrt(0.5) * np.array([math.cos(math.radians(15)), math.sin(math.radians(15)),
                                            -math.sin(math.radians(15)), math.cos(math.radians(15))])


def test_hand_written_rotations_are_rotations():
    for frame, R in HAND.items():
        R = np.array(R)
        np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-12, err_msg=frame)
        assert np.linalg.det(R) == pytest.approx(1.0), frame


def test_euler_and_quaternion_conventions_known_values():
    q = quat_ned_from_frd_euler(0.0, math.radians(-30), math.radians(90))
    np.testing.assert_allclose(q[0], Q_NED_FROM_FRD, atol=1e-12)
    np.testing.assert_allclose(rotation_from_quat_wxyz(Q_NED_FROM_FRD).as_matrix()[0], R_NED_FROM_FRD, atol=1e-12)
    # a pure yaw of 90 deg: forward -> east, right -> south
    np.testing.assert_allclose(quat_ned_from_frd_euler(0.0, 0.0, math.pi / 2)[0],
                               [math.sqrt(0.5), 0, 0, math.sqrt(0.5)], atol=1e-12)
    np.testing.assert_allclose(euler_zyx_from_quat_wxyz(Q_NED_FROM_FRD[None])[0],
                               [0.0, math.radians(-30), math.radians(90)], atol=1e-12)


@pytest.mark.parametrize("frame", ORIENTATION_FRAMES)
def test_every_ros_frame_is_read_as_the_hand_computed_rotation(frame):
    from scipy.spatial.transform import Rotation  # the library turns the hand matrix into the file's numbers

    q_file = Rotation.from_matrix(HAND[frame]).as_quat(scalar_first=True)[None]
    got = rotation_from_quat_wxyz(quat_ned_frd_from_frame(q_file, frame)).as_matrix()[0]
    np.testing.assert_allclose(got, R_NED_FROM_FRD, atol=1e-12)
    if frame == "flu_enu":  # REP-103, also read by the dedicated function
        got = rotation_from_quat_wxyz(quat_ned_frd_from_enu_flu(q_file)).as_matrix()[0]
        np.testing.assert_allclose(got, R_NED_FROM_FRD, atol=1e-12)


@pytest.mark.parametrize("frame", ORIENTATION_FRAMES)
def test_the_synthetic_bag_writer_writes_the_hand_computed_rotation(frame):
    from scipy.spatial.transform import Rotation

    from pipeline.synth.writers.rosbag import frame_quat_xyzw

    q_xyzw = frame_quat_xyzw(Q_NED_FROM_FRD[None], frame)
    np.testing.assert_allclose(Rotation.from_quat(q_xyzw).as_matrix()[0], HAND[frame], atol=1e-12)


def test_gimbal_yaw_relative_to_the_vehicle_known_values():
    from pipeline.ingest.frames import gimbal_to_earth
    from pipeline.ingest.model import AttitudeSeries, GimbalSeries

    # the vehicle heads east (yaw 90 deg); the gimbal, relative to the vehicle heading, pitches 30 deg down:
    # on the earth that is the hand-computed pose above
    t = np.array([0, 1_000_000_000], dtype=np.int64)
    vehicle = AttitudeSeries(t, np.tile([math.sqrt(0.5), 0, 0, math.sqrt(0.5)], (2, 1)))
    pitch = [math.cos(math.radians(15)), 0.0, -math.sin(math.radians(15)), 0.0]
    gimbal = GimbalSeries(t, np.tile(pitch, (2, 1)), np.array([True, True]))
    np.testing.assert_allclose(gimbal_to_earth(gimbal, vehicle).quat_wxyz, np.tile(Q_NED_FROM_FRD, (2, 1)),
                               atol=1e-12)


def test_clock_keys_in_human_units():
    iso = Clock(video_start="2024-05-14T02:30:02.316Z", video_latency_s=0.12, range_offset_s=-0.03)
    unix = Clock(video_start=1715653802.316)
    dt = Clock(video_start=datetime.datetime(2024, 5, 14, 2, 30, 2, 316000, tzinfo=datetime.timezone.utc))
    assert unix.offset_ns("video") == dt.offset_ns("video") == 1_715_653_802_316_000_000
    assert iso.offset_ns("video") == 1_715_653_802_316_000_000 - 120_000_000
    assert iso.offset_ns("range") == -30_000_000 and iso.offset_ns("gimbal") == 0
    assert Clock(video_offset_s=2.5, gimbal_latency_s=0.04).offset_ns("gimbal") == -40_000_000
    with pytest.raises(ValueError, match="give one of"):
        Clock(video_to_telemetry_offset_ns=5, video_start=1.0)


def test_cluster_sizes_and_range_bias():
    rng = np.random.default_rng(5)
    target = np.array([0.0, 0.0, 0.0])
    a = np.radians(np.linspace(200, 250, 12))
    origins = np.c_[4600 * np.sin(a), 4600 * np.cos(a), np.full(12, 2000.0)]
    d = target - origins
    dist = np.linalg.norm(d, axis=1)
    d = d / dist[:, None] + rng.normal(scale=np.radians(0.1), size=d.shape)  # 0.1 deg pointing noise
    good = cluster(origins, d, dist + rng.normal(scale=2.0, size=12))
    assert good.consistent and good.spread_m < 20 and range_bias_problem(good) is None
    biased = cluster(origins, d, dist + 400.0)
    assert biased.consistent and re.search(r"\b(39\d|40\d) m longer", range_bias_problem(biased))
    assert biased.meet_along_sigma_m < 200 and meet_undetermined_warning(biased) is None  # 45 deg apart: determined
    flipped = cluster(origins, -d, dist)  # rays pointing up and away
    assert flipped.inconsistent and not flipped.ahead
    yawed = cluster(origins, d @ np.array([[0, -1.0, 0], [1, 0, 0], [0, 0, 1]]).T, dist)  # 90 deg yaw off
    assert yawed.inconsistent and math.isfinite(yawed.spread_m)


def test_range_bias_not_flagged_where_nearly_parallel_rays_do_not_fix_the_meeting_point():
    """A 40 m pass at 1.7 km (lines of sight 1-2 deg apart) with a pointing error drifting 0 -> 0.6 deg (as a
    gimbal's does): the rays meet ~500 m beyond the target, far outside their statistical error, but a 1.1 deg
    pointing error moves that point by ~700 m along them: no problem, a warning. Ranges in feet still are one."""
    n = 40
    origins = np.c_[np.linspace(-20, 20, n), np.full(n, -1650.0), np.full(n, 400.0)]
    d = -origins
    dist = np.linalg.norm(d, axis=1)
    d /= dist[:, None]
    a = np.radians(np.linspace(0.0, 0.6, n))  # drift about the vertical
    d = np.c_[np.cos(a) * d[:, 0] - np.sin(a) * d[:, 1], np.sin(a) * d[:, 0] + np.cos(a) * d[:, 1], d[:, 2]]
    c = cluster(origins, d, dist)
    assert c.consistent and c.gamma_deg < 2.5
    # the statistical test alone would call it a range bias
    assert abs(c.range_bias_m) > max(5 * c.range_bias_sigma_m, 0.03 * c.distance_m) and c.range_bias_m > 400
    assert c.meet_undetermined and range_bias_problem(c) is None
    assert re.search(r"nearly parallel .* undetermined along them .* cannot be checked", meet_undetermined_warning(c))
    feet = cluster(origins, d, dist * 3.2808)
    assert not feet.meet_undetermined and re.search(r"km longer than the distance", range_bias_problem(feet))
    assert meet_undetermined_warning(feet) is None


def test_check_and_mark_of_a_log_say_it_is_not_a_config(tmp_path, capsys):
    """A log given as the flight config is named as such; a YAML config named other than .yaml is checked."""
    from pathlib import Path

    log = tmp_path / "flight.tlog"
    log.write_bytes(b"\xfd\x09\x00\x00" * 64)
    for command in (["check"], ["mark", "-o", str(tmp_path / "marks.html")]):
        assert cli_main([*command, str(log)]) == 1
        assert capsys.readouterr().err.splitlines() == [
            f"ridgeloc: error: {log}: a telemetry log, not a flight config: `ridgeloc init {tmp_path}` writes one "
            "from the flight's files, or name it in a flight config's files.telemetry"]
    folder = tmp_path / "flight"  # a folder given for its flight config (was "cannot read: [Errno 21] Is a directory")
    folder.mkdir()
    assert cli_main(["check", str(folder)]) == 1
    assert capsys.readouterr().err.splitlines() == [
        f"ridgeloc: error: {folder}: a folder, not a flight config: `ridgeloc init {folder}` writes one from its "
        "files"]
    assert cli_main(["mark", "-o", str(tmp_path / "marks.html"), str(folder)]) == 1  # mark also takes photo folders
    assert capsys.readouterr().err.splitlines() == [
        f"ridgeloc: error: {folder}: no drone photos (.jpg, .jpeg files) here, and a folder is not a flight config: "
        f"`ridgeloc init {folder}` writes one from a flight's files"]
    (folder / "flight.yaml").write_text("name: x\n")
    assert cli_main(["check", str(folder)]) == 1
    assert capsys.readouterr().err.splitlines() == [
        f"ridgeloc: error: {folder}: a folder, not a flight config: give its flight config, {folder / 'flight.yaml'}"]
    assert not (tmp_path / "marks.html").exists()
    repo = Path(__file__).resolve().parents[1]
    cfg = tmp_path / "group1.cfg"
    cfg.write_text((repo / "configs" / "flights" / "group1.yaml").read_text().replace("../../", f"{repo}/"))
    assert cli_main(["check", "--no-clock", str(cfg)]) == 0  # was "unknown log type (suffix '.cfg', ...)"


def test_the_principal_point_warning_names_a_named_target_as_the_config_gives_it(tmp_path, capsys):
    """A flight whose first target is named (`targets:` or a marks file) is warned about under that name, not as
    `target.pixel`, a key the config does not have."""
    clip = Path(__file__).resolve().parents[1] / ".." / "shared" / "fmv" / "aphill_short.ts"
    if not clip.is_file():
        pytest.skip(f"{clip} absent (the shared read-only material is not beside this checkout)")
    config = tmp_path / "flight.yaml"
    config.write_text(f"name: clip\nfiles: {{telemetry: [{clip.resolve()}]}}\naltitude: {{geoid_separation_m: auto}}\n"
                      "mapping: {klv: {azimuth_north: grid}}\n"
                      "targets: [{name: car, frame_index: 0, pixel: [497, 250]}]\n")
    assert cli_main(["check", str(config), "--no-clock", "--json"]) == 0
    warnings = json.loads(capsys.readouterr().out)["warnings"]
    (far,) = [w for w in warnings if "from the principal point" in w]
    assert far.startswith(f"target 'car' ({config}: targets[0] (car)): pixel [497, 250] is 138 px from the "
                          "principal point"), far


def test_lines_of_sight_40_deg_apart_are_not_called_nearly_parallel():
    """At 5 km a 1.1 deg pointing error moves where rays 40 deg apart meet by about +-150 m: still too much to check
    the ranges against, but the rays are not 'nearly parallel' (a trial read that for 40 deg); 1.3 deg are."""
    import numpy as np

    from pipeline.check.geometry import Cluster, meet_undetermined_warning

    def warning(gamma_deg):
        c = Cluster(n=10, n_ranged=10, metric="laser sphere", spread_m=5.0, centre_m=np.zeros(3), meet_m=np.zeros(3),
                    distance_m=5000.0, ahead=True, range_bias_m=-160.0, range_bias_sigma_m=2.0, gamma_deg=gamma_deg,
                    meet_along_sigma_m=170.0)
        return meet_undetermined_warning(c)

    wide, narrow = warning(40.0), warning(1.3)
    assert "nearly parallel" not in wide and wide.startswith(
        "where the lines of sight meet (first to last 40.0 deg, 5.0 km away) is undetermined along them (+-170 m")
    assert narrow.startswith("the lines of sight are nearly parallel (first to last 1.3 deg): where they meet is")
