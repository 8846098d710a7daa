"""`ridgeloc init FOLDER`: the flight config of a folder of flight files, and what it leaves to the user.

Synthetic flights in every log format (`ridgeloc synth`, written as the vehicles write them) are initialised, the
target's pixel set, and run: the answer must be within the generator's noise bound of the truth, and for a ROS
bag that carries its images, CameraInfo and covariances, within 1 m of the answer of the flight's hand-written
config (`ridgeloc synth`'s flight.yaml: the operator's camera calibration, lever arms and sensor specifications).
Real files: the MISB clips and the DJI SRTs of ../shared.
"""

import json
import math
import shutil
from pathlib import Path

import numpy as np
import pymap3d
import pytest
import yaml

from pipeline.autoconfig import config_text, draft_flight_config
from pipeline.autoconfig.timing import align_bursts, observation_choice
from pipeline.cli import main as cli_main
from pipeline.errors import InputError
from pipeline.flight_config import flight_config_from_dict, load_flight_config
from pipeline.ingest.video_time import creation_time_ns
from pipeline.run import process_group
from pipeline.synth.config import SynthConfig, with_sections
from pipeline.synth.conventions import BASE, FLIGHTS
from pipeline.synth.flight import generate

ROOT = Path(__file__).resolve().parents[1]
SHARED = ROOT.parent / "shared"

# A small flight (6 observations, bursts of 3 frames, a coarse ground texture: a few seconds to write), with the
# encoder-grade noise of tests/test_run_e2e.py; its bound, derived there from that noise: 4 sigma_3d = 15.4 m.
TINY = {"group": "tiny", "seed": 11,
        "observations": {"count": 6, "lead_in_s": 3.0, "lead_out_s": 1.0},
        "path": {"intersection_angle_deg": 50.0, "speed_mps": 120.0},
        "noise": {"gnss_drift_m": 0.25, "gnss_white_m": 0.15, "attitude_deg": 0.02, "gimbal_deg": 0.02,
                  "laser_m": 1.0, "attitude_tau_s": 7.0, "gnss_tau_s": 30.0},
        "video": {"burst_frames": 3, "start_delay_s": 0.5},
        "scene": {"texture_px": 2048, "texture_res_m": 2.0, "supersample": 1}}
BOUND_M = 4 * math.sqrt(2 * (2.47**2 + 0.8**2) + 3 * 0.3**2 + 1.0**2)
# format -> (synth changes, images inside the bag)
FORMATS = {
    "tlog": ({"format": "tlog"}, False),
    "ros1": ({"format": "ros1", "video": {"images_in_bag": True}}, True),
    "ros2-sqlite3": ({"format": "ros2-sqlite3"}, False),
    "ros2-mcap": ({"format": "ros2-mcap", "video": {"images_in_bag": True}}, True),
    "mcap": ({"format": "mcap"}, False),
    "klv": ({"format": "klv", "camera": {"dist": [0.0] * 5},
             "lever_arms_m": {"camera": [0.0] * 3, "rangefinder": [0.0] * 3}}, False),
}



@pytest.fixture(scope="module", params=list(FORMATS))
def initialised(request, tmp_path_factory):
    """(format, flight folder, truth, the init config's path, init's console output) of a tiny flight."""
    fmt = request.param
    root = tmp_path_factory.mktemp(f"init-{fmt}")
    folder = root / fmt
    generate(SynthConfig.from_dict(with_sections(TINY, FORMATS[fmt][0])), folder, write_flight_config=True)
    out = root / "init.yaml"
    assert cli_main(["init", str(folder), "-o", str(out)]) == 0
    return fmt, folder, json.loads((folder / "truth.json").read_text()), out


def _mle_ecef(result) -> np.ndarray:
    return np.array(pymap3d.enu2ecef(*result.estimates["mle"].position_m, *result.origin_lla))


