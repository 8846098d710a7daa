"""One small synthetic flight through every stage (synth -> ingest -> track -> sync -> solve -> outputs).

Error bound, from the generator's noise (set below), not from the estimator's output:
- line-of-sight angle error per axis: the gimbal's logged attitude (0.02 deg) plus, because its yaw is logged
  relative to the vehicle's heading (MAVLink YAW_IN_VEHICLE_FRAME, composed with the vehicle's yaw), the
  vehicle's (0.02 deg): at most sqrt(2) * 0.02 deg = 0.49 mrad, i.e. 2.47 m across the line of sight at the 5 km
  slant range; slow Gauss-Markov processes (tau 20 s, as long as the flight), so no averaging over observations
  is credited;
- tracking error: below 0.3 px (tests/test_track_sift.py; checked here too) = 0.17 mrad = 0.8 m at 5 km;
- GNSS 0.3 m per axis; laser 1 m along the line of sight.
  sigma_3d <= sqrt(2 * (2.47^2 + 0.8^2) + 3 * 0.3^2 + 1^2) = 3.8 m; the bound is 4 sigma_3d = 15.4 m.
A convention error anywhere in the chain (a frame, a sign, a clock offset, the datum, the lens) is tens to
thousands of metres at 5 km.
"""

import json
import math

import numpy as np
import pytest

from pipeline import observation_file
from pipeline.cli import main as cli_main
from pipeline.flight_config import load_flight_config
from pipeline.run import process_group
from pipeline.synth import flight as synth
from pipeline.synth.config import SynthConfig

SIGMA_3D_M = math.sqrt(2 * (2.47**2 + 0.8**2) + 3 * 0.3**2 + 1.0**2)
BOUND_M = 4 * SIGMA_3D_M



def _flight_config(folder, out_path):
    """What an operator would write for the flight (camera, lever arms, clock offset, mark), from truth.json's
    metadata; truth_file only feeds the error columns."""
    d = json.loads((folder / "truth.json").read_text())
    cam = d["camera"]
    lines = [
        "name: tiny",
        "files: {telemetry: [flight/flight.tlog], video: flight/video.mp4, frames_csv: flight/video.frames.csv}",
        f"altitude: {{geoid_separation_m: {d['metadata']['geoid_separation_m']}}}",
        "camera: {" + ", ".join(f"{k}: {cam[k]}" for k in ("width_px", "height_px", "fx_px", "fy_px", "cx_px",
                                                           "cy_px", "dist", "R_optical_from_gimbal")) + "}",
        f"lever_arms_m: {{camera: {d['lever_arms_m']['camera']}, rangefinder: {d['lever_arms_m']['rangefinder']}}}",
        f"clock: {{video_to_telemetry_offset_ns: {d['metadata']['clock']['video_to_telemetry_offset_ns']}}}",
        f"target: {{frame_index: {d['target_mark']['frame_index']}, pixel: {d['target_mark']['pixel']}}}",
        "truth_file: flight/truth.json",
    ]
    out_path.write_text("\n".join(lines) + "\n")
    return out_path


@pytest.fixture(scope="module")
def tiny_flight(tmp_path_factory):
    root = tmp_path_factory.mktemp("e2e")
    cfg = SynthConfig.from_dict({
        "group": "tiny", "seed": 11,
        "observations": {"count": 6, "lead_in_s": 3.0, "lead_out_s": 1.0},
        "path": {"intersection_angle_deg": 50.0, "speed_mps": 120.0},
        "gimbal": {"yaw_in_vehicle_frame": True},
        "noise": {"gnss_drift_m": 0.25, "gnss_white_m": 0.15, "attitude_deg": 0.02, "gimbal_deg": 0.02,
                  "laser_m": 1.0},
        "video": {"burst_frames": 1, "start_delay_s": 0.5},
        "scene": {"texture_px": 2048, "texture_res_m": 2.0, "supersample": 1},
    })
    synth.generate(cfg, root / "flight")
    return root, _flight_config(root / "flight", root / "tiny.yaml")


def test_every_stage_locates_the_target_within_the_noise_bound(tiny_flight):
    root, cfg_path = tiny_flight
    r = process_group(load_flight_config(cfg_path))
    truth = json.loads((root / "flight" / "truth.json").read_text())
    assert r.n_observations == truth["n_observations"] == 6
    assert r.intersection_angle_deg == pytest.approx(truth["intersection_angle_deg"], abs=0.5)
    # tracking against the true projections
    true_px = {f["frame_index"]: f["true_target_pixel"] for f in truth["frames"]}
    tracked = [(p, true_px[i]) for i, p in zip(r.tracking["frame_index"], r.tracking["pixel_px"], strict=True)]
    assert all(p is not None for p, _ in tracked)
    err_px = [math.dist(p, t) for p, t in tracked]
    assert max(err_px) < 0.6 and np.median(err_px) < 0.3, err_px
    errors = r.errors_m()
    assert errors["mle"] < BOUND_M, errors
    assert errors["ridge"] < BOUND_M, errors
    assert set(r.timings_s) == {"ingest", "decode", "track", "sync", "solve", "answer"}


