"""Synthetic flights: every written file opens in the standard libraries (pymavlink, rosbags, mcap, OpenCV), and
the logged telemetry, read back independently, reproduces the true camera geometry in truth.json.

The geometry check reconstructs the camera from the logs of a noise-free flight the way a user would
(antenna position + lever arm, attitudes relative to the local level NED at the vehicle, gimbal -> optical) with
pymap3d and scipy, and projects the surveyed target: it must land on truth.json's true pixel.
"""

import json
from pathlib import Path

import cv2
import numpy as np
import pymap3d
import pytest
from mcap.reader import make_reader
from pymavlink import mavutil
from rosbags.highlevel import AnyReader
from rosbags.typesys import Stores, get_typestore
from scipy.spatial.transform import Rotation, Slerp

from pipeline.synth.config import SynthConfig
from pipeline.synth.flight import generate

R_ENU_FROM_NED = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])
FLU_FROM_FRD = np.diag([1.0, -1.0, -1.0])

NOISE_FREE = {"gnss_drift_m": 0.0, "gnss_white_m": 0.0, "attitude_deg": 0.0, "gimbal_deg": 0.0, "laser_m": 0.0,
              "laser_dropout": 0.0}
SMALL_SCENE = {"texture_px": 1024, "texture_res_m": 6.0}
FLIGHTS = {
    "tlog": {"format": "tlog"},
    "tlog_vehicle_yaw": {"format": "tlog", "gimbal": {"yaw_in_vehicle_frame": True}},
    "ros1": {"format": "ros1"},
    "ros2-sqlite3": {"format": "ros2-sqlite3", "video": {"images_in_bag": True}},
    "ros2-mcap": {"format": "ros2-mcap", "path": {"kind": "straight", "intersection_angle_deg": 12.0}},
    "mcap": {"format": "mcap", "path": {"kind": "waypoints", "waypoints_enu_m": [[-5000, -2500, 2000],
                                                                                [-4000, 0, 2050],
                                                                                [-4500, 3000, 2000]]},
             "observations": {"count": 3, "spacing_s": 20}},
}


def _config(name: str, noise_free: bool) -> SynthConfig:
    doc = {"group": name, "seed": 5, "observations": {"count": 3}, "path": {"intersection_angle_deg": 20.0},
           "scene": SMALL_SCENE, "video": {"burst_frames": 3}}
    for key, value in FLIGHTS[name].items():
        doc[key] = {**doc.get(key, {}), **value} if isinstance(value, dict) else value
    if noise_free:
        doc["noise"] = NOISE_FREE
    return SynthConfig.from_dict(doc)


@pytest.fixture(scope="module")
def flights(tmp_path_factory):
    base = tmp_path_factory.mktemp("synth")
    out = {}
    for name in FLIGHTS:
        out[name] = generate(_config(name, noise_free=True), base / name).out_dir
    return out


# ---- readers written for the test, straight on the standard libraries ----------------------------------------

def read_tlog(path: Path, geoid_sep: float) -> dict:
    conn = mavutil.mavlink_connection(str(path), dialect="ardupilotmega")
    d = {k: [] for k in ("gps", "att", "gim", "las")}
    flags = set()
    while (m := conn.recv_match()) is not None:
        t = round(m._timestamp * 1e6) * 1000
        typ = m.get_type()
        if typ == "GLOBAL_POSITION_INT":
            d["gps"].append((t, m.lat / 1e7, m.lon / 1e7, m.alt / 1000 + geoid_sep))
        elif typ == "ATTITUDE":
            d["att"].append((t, *Rotation.from_euler("ZYX", [m.yaw, m.pitch, m.roll]).as_quat()))
        elif typ == "GIMBAL_DEVICE_ATTITUDE_STATUS":
            flags.add(m.flags)
            w, x, y, z = m.q
            d["gim"].append((t, x, y, z, w))
        elif typ == "CAMERA_TRACKING_GEO_STATUS":
            d["las"].append((t, m.dist))
    conn.close()
    assert len(flags) == 1
    return {**{k: np.array(v) for k, v in d.items()}, "yaw_in_vehicle": flags == {32}}