def test_init_then_the_target_then_run(initialised, capsys):
    fmt, folder, truth, out = initialised
    config = load_flight_config(out)  # as written, it loads
    assert config.target is None and config.truth_file is None
    doc = yaml.safe_load(out.read_text())
    text = out.read_text()
    fill = [line for line in text.splitlines() if "FILL IN" in line]
    # what no file states: the target always; the intrinsics where no CameraInfo or field of view gives them
    has_intrinsics = fmt in ("ros1", "ros2-sqlite3", "ros2-mcap", "klv")
    assert any(line.startswith("# target:") for line in fill)
    assert any(line.startswith("# camera:") for line in fill) == (not has_intrinsics)
    assert "clock: {video_start: FILL_IN}" not in text  # the video clock is always found
    if not has_intrinsics:  # the user fills in the camera: the calibration an operator has
        doc["camera"] = {k: truth["camera"][k] for k in ("width_px", "height_px", "fx_px", "fy_px", "cx_px",
                                                        "cy_px", "dist")}
    if "sigma" not in doc:  # and the optional lines from the sensors' specifications, as the hand-written config
        # has them: without them the MLE estimates the accuracies from six observations, and its answer moves with
        # the tracked pixels by metres (the H.264 of the full-motion video is not bit-reproducible)
        doc["sigma"] = {k: v for k, v in yaml.safe_load((folder / "flight.yaml").read_text())["sigma"].items()
                        if k != "pixel_px"}
    doc["target"] = truth["target_mark"]
    doc["truth_file"] = str(folder / "truth.json")
    result = process_group(flight_config_from_dict(doc, out))
    assert result.n_observations == truth["n_observations"] == 6
    assert result.errors_m()["mle"] < BOUND_M, result.errors_m()
    if FORMATS[fmt][1]:  # a bag with its images: the answer of the hand-written config within 1 m
        hand = process_group(load_flight_config(folder / "flight.yaml"))
        assert np.linalg.norm(_mle_ecef(result) - _mle_ecef(hand)) < 1.0


def test_what_init_states_for_each_format(initialised):
    fmt, folder, truth, out = initialised
    doc = yaml.safe_load(out.read_text())
    meta = truth["metadata"]
    assert "mapping" not in doc  # written in the readers' default conventions: none to fix
    assert doc.get("observations") == {"mode": "bursts"}  # a camera triggered in bursts
    if fmt in ("ros1", "ros2-mcap", "klv"):  # frames stamped on the telemetry's clock
        assert "clock" not in doc
    else:  # the mp4's creation time and the shots that triggered its bursts give the offset exactly
        start_ns = load_flight_config(out).clock.offset_ns("video")
        assert start_ns == meta["clock"]["video_to_telemetry_offset_ns"]
    if fmt.startswith("ros"):  # NavSatFix and Imu covariances: the generator's noise as the bag states it
        assert doc["sigma"] == {"position_m": round(math.hypot(0.25, 0.15), 3), "attitude_deg": 0.02}
    if fmt == "tlog":  # MAVLink altitudes are AMSL
        assert doc["altitude"] == {"geoid_separation_m": "auto"}
    if fmt == "ros2-mcap":  # the bag's own folder named: the bag is the flight
        bag = folder / "flight_ros2"
        assert draft_flight_config(bag, out.parent / "bag.yaml").doc["files"] == {"telemetry": [
            str(bag.relative_to(out.parent))]}


def test_the_run_command_on_an_init_config(tmp_path, capsys):
    """`ridgeloc init` then `ridgeloc run` as a user types them (images and CameraInfo in a ROS 1 bag; the
    target left at the image centre of the first observation, where the laser points)."""
    folder = tmp_path / "bag"
    generate(SynthConfig.from_dict(with_sections(TINY, FORMATS["ros1"][0])), folder)
    assert cli_main(["init", str(folder)]) == 0
    printed = capsys.readouterr().out
    assert f"wrote {folder / 'flight.yaml'}" in printed
    assert "to fill in (1), marked FILL IN in flight.yaml:\n  target:" in printed
    assert f"next: ridgeloc mark {folder / 'flight.yaml'}" in printed
    assert cli_main(["init", str(folder)]) == 1  # an existing config is not replaced
    assert "--overwrite" in capsys.readouterr().err
    assert cli_main(["run", str(folder / "flight.yaml"), "-o", str(tmp_path / "out"), "-q", "--no-figures"]) == 0
    assert (tmp_path / "out" / "targets.csv").is_file()


def test_conventions_are_found_from_the_data(tmp_path):
    """A gimbal topic in the camera optical frame with its yaw relative to the vehicle: the default reading
    scatters the optical axes over kilometres; init writes the mapping check names, and the axes meet."""
    name = "ros_optical_vehicle_yaw"
    cfg = with_sections({**BASE, "group": name}, FLIGHTS[name])
    generate(SynthConfig.from_dict(cfg), tmp_path / name)
    draft = draft_flight_config(tmp_path / name, tmp_path / "init.yaml")
    assert draft.doc["mapping"] == {"ros": {"gimbal": {"frame": "optical_enu", "yaw_in_vehicle_frame": True}}}
    decided = dict(draft.decisions)
    assert "the optical axes meet: laser sphere points within 5 m" in decided["conventions"]
    assert not draft.problems
    assert yaml.safe_load(config_text(draft, "ridgeloc init")) == draft.doc