def test_run_command_writes_the_report_and_skips_a_bad_group(tiny_flight, capsys):
    root, cfg_path = tiny_flight
    (root / "broken.yaml").write_text(cfg_path.read_text().replace("name: tiny", "name: broken")
                                      .replace("flight/flight.tlog", "flight/missing.tlog"))
    (root / "run.yaml").write_text("groups: [tiny.yaml, broken.yaml]\n")
    out = root / "out"
    assert cli_main(["run", str(root / "run.yaml"), "-o", str(out), "-q"]) == 1
    err = capsys.readouterr().err
    assert "broken" in err and "missing.tlog" in err and len(err.strip().splitlines()) == 1
    assert not (out / "broken").exists()
    rows = (out / "table4.csv").read_text().splitlines()
    assert rows[0] == "method,tiny"
    names = [row.split(",")[0] for row in rows[1:]]
    assert names[-2:] == ["intersection_angle_deg", "observations"] and "mle" in names and "ridge" in names
    assert rows[-1] == "observations,6"
    report = (out / "report.md").read_text()
    assert "Weighted MLE" in report and "broken" in report
    # observations.json is the `ridgeloc solve` input: re-solving it gives estimates.json again
    obs = observation_file.load(out / "tiny" / "observations.json")
    assert obs.n == 6 and obs.truth_m is not None
    doc = json.loads((out / "tiny" / "estimates.json").read_text())
    capsys.readouterr()
    assert cli_main(["solve", str(out / "tiny" / "observations.json"), "--method", "mle", "--json"]) == 0
    again = json.loads(capsys.readouterr().out)
    np.testing.assert_allclose(again["estimates"]["mle"]["position_m"], doc["estimates"]["mle"]["position_m"],
                               atol=1e-6)
    mle_err = float(rows[names.index("mle") + 1].split(",")[1])
    assert mle_err == pytest.approx(doc["estimates"]["mle"]["error_m"], abs=1e-3)


def test_template_mark_and_a_bad_mark_frame(tiny_flight):
    import cv2

    from pipeline.errors import ConfigError
    from pipeline.ingest import VideoFrames

    root, cfg_path = tiny_flight
    truth = json.loads((root / "flight" / "truth.json").read_text())
    k, (u, v) = truth["target_mark"]["frame_index"], truth["target_mark"]["pixel"]
    with VideoFrames(root / "flight" / "video.mp4") as video:
        frame = video[k]
    x0, y0 = round(u) - 100, round(v) - 80
    cv2.imwrite(str(root / "template.png"), frame[y0:y0 + 161, x0:x0 + 201])
    text = cfg_path.read_text()
    mark_line = next(line for line in text.splitlines() if line.startswith("target:"))
    (root / "template.yaml").write_text(text.replace(
        mark_line, f"target: {{template: template.png, template_pixel: [{u - x0}, {v - y0}]}}"))
    by_template = process_group(load_flight_config(root / "template.yaml"))
    by_pixel = process_group(load_flight_config(cfg_path))
    assert by_template.tracking["mark"]["frame_index"] == by_pixel.tracking["frame_index"][0]
    np.testing.assert_allclose(by_template.observations.pixel, by_pixel.observations.pixel, atol=0.5)
    (root / "badmark.yaml").write_text(text.replace(mark_line, "target: {frame_index: 99999, pixel: [300, 200]}"))
    with pytest.raises(ConfigError, match=r"badmark\.yaml: target: frame index 99999 out of range \(the video has "
                       r"frames 0\.\.\d+\)$"):  # at load: the config has a frames CSV
        load_flight_config(root / "badmark.yaml")


def test_hard_outliers_tracking_lists_every_frame_with_its_reason():
    """The sample flight with a cloud-covered and an out-of-view target: tracking.json keeps all 14 planned
    frames, flags the 2 lost ones with why, and marks the one dropped (no range either) as not used."""
    from pathlib import Path

    from pipeline.results import group_files

    cfg = Path(__file__).resolve().parent.parent / "configs" / "flights" / "hard_outliers.yaml"
    r = process_group(load_flight_config(cfg))
    t = json.loads(group_files(r)["tracking.json"])
    assert len(t["frame_index"]) == len(t["lost"]) == len(t["reason"]) == len(t["used"]) == 14
    assert sum(t["lost"]) == 2 and sum(t["used"]) == r.n_observations == 13
    for lost, reason, used in zip(t["lost"], t["reason"], t["used"], strict=True):
        assert (reason is None) == (not lost and used)
        if lost:
            assert reason.startswith("target lost: ")
        if not used:
            assert "dropped" in reason
    assert "target lost in 2 of 14" in " ".join(r.settings["notes"])
    # issue 12: its three gross range outliers (-424, +311, -650 m) get zero weight and are listed per
    # observation in estimates.json, and in the notes with their video frame and time in the flight
    doc = json.loads(group_files(r)["estimates.json"])
    rejected = doc["estimates"]["mle"]["rejected"]
    assert [x["residual"] for x in rejected] == ["range"] * 3 and all(abs(x["value"]) > 300 for x in rejected)
    # laser ranging alone: the short arc leaves it rank deficient; where it does iterate (another BLAS kernel, a
    # tenth of a pixel elsewhere) it runs away or stops unconverged: never a converged point
    range_doc = (doc.get("unsolved") or {}).get("range") or doc["estimates"]["range"]
    assert range_doc["status"] in ("degenerate", "diverged", "max_iterations")
    video = [f for f, used in zip(t["frame_index"], t["used"], strict=True) if used]
    t0 = min(r.observations.t_ns)
    notes = [n for n in r.settings["notes"] if n.startswith("mle: rejected")]
    assert len(notes) == 3
    for x, note in zip(rejected, notes, strict=True):
        assert x["t_ns"] == r.observations.t_ns[x["frame"]]
        assert (f"mle: rejected the laser range of observation {x['frame']} (video frame {video[x['frame']]}, "
                f"t = {(x['t_ns'] - t0) / 1e9:.2f} s after the first observation): residual {x['value']:+.2f} m"
                ) in note
