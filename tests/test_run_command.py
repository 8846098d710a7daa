"""`ridgeloc run` as a user runs it: a batch of 20 flights, 2 of them broken, through the real command."""

import json
from pathlib import Path

import pytest
import yaml

from pipeline.cli import main

REPO = Path(__file__).resolve().parents[1]
SAMPLE = REPO / "configs" / "flights" / "group6.yaml"


def _flight_config(name: str, **changes) -> dict:
    doc = yaml.safe_load(SAMPLE.read_text())
    base = SAMPLE.parent
    files = doc["files"]
    files["telemetry"] = [str((base / t).resolve()) for t in files["telemetry"]]
    for key in ("video", "frames_csv"):
        files[key] = str((base / files[key]).resolve())
    doc["truth_file"] = str((base / doc["truth_file"]).resolve())
    doc["name"] = name
    doc.update(changes)
    return doc


def test_twenty_flights_two_broken_give_eighteen_reports_and_a_summary(tmp_path, capsys):
    flights = []
    for i in range(18):
        flights.append(_flight_config(f"flight{i:02d}"))
    missing = _flight_config("missing_log")
    missing["files"]["telemetry"] = [str(tmp_path / "nowhere.tlog")]
    garbage = tmp_path / "garbage.tlog"
    garbage.write_bytes(b"\x00\x01 this is not a tlog " * 200)
    broken = _flight_config("garbage_log")
    broken["files"]["telemetry"] = [str(garbage)]
    flights[5:5] = [missing]
    flights[12:12] = [broken]
    paths = []
    for doc in flights:
        p = tmp_path / "flights" / f"{doc['name']}.yaml"
        p.parent.mkdir(exist_ok=True)
        p.write_text(yaml.safe_dump(doc))
        paths.append(str(p))
    manifest = tmp_path / "manifest.yaml"
    manifest.write_text(yaml.safe_dump(paths))
    out = tmp_path / "out"

    rc = main(["run", str(manifest), "-o", str(out), "--no-figures", "-q", "--workers", "2"])
    captured = capsys.readouterr()
    assert rc == 1
    finished = sorted(p.parent.name for p in out.glob("*/estimates.json"))
    assert finished == [f"flight{i:02d}" for i in range(18)]
    assert not (out / "missing_log").exists() and not (out / "garbage_log").exists()
    assert "2 of 20 flight(s) failed (the others finished): missing_log, garbage_log" in captured.out
    summary = captured.err.strip().splitlines()
    assert len(summary) == 2 and all(line.startswith("ridgeloc: ") for line in summary)
    assert any("missing_log" in line and "nowhere.tlog" in line for line in summary)
    assert any("garbage_log" in line and "garbage.tlog" in line for line in summary)
    assert "Traceback" not in captured.err
    run = json.loads((out / "run.json").read_text())
    assert sorted(f["name"] for f in run["failures"]) == ["garbage_log", "missing_log"]
    assert len(run["groups"]) == 18
    table = (out / "table4.csv").read_text().splitlines()
    assert table[0].split(",")[1:] == [f"flight{i:02d}" for i in range(18)]
    for name in ("report.html", "report.md", "targets.csv", "targets.geojson", "targets.kml"):
        assert (out / name).is_file()

    # A re-run reuses the 18 finished flights and still reports the 2 failures.
    mtime = (out / "flight00" / "estimates.json").stat().st_mtime_ns
    rc = main(["run", str(manifest), "-o", str(out), "--no-figures", "-q"])
    assert rc == 1
    assert (out / "flight00" / "estimates.json").stat().st_mtime_ns == mtime
    assert "2 of 20 flight(s) failed" in capsys.readouterr().out


def test_a_folder_of_flights_runs_each_flight_yaml(tmp_path, capsys):
    for name in ("a", "b"):
        d = tmp_path / "flights" / name
        d.mkdir(parents=True)
        (d / "flight.yaml").write_text(yaml.safe_dump(_flight_config(f"folder_{name}")))
    out = tmp_path / "out"
    assert main(["run", str(tmp_path / "flights"), "-o", str(out), "--no-figures", "-q"]) == 0
    assert (out / "folder_a" / "estimates.json").is_file() and (out / "folder_b" / "estimates.json").is_file()
    assert "all 2 flight(s) finished" in capsys.readouterr().out


