"""The committed sample_data/: Table 3's geometry, format coverage, size budget, files that open, and
deterministic regeneration (scripts/make_sample_data.py)."""

import hashlib
import json
import math
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pymap3d
import pytest
from mcap.reader import make_reader
from pymavlink import mavutil
from rosbags.highlevel import AnyReader

ROOT = Path(__file__).resolve().parents[1]
SAMPLE = ROOT / "sample_data"
TABLE3 = {"group1": (53.97, 16), "group2": (24.03, 17), "group3": (24.36, 34), "group4": (31.42, 11),
          "group5": (46.46, 18), "group6": (36.41, 11)}
EXTRA = {"hard_outliers": (40.0, 14), "angle10": (10.0, 10)}
ALL = {**TABLE3, **EXTRA}


def _truth(group: str) -> dict:
    return json.loads((SAMPLE / group / "truth.json").read_text())


def _angle_deg(a, b) -> float:
    return math.degrees(math.acos(np.clip(np.dot(a, b) / (np.linalg.norm(a) * np.linalg.norm(b)), -1, 1)))


@pytest.mark.parametrize("group", list(ALL))
def test_geometry_matches_table3(group):
    """Intersection angle (first vs last true line of sight) and observation count, from the true poses."""
    truth = _truth(group)
    t = truth["target"]
    target = np.array(pymap3d.geodetic2ecef(t["lat_deg"], t["lon_deg"], t["alt_m"]))
    cams = np.array([truth["frames"][o["frame_index"]]["camera_position_ecef_m"] for o in truth["observations"]])
    angle_deg, count = ALL[group]
    assert len(truth["observations"]) == count
    assert abs(_angle_deg(target - cams[0], target - cams[-1]) - angle_deg) < 0.01
    # observation distance ~5 km and observation angle (line of sight vs the vertical at the target) ~66.42 deg
    up = np.array(pymap3d.enu2uvw(0.0, 0.0, 1.0, t["lat_deg"], t["lon_deg"]))
    for c in cams:
        assert abs(np.linalg.norm(c - target) - 5000.0) < 120.0
        assert abs(_angle_deg(c - target, up) - 66.42) < 1.5
    obs_t = [o["t_ns"] for o in truth["observations"]]
    assert obs_t == sorted(obs_t) and all(truth["frames"][o["frame_index"]]["t_ns"] == o["t_ns"]
                                          for o in truth["observations"])


def test_formats_are_covered_and_folder_is_small():
    formats = {_truth(g)["metadata"]["format"] for g in ALL}
    assert {"tlog", "ros1", "mcap"} <= formats and formats & {"ros2-sqlite3", "ros2-mcap"}
    assert any("frames" in _truth(g)["metadata"]["files"] for g in ALL)  # CompressedImage inside a bag
    total = sum(p.stat().st_size for p in SAMPLE.rglob("*") if p.is_file())
    assert total < 50e6


def test_hard_flight_has_outliers_and_lost_target():
    obs = _truth("hard_outliers")["observations"]
    outliers = [o for o in obs if o["range_outlier"]]
    assert len(outliers) == 3 and all(abs(o["range_measured_m"] - o["range_true_m"]) > 200 for o in outliers)
    assert sum(not o["range_valid"] for o in obs) == 2
    assert sum(not o["target_visible"] for o in obs) == 2


def test_manifest_matches_committed_files():
    manifest = json.loads((SAMPLE / "MANIFEST.json").read_text())
    assert set(manifest) == set(ALL)
    for group, entry in manifest.items():
        on_disk = {p.relative_to(SAMPLE / group).as_posix() for p in (SAMPLE / group).rglob("*") if p.is_file()}
        assert on_disk == set(entry["files"])
        for rel, f in entry["files"].items():
            assert hashlib.sha256((SAMPLE / group / rel).read_bytes()).hexdigest() == f["sha256"], rel


@pytest.mark.parametrize("group", list(ALL))
def test_committed_files_open_in_standard_libraries(group):
    """Each telemetry file opens with its standard library; its laser shots are those truth.json says were
    logged, and every observation with a valid range has its shot at the observation's time."""
    truth = _truth(group)
    files = truth["metadata"]["files"]
    tel = SAMPLE / group / files["telemetry"]
    if tel.suffix == ".tlog":
        conn = mavutil.mavlink_connection(str(tel), dialect="ardupilotmega")
        shots = []
        while (m := conn.recv_match(type="CAMERA_TRACKING_GEO_STATUS")) is not None:
            shots.append(round(m._timestamp * 1e6) * 1000)
        conn.close()
    elif tel.suffix == ".mcap":
        with open(tel, "rb") as f:
            shots = [m.log_time for _, _, m in make_reader(f).iter_messages(topics=["/uav/laser"])]
    else:
        with AnyReader([tel]) as r:
            counts = {c.topic: c.msgcount for c in r.connections}
            laser = [c for c in r.connections if c.topic == "/uav/laser/range"]
            shots = [t for _, t, _ in r.messages(connections=laser)]
        if "frames" in files:
            assert counts["/uav/camera/image/compressed"] == len(truth["frames"])
    logged = [t for t, ok in zip(truth["laser_shots"]["t_ns"], truth["laser_shots"]["logged"], strict=True) if ok]
    assert shots == logged
    assert {o["t_ns"] for o in truth["observations"] if o["range_valid"]} <= set(shots)
    if "video" in files:
        cap = cv2.VideoCapture(str(SAMPLE / group / files["video"]))
        assert int(cap.get(cv2.CAP_PROP_FRAME_COUNT)) == len(truth["frames"])
        cap.release()


def test_regenerating_a_flight_reproduces_it(tmp_path):
    """scripts/make_sample_data.py --only group6 rebuilds the committed flight: telemetry, truth and frame
    times byte for byte, and the video's decoded frames (exactly, or within 1 DN if the encoder differs)."""
    out = tmp_path / "sd"
    subprocess.run([sys.executable, str(ROOT / "scripts" / "make_sample_data.py"), "--only", "group6", "-o",
                    str(out), "--no-frame-png"], check=True, capture_output=True)
    for name in ("flight.tlog", "truth.json", "video.frames.csv"):
        assert (out / "group6" / name).read_bytes() == (SAMPLE / "group6" / name).read_bytes(), name
    from pipeline.synth.writers.video import read_video_frames
    new = read_video_frames(out / "group6" / "video.mp4")
    old = read_video_frames(SAMPLE / "group6" / "video.mp4")
    assert len(new) == len(old)
    for a, b in zip(new, old, strict=True):
        assert np.abs(a.astype(np.int16) - b).mean() < 1.0