def test_a_full_motion_video_needs_only_the_target(tmp_path):
    clip = SHARED / "fmv" / "aphill_klv_10s.ts"
    if not clip.is_file():
        pytest.skip("../shared/fmv not present")
    draft = draft_flight_config(clip, tmp_path / "clip.yaml")
    assert [f.key for f in draft.fill_in if f.required] == ["target"]
    assert draft.doc["altitude"] == {"geoid_separation_m": "auto"}  # EG 0104 altitudes are MSL
    assert "clock" not in draft.doc
    # its frame centres lie 72 m off the line of sight with true-north azimuths, 0.4 m with grid north (check's
    # frame-centre check): init reads them so, as check suggests
    assert draft.doc["mapping"] == {"klv": {"azimuth_north": "grid"}}
    assert "from UTM grid north" in dict(draft.decisions)["azimuths"]
    (tmp_path / "clip.yaml").write_text(config_text(draft, "ridgeloc init"))
    config = load_flight_config(tmp_path / "clip.yaml")
    assert config.files.telemetry == (str(clip),)
    from pipeline.flight.flight import read_flight_logs
    from pipeline.ingest.frame_centre import frame_centre_checks

    (_, check), = frame_centre_checks(read_flight_logs(config))
    assert check.median_m < 5 and check.explained_by is None


def _dji_folder(tmp_path, srt: str, frames: int) -> Path:
    """A DJI video folder: a real SRT of ../shared/srt beside a stand-in MP4 of the SRT's length (30 fps)."""
    import cv2

    src = SHARED / "srt" / srt
    if not src.is_file():
        pytest.skip("../shared/srt not present")
    folder = tmp_path / Path(srt).stem
    folder.mkdir()
    shutil.copy(src, folder / "DJI_0001.SRT")
    writer = cv2.VideoWriter(str(folder / "DJI_0001.MP4"), cv2.VideoWriter_fourcc(*"mp4v"), 30, (320, 180))
    for i in range(frames):
        writer.write(np.full((180, 320, 3), i % 250, np.uint8))
    writer.release()
    return folder


def test_a_dji_video_whose_srt_states_the_gimbal_needs_only_the_target(tmp_path):
    folder = _dji_folder(tmp_path, "ruz76_DJI_M300RTK.SRT", 8)  # Matrice 300: focal length, gimbal angles
    draft = draft_flight_config(folder, folder / "flight.yaml")
    assert [f.key for f in draft.fill_in if f.required] == ["target"]
    decided = dict(draft.decisions)
    assert "from the field of view DJI_0001.SRT" in decided["intrinsics"]  # the SRT's focal length
    assert "clock" not in draft.doc  # the SRT's cues are timed on its video
    assert draft.doc["observations"]["mode"] == "frames"  # no laser: frames the telemetry covers
    (folder / "flight.yaml").write_text(config_text(draft, "ridgeloc init"))
    assert load_flight_config(folder / "flight.yaml").name == "ruz76_DJI_M300RTK"


def test_a_dji_srt_with_heights_above_take_off_leaves_the_take_off_altitude_to_fill_in(tmp_path):
    """Phantom 4 RTK: gimbal angles but `H` heights above the take-off point and no focal length. The config is
    written with the take-off altitude (mapping srt.takeoff_altitude_m) and the intrinsics to fill in; filled in,
    the positions are the heights plus the take-off altitude, on its datum."""
    from pipeline.flight.flight import read_flight_logs

    folder = _dji_folder(tmp_path, "juanirache_p4_rtk.SRT", 30 * 56)
    draft = draft_flight_config(folder, folder / "flight.yaml")
    assert sorted(f.key for f in draft.fill_in if f.required) == ["camera", "mapping", "target"]
    (target,) = [f for f in draft.fill_in if f.key == "target"]
    assert target.why.endswith("without a laser, whatever the camera looked at)")  # no laser to point
    text = config_text(draft, "ridgeloc init")
    assert "#   srt: {takeoff_altitude_m: FILL_IN, abs_datum: amsl}" in text
    filled = (text.replace("#   srt: {takeoff_altitude_m: FILL_IN, abs_datum: amsl}",
                           "  srt: {takeoff_altitude_m: 20.0, abs_datum: ellipsoid}")
              .replace("# mapping:", "mapping:", 1))
    (folder / "flight.yaml").write_text(filled)
    position = read_flight_logs(load_flight_config(folder / "flight.yaml")).position
    assert position.alt_datum == "ellipsoid"
    np.testing.assert_allclose(position.alt_m[:3], [85.80 + 20, 85.83 + 20, 85.94 + 20])


