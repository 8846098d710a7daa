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
EXTRA = {"hard_outliers": (40.0, 14), "angle10": (10.0, 10), "fmv": (30.0, 10), "three_targets": (53.97, 16)}
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


def test_three_target_flight_has_an_occluded_and_a_departing_target():
    """issue 21: three targets of different sizes and contrasts; one hidden for a while (by its cloud) then seen
    again, one leaving the view for good; each true pixel projects its true position (checked against the
    frames' true poses and the camera's pinhole without distortion, within the distortion's few pixels)."""
    truth = _truth("three_targets")
    targets = {t["name"]: t for t in truth["targets"]}
    assert len(targets) == 3 and len({(t["size_m"], t["contrast"]) for t in targets.values()}) == 3
    n = truth["n_observations"]
    assert targets["panel"]["visible_observations"] == list(range(n))
    grey = targets["small_grey"]["visible_observations"]
    assert [i for i in range(n) if i not in grey] == [6, 7, 8]  # occluded, then back
    far = targets["far_north"]["visible_observations"]
    assert far == list(range(far[-1] + 1)) and far[-1] < n - 1  # seen from the start, then out of the image
    frames = truth["frames"]
    obs = truth["observations"]
    assert all(not frames[o["frame_index"]]["targets"]["far_north"]["visible"] for o in obs[far[-1] + 1:])
    cam = truth["camera"]
    for t in targets.values():  # the mark is the true pixel in the first frame showing it
        f = frames[t["mark"]["frame_index"]]
        X = np.array(pymap3d.geodetic2ecef(t["lat_deg"], t["lon_deg"], t["alt_m"]))
        d = np.array(f["R_ecef_from_optical"]).T @ (X - np.array(f["camera_position_ecef_m"]))
        u, v = cam["fx_px"] * d[0] / d[2] + cam["cx_px"], cam["fy_px"] * d[1] / d[2] + cam["cy_px"]
        assert np.hypot(u - t["mark"]["pixel"][0], v - t["mark"]["pixel"][1]) < 5.0, t["name"]


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
    elif tel.suffix == ".ts":  # STANAG 4609: PyAV demuxes the KLV stream, stanag4609 decodes the Local Sets
        import av
        from stanag4609 import st0601

        with av.open(str(tel)) as c:
            assert c.streams.video[0].codec_context.name == "h264"
            n_video, sets = 0, []
            for p in c.demux(c.streams.video[0], c.streams.data[0]):
                if p.size and p.stream.type == "video":
                    n_video += 1
                elif p.size:
                    sets.append(st0601.decode_uas_local_set(bytes(p)))
        assert n_video == len(sets) == len(truth["frames"])
        shots = [s.misp_timestamp_microseconds * 1000 for s in sets if s.value(21) is not None]
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


# Regeneration is compared by content, not bytes: the generator's float64 arithmetic goes through numpy/OpenBLAS,
# whose kernel (chosen per CPU, or by OPENBLAS_CORETYPE) and thread count may change the last bit of a result, and
# a last-bit change can flip a float32 in the tlog. Stated tolerances:
#   tlog: same messages in the same order with the same timestamps; integer, string and array-of-integer fields
#         exact; float fields (float32 on the wire) to a relative 1e-6 (~8 float32 ulps), absolute floor 1e-12;
#   truth.json: same structure, integers, strings and booleans exact; floats to a relative 1e-9 (5 mm on an ECEF
#         coordinate), absolute floor 1e-9; video.frames.csv: identical rows (integer ns);
#   video: same frame count, each decoded frame at a PSNR >= 40 dB against the committed one (RMS < 2.6 DN).
TLOG_REL, TLOG_ABS = 1e-6, 1e-12
TRUTH_REL, TRUTH_ABS = 1e-9, 1e-9
MIN_PSNR_DB = 40.0


def _tlog_messages(path: Path) -> list[tuple[str, float, dict]]:
    conn = mavutil.mavlink_connection(str(path), dialect="ardupilotmega")
    out = []
    while (m := conn.recv_match()) is not None:
        out.append((m.get_type(), m._timestamp, m.to_dict()))
    conn.close()
    return out