def test_missing_run_config_is_one_line_error(tmp_path, capsys):
    assert main(["run", str(tmp_path / "nope.yaml"), "-o", str(tmp_path / "out")]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "nope.yaml" in err[0] and "not found" in err[0]
    assert not (tmp_path / "out").exists()


def _misfit_result():
    import numpy as np

    from pipeline.results import GroupResult
    from pipeline.solve.estimate import Estimate, Status
    from pipeline.solve.observations import Observations

    P = np.tile(np.hstack([np.eye(3), np.zeros((3, 1))]), (3, 1, 1))
    obs = Observations(P=P, pixel=np.zeros((3, 2)), platform_m=np.eye(3) * 1000.0,
                       range_m=np.array([1200.0, 1250.0, 1300.0]), truth_m=np.zeros(3))
    rejected = [{"frame": 1, "t_ns": 1, "residual": "range", "value": 400.0, "sigmas": 80.0},
                {"frame": 2, "t_ns": 2, "residual": "u", "value": 60.0, "sigmas": 17.0}]
    mle = Estimate("mle", np.array([3.0, 4.0, 0.0]), 7, Status.CONVERGED, extras={"rejected": rejected})
    misfit = "mle: the error model does not fit this flight: the residuals drift; the covariance was inflated"
    r = GroupResult(name="g", origin_lla=(34.0, 108.0, 400.0), observations=obs, estimates={"mle": mle},
                    truth_m=np.zeros(3), intersection_angle_deg=30.0, timings_s={"solve": 0.5}, tracking={},
                    settings={"notes": ["target lost in 1 of 4 frames", misfit],
                              "solve_failures": {"range": {"status": "degenerate", "reason": "collinear"},
                                                 "vision": "needs two pixels"}})
    return r, misfit


def test_console_summary_says_misfit_rejections_and_unsolved_methods():
    """Issue 12 in `ridgeloc run`'s console: under a group's line, the mle's misfit sentence, how many
    observations it rejected, and the methods that did not solve with their status."""
    from pipeline.commands.run import group_summary

    r, misfit = _misfit_result()
    assert group_summary(r) == [
        "g: 3 observations, 0.50 s, error mle 5.00 m",
        f"  {misfit}",
        "  mle: 2 range and pixel residual(s) rejected as gross outliers (zero weight; listed in the report and "
        "estimates.json)",
        "  not solved: range (degenerate), vision (failed)"]
    r.estimates["mle"].extras["rejected"] = []
    r.settings = {"notes": []}
    assert group_summary(r, reused=True) == ["g: 3 observations, reused, error mle 5.00 m"]
    parallel = "the lines of sight are nearly parallel (first to last 1.3 deg): where they meet is undetermined"
    r.settings = {"notes": [parallel], "geometry_warnings": [parallel]}  # the geometry checks' warning comes first
    assert group_summary(r) == ["g: 3 observations, 0.50 s, error mle 5.00 m", f"  warning: {parallel}"]


def test_a_truncated_log_read_past_is_said_on_the_console(tmp_path, capsys):
    """A tlog cut mid-record is read up to the cut and the flight runs on what it holds: the console says so under
    the flight's line (it was only in the report's notes, the answer looking as sure as a whole flight's)."""
    doc = _flight_config("cut")
    whole = Path(doc["files"]["telemetry"][0]).read_bytes()
    cut = tmp_path / "flight.tlog"
    cut.write_bytes(whole[: len(whole) * 2 // 3])
    doc["files"]["telemetry"] = [str(cut)]
    config = tmp_path / "flight.yaml"
    config.write_text(yaml.safe_dump(doc))
    main(["run", str(config), "-o", str(tmp_path / "out"), "--no-figures"])
    captured = capsys.readouterr()
    lines = (captured.out + captured.err).splitlines()
    at = next(i for i, line in enumerate(lines) if line.startswith("cut: ") and "observation" in line)
    assert lines[at + 1].startswith(f"  warning: {cut}: file ends mid-record (truncated); read "), lines[at:at + 3]


def test_quiet_run_still_says_when_the_mle_model_does_not_fit(tmp_path, capsys, monkeypatch):
    """`ridgeloc run -q` prints only the summary and errors, and the mle's misfit sentence per group."""
    import pipeline.batch

    r, misfit = _misfit_result()
    monkeypatch.setattr(pipeline.batch, "run_groups", lambda *a, **k: ([r], [], []))
    # exit 1: this toy flight's one target is not located (its only estimate lies in no camera's view)
    assert main(["run", str(SAMPLE), "-o", str(tmp_path / "out"), "--no-figures", "-q"]) == 1
    out = capsys.readouterr().out.splitlines()
    assert out[:2] == [f"g: {misfit}", "all 1 flight(s) finished"]
    assert out[3].split() == ["target", "latitude", "longitude", "MSL", "m", "MGRS", "CE90", "m", "category", "method"]
    assert out[4].startswith("g ") and "NOT LOCATED" in out[4] and len(out) == 5  # the answers end a quiet run


@pytest.fixture
def no_flight_runs(monkeypatch):
    """run_groups replaced by a failure: what a test runs must be refused before any flight runs."""
    import pipeline.batch

    def no_flight(*args, **kwargs):
        raise AssertionError("a flight ran before its command line was refused")

    monkeypatch.setattr(pipeline.batch, "run_groups", no_flight)


def test_an_existing_file_as_the_output_folder_is_refused_before_any_flight_runs(tmp_path, capsys, no_flight_runs):
    afile = tmp_path / "afile"
    afile.write_text("keep me")
    assert main(["run", str(SAMPLE), "-o", str(afile), "--no-figures", "-q"]) == 1
    assert capsys.readouterr().err.splitlines() == [
        f"ridgeloc: error: {afile}: is a file, not a folder: -o names the folder to write the outputs into"]
    assert main(["run", str(SAMPLE), "-o", str(afile / "sub"), "--no-figures", "-q"]) == 1
    assert capsys.readouterr().err.splitlines() == [
        f"ridgeloc: error: {afile / 'sub'}: cannot create the output folder: {afile} is not a folder"]
    assert afile.read_text() == "keep me"


def test_a_scheduler_without_the_dask_executor_is_refused(tmp_path, capsys, no_flight_runs):
    """--scheduler names a Dask scheduler; without --executor dask it was ignored and the run went on locally."""
    out = tmp_path / "out"
    assert main(["run", str(SAMPLE), "-o", str(out), "--scheduler", "tcp://127.0.0.1:1", "-q"]) == 1
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 1 and "--executor dask" in err[0]
    assert not out.exists()


@pytest.mark.parametrize("content", [b"", b"a text file, not a video\n",
                                     (REPO / "sample_data" / "fmv" / "flight.ts").read_bytes()[:3072]],
                         ids=["empty", "text", "first-3KB"])
def test_a_single_bad_video_fails_in_one_line_and_writes_nothing(tmp_path, capsys, content):
    """A run whose every flight failed writes no report, run.json or empty targets.* (as a bad config), and its
    summary names the flight without saying that others finished."""
    video = tmp_path / "bad.ts"
    video.write_bytes(content)
    out = tmp_path / "out"
    assert main(["run", str(video), "-o", str(out), "--no-figures", "-q"]) == 1
    captured = capsys.readouterr()
    err = captured.err.splitlines()
    assert len(err) == 1 and err[0].startswith(f"ridgeloc: bad: failed: {video}: "), err
    assert captured.out.splitlines() == ["1 of 1 flight(s) failed: bad"]
    assert not out.exists()


def _not_configs(folder: Path) -> dict[str, Path]:
    """Inputs that are not configs, by the readers' suffix and content sniffing: kind -> path."""
    folder.mkdir()
    (folder / "flight.tlog").write_bytes(b"\xfd\x09\x00\x00" * 64)
    (folder / "clip.SRT").write_text("1\n00:00:00,000 --> 00:00:00,033\n[latitude: 46.5] [longitude: 7.5]\n")
    (folder / "ros2_bag").mkdir()
    (folder / "ros2_bag" / "metadata.yaml").write_text("rosbag2_bagfile_information: {}\n")
    (folder / "DJI_0001.JPG").write_bytes(b"\xff\xd8\xff")
    (folder / "clip.avi").write_bytes(b"RIFF")
    return {"telemetry log": folder / "flight.tlog", "srt": folder / "clip.SRT", "ros2": folder / "ros2_bag",
            "photo": folder / "DJI_0001.JPG", "video": folder / "clip.avi"}


def _log_not_config(path: Path) -> str:
    return (f"a telemetry log, not a flight config: `ridgeloc init {path.parent}` writes one from the flight's files, "
            "or name it in a flight config's files.telemetry")


def _not_config(kind: str, path: Path) -> str:
    """What a user who gave `path` where a config belongs is told: for a log or a video, the command that writes
    the config (`ridgeloc init` of its folder), not only the one that shows what the file holds."""
    if kind == "photo":
        return "drone photos, not a flight config: use `ridgeloc inspect` or `ridgeloc locate`"
    if kind == "video":
        return (f"a video, not a flight config: `ridgeloc init {path.parent}` writes one from the flight's files, "
                "or name it in a flight config's files.video")
    return _log_not_config(path)


def test_run_of_a_log_says_it_is_not_a_config(tmp_path, capsys):
    """A log given as the config is named as such (was "cannot read: 'utf-8' codec can't decode ..." or "the top
    level must be a mapping of keys"), alone and listed in a manifest."""
    out = tmp_path / "out"
    for kind, path in _not_configs(tmp_path / "in").items():
        assert main(["run", str(path), "-o", str(out), "-q"]) == 1, kind
        assert capsys.readouterr().err.splitlines() == [f"ridgeloc: error: {path}: {_not_config(kind, path)}"], kind
    log = tmp_path / "in" / "flight.tlog"
    manifest = tmp_path / "manifest.yaml"
    manifest.write_text(yaml.safe_dump([str(log)]))
    assert main(["run", str(manifest), "-o", str(out), "-q"]) == 1
    assert capsys.readouterr().err.splitlines() == [f"ridgeloc: flight: failed: {log}: {_log_not_config(log)}"]
    assert not out.exists()


def test_a_run_into_another_runs_folder_is_refused_unless_overwrite(tmp_path, capsys, monkeypatch):
    """Issue 38: OUT holding another run's finished flights is refused before any flight runs (the summary files
    would describe one run and the folders beside them another); --overwrite removes them, so OUT is one run's."""
    import pipeline.batch
    from pipeline.report.outputs import write_group_outputs
    from support.synthetic import synthetic_group

    out = tmp_path / "out"
    write_group_outputs(out, synthetic_group("someone_else", seed=1, n_frames=6), "digest", figures=False)
    flight = SAMPLE  # configs/flights/group6.yaml

    def no_flight(*args, **kwargs):
        raise AssertionError("a flight ran before its command line was refused")

    monkeypatch.setattr(pipeline.batch, "run_groups", no_flight)
    assert main(["run", str(flight), "-o", str(out), "--no-figures", "-q"]) == 1
    assert capsys.readouterr().err.splitlines() == [
        f"ridgeloc: error: {out}: holds another run's results (someone_else): choose another output folder, or "
        "give --overwrite to replace them"]
    assert (out / "someone_else" / "result.json").is_file()
    r = synthetic_group("group6", seed=2, n_frames=6)
    monkeypatch.setattr(pipeline.batch, "run_groups", lambda *a, **k: ([r], [], []))
    assert main(["run", str(flight), "-o", str(out), "--no-figures", "-q", "--overwrite"]) == 0
    assert sorted(p.name for p in out.iterdir() if p.is_dir() and p.name != "cot") == ["group6"]  # its flights' only
    assert [row.split(",")[0] for row in (out / "targets.csv").read_text().splitlines()[1:]] == ["group6"]


def test_a_failed_flights_folder_from_an_earlier_run_is_removed(tmp_path):
    """A flight that fails on a re-run loses the folder its earlier success left: targets.csv says it failed, and
    no folder beside it says otherwise."""
    from pipeline.report.outputs import write_run_outputs
    from pipeline.results import GroupFailure
    from support.synthetic import synthetic_group

    out = tmp_path / "out"
    a, b = synthetic_group("a", seed=1, n_frames=6), synthetic_group("b", seed=2, n_frames=6)
    write_run_outputs(out, [a, b], [], {}, figures=False)
    assert (out / "b" / ".done").is_file()
    write_run_outputs(out, [a], [GroupFailure("b", "b.yaml", "b.yaml: file not found")], {}, figures=False)
    assert not (out / "b").exists() and (out / "a" / ".done").is_file()
    rows = (out / "targets.csv").read_text().splitlines()[1:]
    assert [r.split(",")[0] for r in rows] == ["a", "b"] and "not_located" in rows[1]


def test_broken_flight_configs_of_a_folder_are_named_by_their_folders(tmp_path, capsys):
    """A folder of flights, each in its own folder as `ridgeloc init` writes them (FOLDER/flight.yaml): a config
    that does not load is reported under its folder's name, not as 'flight' (every one of them was)."""
    for name, text in (("north", "name: north\naltitdue: {geoid_separation_m: auto}\n"), ("south", "name: [\n")):
        (tmp_path / "flights" / name).mkdir(parents=True)
        (tmp_path / "flights" / name / "flight.yaml").write_text(text)
    out = tmp_path / "out"
    assert main(["run", str(tmp_path / "flights"), "-o", str(out), "-q"]) == 1
    printed = capsys.readouterr()
    err = printed.err.splitlines()
    assert [line.split(": failed: ")[0] for line in err] == ["ridgeloc: north", "ridgeloc: south"], err
    assert "north/flight.yaml: altitdue: unknown key (did you mean 'altitude'?)" in err[0]
    assert "2 of 2 flight(s) failed: north, south" in printed.out and not out.exists()


def test_an_answer_without_stated_accuracies_says_its_uncertainty_rests_on_defaults(tmp_path, capsys):
    """group1 with its `sigma:` line removed: still located, and the answer's reason and the console say that
    position and attitude accuracies were not stated; the sample config (sigma stated) says nothing of it."""
    import csv

    ROOT = Path(__file__).resolve().parents[1]
    text = (ROOT / "configs" / "flights" / "group1.yaml").read_text().replace("../../", f"{ROOT.as_posix()}/")
    bare = tmp_path / "group1_bare.yaml"
    bare.write_text("\n".join(ln for ln in text.splitlines() if not ln.startswith("sigma:")) + "\n")
    said = "sensor accuracies not stated (sigma.position_m, sigma.attitude_deg)"
    for config, out, expect in ((bare, tmp_path / "bare", True),
                                (ROOT / "configs" / "flights" / "group1.yaml", tmp_path / "stated", False)):
        assert main(["run", str(config), "-o", str(out), "--no-figures"]) == 0
        (row,) = list(csv.DictReader((out / "targets.csv").open()))
        assert row["status"] == "located"
        assert (said in row["reason"]) is expect and (said in capsys.readouterr().out) is expect


def test_accuracies_the_answers_method_states_in_its_own_sigma_option_are_stated():
    """`solve.options.mle.sigma` gives the MLE its sensor sigmas: an mle answer's uncertainty rests on them, so it
    is not said to rest on defaults; another method's answer (propagated from `sigma:`) still is."""
    import dataclasses

    from pipeline.flight_config import SigmaPriors, Solve, load_flight_config
    from pipeline.target_stage import unstated_accuracies

    ROOT = Path(__file__).resolve().parents[1]
    config = dataclasses.replace(load_flight_config(ROOT / "configs" / "flights" / "group1.yaml"),
                                 sigma=SigmaPriors())
    assert unstated_accuracies(config, "mle") == ["position_m", "attitude_deg"]
    own = dataclasses.replace(config, solve=Solve(options={"mle": {"sigma": {"position_m": 2.0}}}))
    assert unstated_accuracies(own, "mle") == ["attitude_deg"]
    assert unstated_accuracies(own, "los") == ["position_m", "attitude_deg"]
    assert unstated_accuracies(own, None) == ["position_m", "attitude_deg"]


def test_a_mapping_section_for_a_format_the_flight_lacks_is_a_warning():
    """`mapping: {ros: ...}` on a tlog flight changes nothing: check and run say so instead of taking it quietly
    (a user fixing a convention in the wrong section saw 'consistent' and believed the fix took)."""
    from pipeline.flight.flight import read_flight_logs, unused_mapping_warnings
    from pipeline.flight_config import load_flight_config

    assert unused_mapping_warnings({"ros": {}, "tlog": {}}, ["tlog"]) == [
        "mapping.ros: no file of this flight is read as ros (its files: tlog), so this section changes nothing"]
    # `video:` is read for a video listed among the telemetry files only: files.video takes files.frames_csv
    assert unused_mapping_warnings({"video": {"frames_csv": None}}, ["tlog"]) == [
        "mapping.video: read only for a video listed in files.telemetry (its files: tlog); the video of files.video "
        "takes files.frames_csv, so this section changes nothing"]
    assert unused_mapping_warnings({"video": {}}, ["video", "srt"]) == []
    assert unused_mapping_warnings({"ros": {}, "mcap": {}}, ["mcap"]) == []
    assert unused_mapping_warnings({"klv": {}}, ["fmv", "video"]) == []
    root = Path(__file__).resolve().parents[1]
    config = load_flight_config(root / "configs" / "flights" / "group1.yaml")
    import dataclasses

    log = read_flight_logs(dataclasses.replace(config, mapping={"ros": {"gimbal": {"frame": "frd_ned"}}}))
    assert sum("mapping.ros: no file of this flight is read as ros" in w for w in log.warnings) == 1
    assert not any("mapping." in w for w in read_flight_logs(config).warnings)