@pytest.mark.parametrize(("srt", "missing"), [
    ("juanirache_mavic_pro.SRT", "missing for localization: attitude, gimbal"),  # no aircraft or gimbal angles
])
def test_a_dji_srt_that_lacks_what_localization_needs_is_one_line(tmp_path, capsys, srt, missing):
    folder = _dji_folder(tmp_path, srt, 30)
    assert cli_main(["init", str(folder)]) == 1
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and missing in err and "DJI_0001.SRT" in err
    assert not (folder / "flight.yaml").exists()


def test_a_folder_without_a_flight_is_one_line(tmp_path, capsys):
    (tmp_path / "notes.txt").write_text("nothing here")
    assert cli_main(["init", str(tmp_path)]) == 1
    err = capsys.readouterr().err.strip()
    assert err == (f"ridgeloc: error: {tmp_path}: found no logs, videos or photos; missing for localization: "
                   "position, attitude, gimbal, frames")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["notes.txt"]


def test_an_unreadable_file_is_named_once(tmp_path, capsys):
    """One file given: its reader's own line (was "x.tlog: found x.tlog: x.tlog: no MAVLink ... (unreadable);
    missing for localization: position, ..."); in a folder: its name once, with why."""
    log = tmp_path / "f" / "x.tlog"
    log.parent.mkdir()
    log.write_text("garbage\n")
    assert cli_main(["init", str(log)]) == 1
    assert capsys.readouterr().err.splitlines() == [
        f"ridgeloc: error: {log}: no MAVLink records found (not a .tlog, or garbage)"]
    assert cli_main(["init", str(log.parent)]) == 1
    assert capsys.readouterr().err.splitlines() == [
        f"ridgeloc: error: {log.parent}: found x.tlog: no MAVLink records found (not a .tlog, or garbage) "
        "(unreadable); missing for localization: position, attitude, gimbal, frames"]
    assert sorted(p.name for p in log.parent.iterdir()) == ["x.tlog"]


def test_photos_become_a_photo_flight(tmp_path):
    photos = ROOT / "sample_data" / "photos" / "h20_laser"
    draft = draft_flight_config(photos, tmp_path / "photos.yaml")
    assert draft.doc["files"] == {"photos": [str(photos)]}
    assert draft.doc["terrain"] == {"dem": str(photos / "dem.tif")}
    (tmp_path / "photos.yaml").write_text(config_text(draft, "ridgeloc init"))
    assert load_flight_config(tmp_path / "photos.yaml").files.photos == (str(photos),)


def test_init_of_photos_says_to_mark_them_next(tmp_path, capsys):
    """The photos' marks are what is left to fill in: the next command is `ridgeloc mark` (it said `ridgeloc run`,
    which would locate each photo's image centre, a different ground point in each photo without a laser)."""
    import shutil

    folder = tmp_path / "photos"
    shutil.copytree(ROOT / "sample_data" / "photos" / "h20_laser", folder)
    (folder / "flight.yaml").unlink()
    assert cli_main(["init", str(folder)]) == 0
    last = capsys.readouterr().out.splitlines()[-1]
    cfg = folder / "flight.yaml"
    assert last == (f"next: ridgeloc mark {cfg} (click the target in every photo that shows it; set marks_file: to "
                    f"the saved CSV), then ridgeloc run {cfg}")
    # the line to fill in names the file `ridgeloc mark` saves, not targets.csv (the answers' file of `run`)
    assert "\n# marks_file: marks.csv   # FILL IN: the CSV `ridgeloc mark` saves" in cfg.read_text()


def test_photos_beside_several_dems_are_told_to_pick_the_one_covering_the_target(tmp_path, capsys):
    """Photos with three GeoTIFFs beside them (../shared/photos/makers): init does not guess which covers the target,
    and does not drop them silently either: an optional line lists them, and uncommented it loads."""
    folder = tmp_path / "photos"
    shutil.copytree(ROOT / "sample_data" / "photos" / "h20_laser", folder)
    (folder / "flight.yaml").unlink()
    shutil.copy(folder / "dem.tif", folder / "other.tif")
    assert cli_main(["init", str(folder)]) == 0
    out = capsys.readouterr().out
    assert "optional: terrain: the DEM that covers the target, one of the 2 beside the photos (dem.tif, other.tif)" \
        in out
    text = (folder / "flight.yaml").read_text()
    assert "\nterrain:" not in text
    line = next(ln for ln in text.splitlines() if ln.startswith("# terrain: "))
    (folder / "flight.yaml").write_text(text.replace(line, line[2:]))
    assert load_flight_config(folder / "flight.yaml").terrain.dem == str(folder / "dem.tif")