def _assert_same_content(new, old, where: str, rel: float, abs_: float) -> None:
    """Recursive comparison of decoded values: floats within rel/abs, everything else exactly."""
    assert type(new) is type(old), f"{where}: {type(new).__name__} vs {type(old).__name__}"
    if isinstance(new, dict):
        assert new.keys() == old.keys(), where
        for k in new:
            _assert_same_content(new[k], old[k], f"{where}/{k}", rel, abs_)
    elif isinstance(new, list | tuple):
        assert len(new) == len(old), f"{where}: length {len(new)} vs {len(old)}"
        for i, (a, b) in enumerate(zip(new, old, strict=True)):
            _assert_same_content(a, b, f"{where}[{i}]", rel, abs_)
    elif isinstance(new, float):
        assert math.isclose(new, old, rel_tol=rel, abs_tol=abs_) or (math.isnan(new) and math.isnan(old)), \
            f"{where}: {new!r} vs {old!r}"
    else:
        assert new == old, f"{where}: {new!r} vs {old!r}"


def _psnr_db(a: np.ndarray, b: np.ndarray) -> float:
    mse = np.mean((a.astype(np.float64) - b.astype(np.float64)) ** 2)
    return math.inf if mse == 0 else 10 * math.log10(255.0**2 / mse)


def test_content_comparison_catches_real_changes():
    """The tolerances above are tight enough to see a changed value, a dropped message or a darker frame."""
    _assert_same_content({"a": [1, 2.0]}, {"a": [1, 2.0 * (1 + 5e-7)]}, "x", TLOG_REL, TLOG_ABS)
    for new, old in (({"a": 1.0}, {"a": 1.0 + 1e-5}), ({"a": 1}, {"a": 2}), ([1.0], [1.0, 2.0]), ({"a": 1}, {"a": 1.0}),
                     ({"lat": 34.36}, {"lat": 34.36 + 1e-7})):
        with pytest.raises(AssertionError):
            _assert_same_content(new, old, "x", TRUTH_REL, TRUTH_ABS)
    img = np.full((40, 60, 3), 128, np.uint8)
    assert _psnr_db(img, img) == math.inf and _psnr_db(img, img + 1) > MIN_PSNR_DB > _psnr_db(img, img + 3)


def test_regenerating_a_flight_reproduces_it(tmp_path):
    """scripts/make_sample_data.py --only group6 rebuilds the committed flight: the same telemetry messages,
    truth and frame times (by content, within the tolerances above) and the same video frames (by PSNR)."""
    out = tmp_path / "sd"
    subprocess.run([sys.executable, str(ROOT / "scripts" / "make_sample_data.py"), "--only", "group6", "-o",
                    str(out), "--no-frame-png"], check=True, capture_output=True)
    new_dir, old_dir = out / "group6", SAMPLE / "group6"
    assert sorted(p.name for p in new_dir.iterdir()) == sorted(p.name for p in old_dir.iterdir())

    new, old = _tlog_messages(new_dir / "flight.tlog"), _tlog_messages(old_dir / "flight.tlog")
    assert len(new) == len(old) > 1000
    for i, ((type_a, t_a, a), (type_b, t_b, b)) in enumerate(zip(new, old, strict=True)):
        assert (type_a, t_a) == (type_b, t_b), f"message {i}"
        _assert_same_content(a, b, f"message {i} {type_a}", TLOG_REL, TLOG_ABS)

    _assert_same_content(json.loads((new_dir / "truth.json").read_text()),
                         json.loads((old_dir / "truth.json").read_text()), "truth.json", TRUTH_REL, TRUTH_ABS)
    assert (new_dir / "video.frames.csv").read_text().splitlines() == \
        (old_dir / "video.frames.csv").read_text().splitlines()

    from pipeline.synth.writers.video import read_video_frames
    new_frames, old_frames = read_video_frames(new_dir / "video.mp4"), read_video_frames(old_dir / "video.mp4")
    assert len(new_frames) == len(old_frames) > 0
    for i, (a, b) in enumerate(zip(new_frames, old_frames, strict=True)):
        assert a.shape == b.shape and _psnr_db(a, b) >= MIN_PSNR_DB, f"frame {i}: {_psnr_db(a, b):.1f} dB"
