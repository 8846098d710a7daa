"""The flight config of a synthetic flight (pipeline/synth/flight_config.py): the committed sample configs are what
it writes, and `ridgeloc synth` -> flight.yaml -> `ridgeloc run` works without any hand-written config."""

import json
import math
from pathlib import Path

import pytest
import yaml

from pipeline.cli import main as cli_main
from pipeline.flight_config import load_flight_config, load_run_config
from pipeline.run import process_group
from pipeline.synth.flight_config import flight_config_text, operator_flight_config

ROOT = Path(__file__).resolve().parents[1]
GROUPS = ("group1", "group2", "group3", "group4", "group5", "group6", "hard_outliers", "angle10", "fmv",
          "three_targets")


@pytest.mark.parametrize("group", GROUPS)
def test_committed_sample_configs_are_what_the_function_writes(group):
    committed_path = ROOT / "configs" / "flights" / f"{group}.yaml"
    committed = yaml.safe_load(committed_path.read_text())
    truth = json.loads((ROOT / "sample_data" / group / "truth.json").read_text())
    doc = operator_flight_config(truth, ROOT / "sample_data" / group, committed_path.parent)
    assert doc == committed
    assert yaml.safe_load(flight_config_text(doc, f"Sample flight {group}")) == committed
    # the values an operator knows, spelled out (the generator's noise of the sample flights = the paper's specs)
    # no correlation times: an operator does not know them (issue 12)
    assert committed["sigma"] == {"pixel_px": 0.5, "range_m": 5.0, "position_m": 2.0, "attitude_deg": 0.2}
    if "targets" in truth:  # issue 21: every target marked at its true pixel in its first visible observation
        assert committed["targets"] == [{"name": t["name"], **t["mark"]} for t in truth["targets"]]
    else:
        assert committed["target"] == truth["target_mark"]
    assert committed["truth_file"] == f"../../sample_data/{group}/truth.json"
    assert load_flight_config(committed_path).name == group  # every listed file exists


def test_sample_run_config_lists_exactly_the_written_configs():
    entries = load_run_config(ROOT / "configs" / "sample.yaml")
    assert [e.config.name for e in entries if not e.config.files.photos] == list(GROUPS)
    # and the photo flight written by `ridgeloc synth --photos` (tests/test_photo_sample.py)
    assert [e.config.name for e in entries if e.config.files.photos] == ["h20_laser"]


# The tiny flight of tests/test_run_e2e.py (2048 px texture, one frame per burst, 120 m/s): a few seconds to make.
TINY = """\
group: tiny
seed: 11
observations: {count: 6, lead_in_s: 3.0, lead_out_s: 1.0}
path: {intersection_angle_deg: 50.0, speed_mps: 120.0}
gimbal: {yaw_in_vehicle_frame: true}
noise: {gnss_drift_m: 0.25, gnss_white_m: 0.15, attitude_deg: 0.02, gimbal_deg: 0.02, laser_m: 1.0,
        attitude_tau_s: 7.0, gnss_tau_s: 30.0}
video: {burst_frames: 1, start_delay_s: 0.5}
scene: {texture_px: 2048, texture_res_m: 2.0, supersample: 1}
"""


def test_synth_writes_a_flight_config_that_runs(tmp_path, capsys):
    (tmp_path / "tiny.yaml").write_text(TINY)
    folder = tmp_path / "flights" / "tiny"
    assert cli_main(["synth", str(tmp_path / "tiny.yaml"), "-o", str(folder)]) == 0
    assert "ridgeloc run" in capsys.readouterr().out
    doc = yaml.safe_load((folder / "flight.yaml").read_text())
    truth = json.loads((folder / "truth.json").read_text())
    # paths relative to the flight folder; sensor specs from this flight's noise, not the sample flights'
    assert doc["files"] == {"telemetry": ["flight.tlog"], "video": "video.mp4", "frames_csv": "video.frames.csv"}
    assert doc["truth_file"] == "truth.json"
    # hypot(0.25, 0.15) = 0.29 -> 0.3
    assert doc["sigma"] == {"pixel_px": 0.5, "range_m": 1.0, "position_m": 0.3, "attitude_deg": 0.02}
    assert doc["clock"]["video_to_telemetry_offset_ns"] == truth["metadata"]["clock"]["video_to_telemetry_offset_ns"]

    r = process_group(load_flight_config(folder / "flight.yaml"))
    assert r.n_observations == truth["n_observations"] == 6
    # bound from the generator's noise, as derived in tests/test_run_e2e.py (4 sigma_3d)
    bound_m = 4 * math.sqrt(2 * (2.47**2 + 0.8**2) + 3 * 0.3**2 + 1.0**2)
    errors = r.errors_m()
    assert errors["mle"] < bound_m and errors["ridge"] < bound_m, errors

    # a folder of synthesized flights runs as is: `ridgeloc run FOLDER` finds every flight.yaml below it
    out = tmp_path / "out"
    assert cli_main(["run", str(tmp_path / "flights"), "-o", str(out), "-q", "--no-figures"]) == 0
    assert (out / "table4.csv").read_text().splitlines()[0] == "method,tiny"