def test_bursts_are_aligned_with_the_shots_that_triggered_them():
    s = 10**9
    period = 40_000_000
    start = 1_700_000_000 * s + 317_000_000  # the video clock's zero on the telemetry clock
    middles = np.array([3, 11, 19, 27, 35, 43]) * s + 40 * period  # bursts of 5 frames around one every 8 s
    frames = np.sort(np.concatenate([m + np.arange(-2, 3) * period for m in middles]))
    shots = start + np.arange(0, 50) * s + 40 * period  # the laser fires once a second, on a frame
    created = start // s * s
    assert align_bursts(frames, shots, created, created + s) == start
    # the shots alone leave whole seconds open: a window of two seconds holds two alignments
    assert align_bursts(frames, shots, created, created + 2 * s) is None
    # a burst's shot lost: the rest still align; two of six lost: too few
    assert align_bursts(frames, np.delete(shots, 11), created, created + s) == start
    assert align_bursts(frames, np.delete(shots, [11, 19]), created, created + s) is None
    # one burst only (continuous video): no alignment
    assert align_bursts(np.arange(100) * period, shots, created, created + s) is None


def test_synthetic_videos_state_their_recording_start(initialised):
    _fmt, folder, truth, _ = initialised
    if not (folder / "video.mp4").exists():
        pytest.skip("frames in the bag or the full-motion video")
    start_ns = truth["metadata"]["clock"]["video_to_telemetry_offset_ns"]
    assert creation_time_ns(folder / "video.mp4") == start_ns // 10**9 * 10**9  # whole seconds, as MP4 keeps it


def test_frames_without_laser_ranges_are_spread_over_the_telemetry(tmp_path):
    folder = _dji_folder(tmp_path, "ruz76_DJI_M300RTK.SRT", 8)
    from pipeline.autoconfig.folder import flight_files, read_folder

    log = flight_files(read_folder(folder)).log
    choice = observation_choice(log, 0)
    covered = np.asarray(log.frames.t_ns) <= log.position.t_ns[-1]
    assert set(choice.section["frame_indices"]) <= set(np.asarray(log.frames.index)[covered].tolist())
    with pytest.raises(InputError):
        flight_files(read_folder(tmp_path / "nothing"))


@pytest.mark.parametrize(("group", "telemetry"), [
    ("group1", "flight.tlog"), ("group2", "flight.bag"), ("group5", "flight.mcap"), ("hard_outliers", "flight.tlog"),
    ("angle10", "flight.mcap")])
def test_sample_flights_bursts_align_within_their_creation_second(group, telemetry):
    """The committed sample mp4s state no creation time: given its second (the truth's offset truncated), the
    bursts and the shots give the offset to the nanosecond, lost and outlying shots included (hard_outliers)."""
    from pipeline.ingest.dispatch import read_file

    folder = ROOT / "sample_data" / group
    offset = json.loads((folder / "truth.json").read_text())["metadata"]["clock"]["video_to_telemetry_offset_ns"]
    created = offset // 10**9 * 10**9
    frames, shots = read_file(folder / "video.mp4").frames.t_ns, read_file(folder / telemetry).range.t_ns
    assert align_bursts(frames, shots, created, created + 10**9) == offset


def test_a_folder_of_several_clips_is_refused_each_clip_being_a_flight(tmp_path, capsys):
    """Two full-motion videos in one folder are two flights (frames and telemetry in each file): init refuses in one
    line naming how to init one clip, instead of merging both clips' telemetry into one flight's config."""
    from pipeline.cli import main as cli_main

    fmv = Path(__file__).resolve().parents[1].parent / "shared" / "fmv"
    if not fmv.is_dir():
        pytest.skip("../shared/fmv absent (the shared read-only material is not beside this checkout)")
    folder = tmp_path / "clips"
    folder.mkdir()
    for name in ("aphill_short.ts", "aphill_klv_10s.ts"):
        (folder / name).symlink_to(fmv / name)
    assert cli_main(["init", str(folder)]) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "2 full-motion videos, each a flight of its own" in err
    assert f"`ridgeloc init {folder / 'aphill_klv_10s.ts'} -o aphill_klv_10s.yaml`" in err
    assert not (folder / "flight.yaml").exists()