def read_ros(path: Path) -> dict:
    d = {k: [] for k in ("gps", "att", "gim", "las")}
    with AnyReader([path], default_typestore=get_typestore(Stores.ROS2_HUMBLE)) as r:
        for c, t, raw in r.messages():
            m = r.deserialize(raw, c.msgtype)
            stamp = m.header.stamp.sec * 1_000_000_000 + m.header.stamp.nanosec
            assert stamp == t  # record time = measurement time
            if c.topic == "/uav/gps/fix":
                d["gps"].append((t, m.latitude, m.longitude, m.altitude))
            elif c.topic in ("/uav/imu", "/uav/gimbal/attitude"):
                q = m.orientation if c.topic == "/uav/imu" else m.quaternion
                R_enu_flu = Rotation.from_quat([q.x, q.y, q.z, q.w]).as_matrix()
                R_ned_frd = R_ENU_FROM_NED.T @ R_enu_flu @ FLU_FROM_FRD
                d["att" if c.topic == "/uav/imu" else "gim"].append((t, *Rotation.from_matrix(R_ned_frd).as_quat()))
            elif c.topic == "/uav/laser/range":
                assert m.min_range <= m.range <= m.max_range
                d["las"].append((t, m.range))
    return {**{k: np.array(v) for k, v in d.items()}, "yaw_in_vehicle": False}


def read_mcap(path: Path) -> dict:
    d = {k: [] for k in ("gps", "att", "gim", "las")}
    with open(path, "rb") as f:
        for schema, channel, msg in make_reader(f).iter_messages():
            assert schema.encoding == "jsonschema" and channel.message_encoding == "json"
            j = json.loads(msg.data)
            assert j["t_ns"] == msg.log_time == msg.publish_time
            if channel.topic == "/uav/gps":
                assert j["altitude_datum"] == "ellipsoid"
                d["gps"].append((j["t_ns"], j["latitude_deg"], j["longitude_deg"], j["altitude_m"]))
            elif channel.topic in ("/uav/attitude", "/uav/gimbal"):
                w, x, y, z = j["q_wxyz"]
                d["att" if channel.topic == "/uav/attitude" else "gim"].append((j["t_ns"], x, y, z, w))
            elif channel.topic == "/uav/laser":
                assert j["valid"]
                d["las"].append((j["t_ns"], j["range_m"]))
    return {**{k: np.array(v) for k, v in d.items()}, "yaw_in_vehicle": False}


def read_logs(folder: Path, truth: dict) -> dict:
    f = truth["metadata"]["files"]["telemetry"]
    if f.endswith(".tlog"):
        return read_tlog(folder / f, truth["metadata"]["geoid_separation_m"])
    if f.endswith(".mcap"):
        return read_mcap(folder / f)
    return read_ros(folder / f)


def _slerp(series: np.ndarray, t_ns: np.ndarray) -> Rotation:
    t = (series[:, 0] - series[0, 0]) / 1e9
    return Slerp(t, Rotation.from_quat(series[:, 1:]))((t_ns - series[0, 0]) / 1e9)


def _R_ecef_from_ned(lat, lon) -> np.ndarray:
    cols = [np.stack(pymap3d.enu2uvw(*b, lat, lon), axis=-1) for b in np.eye(3)]
    return np.stack(cols, axis=-1) @ R_ENU_FROM_NED


