"""Synthetic flight configs: typed loading, unknown keys and bad values rejected with the file named."""

import json
from pathlib import Path

import pytest

from pipeline.errors import ConfigError
from pipeline.synth.config import SynthConfig

ROOT = Path(__file__).resolve().parents[1]


def test_example_config_spells_out_the_defaults():
    cfg = SynthConfig.load(ROOT / "configs" / "synth" / "example.yaml")
    assert cfg == SynthConfig().replace(group="example", description=cfg.description)


@pytest.mark.parametrize("name", ["group1", "group2", "group3", "group4", "group5", "group6", "hard_outliers",
                                  "angle10", "example_waypoints"])
def test_sample_configs_load(name):
    cfg = SynthConfig.load(ROOT / "configs" / "synth" / f"{name}.yaml")
    assert cfg.group == name


def test_unknown_key_is_rejected_with_path(tmp_path):
    p = tmp_path / "f.yaml"
    p.write_text("path:\n  kind: arc\n  radius_m: 4000\n")
    with pytest.raises(ConfigError, match=r"f\.yaml: unknown key\(s\) path\.radius_m"):
        SynthConfig.load(p)


@pytest.mark.parametrize("doc, message", [
    ({"path": {"kind": "spiral"}}, "'path.kind' must be one of"),
    ({"path": {"intersection_angle_deg": 140.0}}, "must be in \\(0, 132.8\\)"),
    ({"observations": {"count": 1}}, "'observations.count' must be >= 2"),
    ({"rates": {"laser_hz": 3.0}}, "must divide the frame rate"),
    ({"laser": {"outlier_observations": [12]}}, "indices outside 0..9"),
    ({"video": {"images_in_bag": True}}, "needs a bag format"),
    ({"path": {"kind": "waypoints", "waypoints_enu_m": [[0, 0, 2000]]}}, "at least two"),
    ({"start_time_utc": "yesterday"}, "ISO 8601"),
    ({"noise": {"laser_m": "5 m"}}, "'noise.laser_m' must be a finite number"),
])
def test_bad_values_are_rejected(doc, message):
    with pytest.raises(ConfigError, match=message):
        SynthConfig.from_dict(doc)


def test_cli_reports_a_missing_config(tmp_path, capsys):
    from pipeline.cli import main
    assert main(["synth", str(tmp_path / "nope.yaml"), "-o", str(tmp_path / "out")]) == 1
    assert "config file not found" in capsys.readouterr().err
    assert not (tmp_path / "out").exists()


def test_cli_writes_a_flight(tmp_path, capsys):
    from pipeline.cli import main
    cfg = tmp_path / "tiny.yaml"
    cfg.write_text("group: tiny\nobservations:\n  count: 2\npath:\n  intersection_angle_deg: 2.0\n"
                   "video:\n  burst_frames: 1\nscene:\n  texture_px: 512\n  texture_res_m: 12.0\n")
    out = tmp_path / "flight"
    assert main(["synth", str(cfg), "-o", str(out), "--format", "mcap", "--seed", "9"]) == 0
    assert "tiny: 2 observations, intersection angle 2.00 deg, 2 frames, mcap" in capsys.readouterr().out
    assert sorted(p.name for p in out.iterdir()) == ["flight.mcap", "flight.yaml", "truth.json", "video.frames.csv",
                                                     "video.mp4"]
    truth = json.loads((out / "truth.json").read_text())
    assert truth["seed"] == 9 and truth["config"]["format"] == "mcap"
    # an existing folder is refused unless --overwrite, and nothing is left behind
    assert main(["synth", str(cfg), "-o", str(out)]) == 1
    assert "already exists" in capsys.readouterr().err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["flight", "tiny.yaml"]


@pytest.mark.parametrize("args", [["--photos", "2", "--overwrite"], [str(ROOT / "configs" / "synth" / "example.yaml"),
                                                                      "--overwrite"]], ids=["photos", "config"])
def test_cli_refuses_a_file_as_the_output_folder_even_with_overwrite(tmp_path, capsys, args):
    from pipeline.cli import main
    afile = tmp_path / "afile"
    afile.write_text("keep me")
    assert main(["synth", *args, "-o", str(afile)]) == 1
    assert capsys.readouterr().err.splitlines() == [
        f"ridgeloc: error: {afile}: is a file, not a folder: -o names the folder to write the outputs into"]
    assert afile.read_text() == "keep me"