def reconstruct(truth: dict, logs: dict, t_ns: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Camera and rangefinder ECEF positions (n, 3) and R_ecef_from_optical (n, 3, 3) at t_ns from the logs."""
    g = logs["gps"]
    lat, lon, h = (np.interp(t_ns, g[:, 0], g[:, i]) for i in (1, 2, 3))
    antenna = np.stack(pymap3d.geodetic2ecef(lat, lon, h), axis=-1)
    R_ecef_ned = _R_ecef_from_ned(lat, lon)
    R_ned_body = _slerp(logs["att"], t_ns).as_matrix()
    R_ned_gim = _slerp(logs["gim"], t_ns).as_matrix()
    if logs["yaw_in_vehicle"]:
        yaw = Rotation.from_matrix(R_ned_body).as_euler("ZYX")[:, 0]
        R_ned_gim = Rotation.from_euler("Z", yaw[:, None]).as_matrix() @ R_ned_gim
    arms = truth["lever_arms_m"]
    camera = antenna + np.einsum("nij,j->ni", R_ecef_ned @ R_ned_body, arms["camera"])
    rangefinder = antenna + np.einsum("nij,j->ni", R_ecef_ned @ R_ned_body, arms["rangefinder"])
    R_ecef_optical = R_ecef_ned @ R_ned_gim @ np.array(truth["camera"]["R_optical_from_gimbal"]).T
    return camera, rangefinder, R_ecef_optical


@pytest.mark.parametrize("name", list(FLIGHTS))
def test_logs_reproduce_the_true_camera_and_range(flights, name):
    folder = flights[name]
    truth = json.loads((folder / "truth.json").read_text())
    logs = read_logs(folder, truth)
    obs_t = np.array([o["t_ns"] for o in truth["observations"]])
    frames = [truth["frames"][o["frame_index"]] for o in truth["observations"]]
    camera, rangefinder, R_ecef_optical = reconstruct(truth, logs, obs_t)
    tgt = np.array(truth["target"]["ecef_m"])
    cam = truth["camera"]
    K = np.array([[cam["fx_px"], 0, cam["cx_px"]], [0, cam["fy_px"], cam["cy_px"]], [0, 0, 1.0]])
    for i, f in enumerate(frames):
        assert np.linalg.norm(camera[i] - f["camera_position_ecef_m"]) < 0.05
        dR = Rotation.from_matrix(R_ecef_optical[i].T @ np.array(f["R_ecef_from_optical"]))
        assert dR.magnitude() < 2e-5  # 25 Hz interpolation; frame mix-ups are ~1e-3 rad
        rvec, _ = cv2.Rodrigues(R_ecef_optical[i].T)
        px = cv2.projectPoints(tgt[None], rvec, -R_ecef_optical[i].T @ camera[i], K, np.array(cam["dist"]))[0]
        assert np.allclose(px.ravel(), f["true_target_pixel"], atol=0.05)
    # the laser (noise-free, aimed at the target) measures the rangefinder-to-target distance
    las = logs["las"]
    shot = {int(t): r for t, r in las}
    for i, t in enumerate(obs_t):
        assert abs(shot[int(t)] - np.linalg.norm(tgt - rangefinder[i])) < 0.01


def test_angle_and_target_pixel_near_centre(flights):
    truth = json.loads((flights["ros2-mcap"] / "truth.json").read_text())
    assert truth["intersection_angle_deg"] == pytest.approx(12.0, abs=1e-6)
    for f in truth["frames"]:
        u, v = f["true_target_pixel"]
        assert f["target_visible"] and abs(u - 301.7) < 25 and abs(v - 198.4) < 25  # tracked, with jitter


def test_bag_images_and_video_decode(flights):
    truth = json.loads((flights["ros2-sqlite3"] / "truth.json").read_text())
    with AnyReader([flights["ros2-sqlite3"] / "flight_ros2"]) as r:
        conns = [c for c in r.connections if c.topic == "/uav/camera/image/compressed"]
        stamps, shapes = [], []
        for c, t, raw in r.messages(connections=conns):
            m = r.deserialize(raw, c.msgtype)
            assert m.format == "jpeg"
            shapes.append(cv2.imdecode(np.asarray(m.data), cv2.IMREAD_COLOR).shape)
            stamps.append(t)
    assert shapes == [(400, 600, 3)] * len(truth["frames"])
    assert stamps == [f["t_ns"] for f in truth["frames"]]
    assert truth["metadata"]["clock"]["video_to_telemetry_offset_ns"] == 0

    folder = flights["tlog"]
    truth = json.loads((folder / "truth.json").read_text())
    cap = cv2.VideoCapture(str(folder / "video.mp4"))
    n = int(cap.get(cv2.CAP_PROP_FRAME_COUNT))
    ok, img = cap.read()
    cap.release()
    assert ok and img.shape == (400, 600, 3) and n == len(truth["frames"])
    rows = (folder / "video.frames.csv").read_text().split()
    assert rows[0] == "frame_index,pts_ns"
    offset = truth["metadata"]["clock"]["video_to_telemetry_offset_ns"]
    for row, f in zip(rows[1:], truth["frames"], strict=True):
        i, pts = map(int, row.split(","))
        assert i == f["frame_index"] and pts + offset == f["t_ns"]


def test_tlog_carries_standard_messages(flights):
    from pipeline.synth.writers.tlog import tlog_summary
    counts = tlog_summary(flights["tlog"] / "flight.tlog")
    assert {"HEARTBEAT", "SYSTEM_TIME", "GLOBAL_POSITION_INT", "ATTITUDE", "GIMBAL_DEVICE_ATTITUDE_STATUS",
            "CAMERA_TRACKING_GEO_STATUS"} <= set(counts)
    assert counts["ATTITUDE"] > 4 * counts["GLOBAL_POSITION_INT"] > 16 * counts["CAMERA_TRACKING_GEO_STATUS"]
    conn = mavutil.mavlink_connection(str(flights["tlog"] / "flight.tlog"), dialect="ardupilotmega")
    m = conn.recv_match(type="SYSTEM_TIME")
    assert m.time_unix_usec == round(m._timestamp * 1e6)
    conn.close()


def test_noisy_telemetry_has_the_stated_errors(tmp_path):
    """Position, pointing and range errors of a noisy flight, measured against the truth, match the config:
    ~2 m per axis (drift + white), 0.2 deg per axis on the gimbal (plus the vehicle's on the lever arm), 5 m."""
    # short correlation times so that 60 observations sample the errors' spread
    noise = {"laser_dropout": 0.0, "attitude_tau_s": 5.0, "gnss_tau_s": 10.0}
    cfg = SynthConfig.from_dict({"group": "noisy", "seed": 11, "format": "mcap", "scene": SMALL_SCENE,
                                 "observations": {"count": 60, "spacing_s": 4}, "video": {"burst_frames": 1},
                                 "path": {"intersection_angle_deg": 80.0}, "noise": noise})
    folder = generate(cfg, tmp_path / "noisy").out_dir
    truth = json.loads((folder / "truth.json").read_text())
    logs = read_mcap(folder / "flight.mcap")
    err = logs["las"][:, 1] - np.array(truth["laser_shots"]["range_true_m"])
    assert 4.5 < err.std() < 5.5 and abs(err.mean()) < 1.0, (err.std(), err.mean())
    obs_t = np.array([o["t_ns"] for o in truth["observations"]])
    frames = [truth["frames"][o["frame_index"]] for o in truth["observations"]]
    camera, _, R_ecef_optical = reconstruct(truth, logs, obs_t)
    pos_err = camera - np.array([f["camera_position_ecef_m"] for f in frames])
    pos_rms = np.sqrt((pos_err ** 2).sum(axis=1).mean() / 3)
    assert 1.2 < pos_rms < 3.0, pos_rms  # per axis; 1.97 m stated
    ang = [Rotation.from_matrix(R.T @ np.array(f["R_ecef_from_optical"])).magnitude()
           for R, f in zip(R_ecef_optical, frames, strict=True)]
    per_axis_deg = np.degrees(np.sqrt(np.mean(np.square(ang)) / 3))
    assert 0.12 < per_axis_deg < 0.3, per_axis_deg


def test_rendered_target_and_sift(tmp_path):
    """The cross target appears where truth.json says; frames have SIFT features that match between bursts."""
    cfg = SynthConfig.from_dict({"group": "r", "seed": 3, "observations": {"count": 3},
                                 "path": {"intersection_angle_deg": 6.0}, "video": {"burst_frames": 2},
                                 "scene": {"texture_px": 2048, "texture_res_m": 3.0}})
    folder = generate(cfg, tmp_path / "r").out_dir
    truth = json.loads((folder / "truth.json").read_text())
    cap = cv2.VideoCapture(str(folder / "video.mp4"))
    imgs = []
    while (ok_img := cap.read())[0]:
        imgs.append(ok_img[1])
    grey = [cv2.cvtColor(i, cv2.COLOR_BGR2GRAY).astype(np.float32) for i in imgs]
    for g, f in zip(grey, truth["frames"], strict=True):
        u, v = (round(x) for x in f["true_target_pixel"])
        win = g[v - 12:v + 13, u - 12:u + 13]
        bright = win > np.percentile(win, 93)
        ys, xs = np.nonzero(bright)
        assert win.max() > 190  # the white panel stands out from the fields
        assert abs(xs.mean() - 12 - (f["true_target_pixel"][0] - u)) < 2.0
        assert abs(ys.mean() - 12 - (f["true_target_pixel"][1] - v)) < 2.0
    sift = cv2.SIFT_create()
    k1, d1 = sift.detectAndCompute(imgs[0], None)
    k2, d2 = sift.detectAndCompute(imgs[2], None)  # first frame of the next burst, seconds later
    assert len(k1) > 200 and len(k2) > 200
    good = [a for a, b in cv2.BFMatcher().knnMatch(d1, d2, k=2) if a.distance < 0.75 * b.distance]
    p1 = np.float32([k1[a.queryIdx].pt for a in good])
    p2 = np.float32([k2[a.trainIdx].pt for a in good])
    H, inliers = cv2.findHomography(p1, p2, cv2.RANSAC, 3.0)
    assert H is not None and inliers.sum() > 50
