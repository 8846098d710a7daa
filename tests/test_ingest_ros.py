"""ROS 1 / ROS 2 bags: REP-103 frame conversion, units, validity, topic mapping, images, real bags, bad input."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import cv2
import numpy as np
import pytest
from rosbags.highlevel import AnyReader
from rosbags.typesys import Stores, get_typestore
from scipy.spatial.transform import Rotation

from pipeline.errors import ConfigError, LogReadError
from pipeline.ingest import BagImages, read_flight
from support.writers import ros_message, write_ros_bag

LOGS = Path(__file__).resolve().parents[1] / ".." / "shared" / "logs"
T0 = 1_700_000_000_000_000_000
S15, C15 = math.sin(math.radians(15)), math.cos(math.radians(15))
S45 = math.sin(math.pi / 4)


def _rows(n=8, gps_topic="/uav/gps/fix"):
    rows = []
    for i in range(n):
        t = T0 + i * 100_000_000
        rows.append((gps_topic, t + 50, *ros_message("navsat", t, lat=47.0 + i * 1e-5, lon=8.5, alt=512.25,
                                                     status=-1 if i == 0 else 0)))
        # vehicle heading north, level: REP-103 yaw 90 deg about ENU z
        rows.append(("/uav/imu", t + 51, *ros_message("imu", t + 1, q_xyzw=[0, 0, S45, S45])))
        # gimbal pointing east (ENU yaw 0), pitched 30 deg down: +30 deg about FLU y (left)
        rows.append(("/uav/gimbal/attitude", t + 52, *ros_message("quat", t + 2, q_xyzw=[0, S15, 0, C15])))
        rows.append(("/uav/laser/range", t + 53, *ros_message(
            "range", t + 3, range=[812.5, math.inf, 0.5, 6000.0][i % 4], min_range=1.0, max_range=5000.0)))
    return rows


@pytest.mark.parametrize("storage", ["ros1", "sqlite3", "mcap"])
def test_bag_frames_units_validity(tmp_path, storage):
    path = tmp_path / ("f.bag" if storage == "ros1" else "f_ros2")
    write_ros_bag(path, _rows(), storage)
    log = read_flight([path])
    assert log.formats == ["ros1" if storage == "ros1" else "ros2"]
    # status -1 (no fix) dropped; header.stamp, not record time
    assert log.position.t_ns.size == 7 and log.position.t_ns[0] == T0 + 100_000_000
    assert log.position.alt_datum == "ellipsoid" and log.position.alt_m[0] == 512.25
    assert any("1 of 8 /uav/gps/fix messages without a GPS fix dropped" in w for w in log.warnings)
    # heading north level in ROS (ENU yaw 90) = identity FRD -> NED
    np.testing.assert_allclose(log.attitude.quat_wxyz[0], [1, 0, 0, 0], atol=1e-12)
    # gimbal east and 30 deg down: optical axis (FRD x) -> NED (0, cos30, +sin30)
    fwd = Rotation.from_quat(log.gimbal.quat_wxyz[0], scalar_first=True).apply([1, 0, 0])
    np.testing.assert_allclose(fwd, [0, math.cos(math.radians(30)), 0.5], atol=1e-12)
    assert not log.gimbal.yaw_in_vehicle_frame.any()
    # range: inside [1, 5000] valid; +inf, below min, above max invalid
    assert log.range.valid[:4].tolist() == [True, False, False, False]
    assert log.range.range_m[0] == 812.5


def test_topic_fallback_override_and_by_type(tmp_path):
    path = tmp_path / "f.bag"
    write_ros_bag(path, _rows(4, gps_topic="/mavros/global_position/global"), "ros1")
    assert read_flight([path]).position.source.endswith("/mavros/global_position/global")
    path2 = tmp_path / "g.bag"
    write_ros_bag(path2, _rows(4, gps_topic="/my/odd/fix"), "ros1")
    log = read_flight([path2])
    assert log.position.source.endswith("/my/odd/fix")
    assert any("the only sensor_msgs/msg/NavSatFix topic" in w for w in log.warnings)
    log = read_flight([path2], mapping={"ros": {"position": {"topic": "/nothing", "by_type": False}}})
    assert log.position is None and "position" in log.missing_for_localization()
    log = read_flight([path2], mapping={"ros": {"position": {"topic": "/my/odd/fix"}}})
    assert not any("NavSatFix" in w for w in log.warnings)
    with pytest.raises(ConfigError, match="unknown key 'topik'"):
        read_flight([path2], mapping={"ros": {"position": {"topik": "/x"}}})
    with pytest.raises(ConfigError, match="unknown format 'rosbag'"):
        read_flight([path2], mapping={"rosbag": {}})


def test_images_in_bag_decode_only_requested(tmp_path):
    rng = np.random.default_rng(3)
    imgs = [rng.integers(0, 255, (24, 32, 3), dtype=np.uint8) for _ in range(5)]
    rows = []
    for i, img in enumerate(imgs):
        _, jpg = cv2.imencode(".png", img)  # lossless, so decoded pixels compare exactly
        rows.append(("/uav/camera/image/compressed", T0 + i * 10**8 + 7,
                     *ros_message("compressed", T0 + i * 10**8, data=jpg.tobytes(), format="png")))
    rows.append(("/uav/camera/camera_info", T0, *ros_message(
        "camera_info", T0, width=32, height=24, d=[0.1, -0.2, 0, 0, 0], k=[[40, 0, 16], [0, 41, 12], [0, 0, 1]],
        p=[[40, 0, 16, 0], [0, 41, 12, 0], [0, 0, 1, 0]])))
    path = tmp_path / "img.bag"
    write_ros_bag(path, rows, "ros1")
    log = read_flight([path])
    assert log.frames.t_ns.tolist() == [T0 + i * 10**8 for i in range(5)]
    assert (log.frames.width_px, log.frames.height_px) == (32, 24) and log.frames.clock == "unix"
    assert log.camera_info.K[1, 1] == 41 and log.camera_info.D[0] == pytest.approx(0.1)
    bag = BagImages(path)
    got = bag.read([3, 1])
    assert sorted(got) == [1, 3]
    np.testing.assert_array_equal(got[3], imgs[3])
    with pytest.raises(LogReadError, match="no message 9"):
        bag.read([9])


@pytest.mark.parametrize("encoding", ["mono8", "rgb8", "bgr8", "mono16"])
def test_raw_image_encodings(tmp_path, encoding):
    rng = np.random.default_rng(4)
    if encoding == "mono16":
        img = rng.integers(0, 65535, (6, 10), dtype=np.uint16)
    elif encoding == "mono8":
        img = rng.integers(0, 255, (6, 10), dtype=np.uint8)
    else:
        img = rng.integers(0, 255, (6, 10, 3), dtype=np.uint8)
    path = tmp_path / "raw_ros2"
    write_ros_bag(path, [("/uav/camera/image", T0, *ros_message("image", T0, img=img, encoding=encoding))],
                  "sqlite3")
    out = BagImages(path).read([0])[0]
    expect = img[:, :, ::-1] if encoding == "rgb8" else img
    np.testing.assert_array_equal(out, expect)


def test_real_ros1_navsatfix_bag_against_raw_rosbags():
    path = LOGS / "rviz_satellite_sample_gps.bag"
    with AnyReader([path], default_typestore=get_typestore(Stores.ROS2_HUMBLE)) as r:
        conn = r.connections[0]
        _, _, raw = next(iter(r.messages(connections=[conn])))
        first = r.deserialize(raw, conn.msgtype)
    log = read_flight([path])
    assert log.position.t_ns.size == 151
    assert log.position.t_ns[0] == first.header.stamp.sec * 10**9 + first.header.stamp.nanosec
    assert log.position.lat_deg[0] == first.latitude and log.position.lon_deg[0] == first.longitude
    assert log.position.alt_datum == "ellipsoid"
    assert log.missing_for_localization() == ["attitude", "gimbal", "range", "frames"]


def test_real_ros1_compressed_image_and_camera_info():
    path = LOGS / "ubiquity_fiducials_aruco_marker.bag"
    log = read_flight([path])
    assert (log.frames.width_px, log.frames.height_px) == (1280, 720)
    ci = log.camera_info
    assert (ci.width_px, ci.height_px) == (1280, 720) and ci.distortion_model == "plumb_bob"
    assert ci.K[0, 0] == pytest.approx(1276.704618) and ci.K[0, 2] == pytest.approx(634.8876509)
    assert ci.P.shape == (3, 4) and ci.D.shape == (5,)
    img = BagImages(path).read([0])[0]
    assert img.shape == (720, 1280, 3)


def test_real_ros2_talker_qos_mismatch_is_reported():
    path = LOGS / "rosbag2_talker_mcap"
    from pipeline.ingest import inspect_paths
    (res,) = inspect_paths([path])
    counts = {s.name: s.count for s in res.log.streams}
    assert counts == {"/topic": 10, "/rosout": 10, "/parameter_events": 0}
    assert any("iterated 0 of 20 messages that metadata.yaml lists on /rosout, /topic" in w
               for w in res.log.warnings)
    assert res.log.missing_for_localization() == ["position", "attitude", "gimbal", "range", "frames"]


def test_bad_bags(tmp_path):
    g = tmp_path / "garbage.bag"
    g.write_bytes(b"#ROSBAG V2.0\n" + bytes(range(256)) * 4)
    with pytest.raises(LogReadError, match=r"garbage\.bag: cannot open bag"):
        read_flight([g])
    # a connection whose message definition is missing (empty) and whose hash does not match
    from rosbags.rosbag1 import Writer
    ts = get_typestore(Stores.ROS2_HUMBLE)
    ty, msg = ros_message("navsat", T0, lat=1.0, lon=2.0, alt=3.0)
    md = tmp_path / "nodef.bag"
    with Writer(md) as w:
        c = w.add_connection("/uav/gps/fix", ty, msgdef="", md5sum="0" * 32)
        w.write(c, T0, ts.serialize_ros1(msg, ty))
    with pytest.raises(LogReadError, match=r"nodef\.bag: cannot decode /uav/gps/fix .*message definition missing"):
        read_flight([md])
    # a ROS 1 bag cut off while recording (no index): read by scanning, with a warning saying how much
    full = tmp_path / "full.bag"
    write_ros_bag(full, _rows(40), "ros1")
    cut = tmp_path / "cut.bag"
    cut.write_bytes(full.read_bytes()[: full.stat().st_size // 2])
    log = read_flight([cut])
    assert any("rosbags cannot open it (Bag index looks damaged" in w and "file ends inside a record" in w
               and "covering" in w for w in log.warnings)
    assert 10 < log.position.t_ns.size < 40 and log.position.lat_deg[0] == pytest.approx(47.00001)
    assert log.attitude.t_ns.size >= log.position.t_ns.size - 1
    tiny = tmp_path / "tiny.bag"
    tiny.write_bytes(full.read_bytes()[:40])
    with pytest.raises(LogReadError, match=r"tiny\.bag: cannot open bag"):
        read_flight([tiny])
    folder = tmp_path / "empty_folder"
    folder.mkdir()
    with pytest.raises(LogReadError, match="not a ROS 2 bag"):
        read_flight([folder])


def test_no_fix_at_all(tmp_path):
    rows = [("/uav/gps/fix", T0 + i, *ros_message("navsat", T0 + i, lat=0.0, lon=0.0, alt=0.0, status=-1))
            for i in range(3)]
    path = tmp_path / "nofix.bag"
    write_ros_bag(path, rows, "ros1")
    log = read_flight([path])
    assert log.position is None
    assert any("no GPS fix in 3 /uav/gps/fix messages" in w for w in log.warnings)


def test_ros2_mcap_bag_cut_off(tmp_path):
    path = tmp_path / "cut_ros2"
    blob = np.random.default_rng(5).integers(0, 255, 40_000, dtype=np.uint8).tobytes()
    images = [("/uav/camera/image/compressed", T0 + i * 10**8 + 60, *ros_message("compressed", T0 + i * 10**8,
                                                                                data=blob)) for i in range(200)]
    write_ros_bag(path, _rows(200) + images, "mcap")  # 8 MB: several MCAP chunks
    (f,) = path.glob("*.mcap")
    data = f.read_bytes()
    f.write_bytes(data[: int(len(data) * 0.6)])
    log = read_flight([path])
    assert log.warnings[0].startswith(f"{path}: rosbags cannot open it")
    assert any("reading stopped after" in w for w in log.warnings)
    assert 20 < log.position.t_ns.size < 199 and log.position.t_ns[0] == T0 + 100_000_000
    np.testing.assert_allclose(log.attitude.quat_wxyz[0], [1, 0, 0, 0], atol=1e-12)


def _image_rows(n=12):
    rows = []
    for i in range(n):
        img = np.full((16, 24, 3), i * 20, np.uint8)
        _, png = cv2.imencode(".png", img)
        rows.append(("/uav/camera/image/compressed", T0 + i * 10**8 + 9,
                     *ros_message("compressed", T0 + i * 10**8, data=png.tobytes(), format="png")))
    return rows


def test_bag_images_from_cut_ros1_bag_and_plain_mcap(tmp_path):
    full = tmp_path / "img.bag"
    write_ros_bag(full, _image_rows() + _rows(12), "ros1")
    cut = tmp_path / "img_cut.bag"
    cut.write_bytes(full.read_bytes()[: int(full.stat().st_size * 0.7)])
    bag = BagImages(cut)
    n = bag.frames.t_ns.size
    assert 3 < n < 12 and bag.frames.t_ns[1] == T0 + 10**8
    assert bag.read([n - 1])[n - 1][0, 0, 0] == (n - 1) * 20

    from mcap_ros2.writer import Writer as Ros2Writer
    from rosbags.typesys import Stores, get_typestore

    ts = get_typestore(Stores.ROS2_HUMBLE)
    p = tmp_path / "images.mcap"
    ty = "sensor_msgs/msg/CompressedImage"
    with open(p, "wb") as f:
        w = Ros2Writer(f)
        schema = w.register_msgdef(ty, ts.generate_msgdef(ty, ros_version=2)[0])
        for i in range(5):
            _, png = cv2.imencode(".png", np.full((8, 10), 40 * i, np.uint8))
            w.write_message("/cam/compressed", schema, {"header": {"stamp": {"sec": 1_700_000_000, "nanosec": i},
                                                                   "frame_id": "cam"},
                                                        "format": "png", "data": png.tobytes()},
                            log_time=T0 + i, publish_time=T0 + i)
        w.finish()
    log = read_flight([p])
    assert log.frames.t_ns.tolist() == [T0 + i for i in range(5)] and log.frames.width_px == 10
    imgs = BagImages(p).read([4, 2])
    assert imgs[4][0, 0] == 160 and imgs[2].shape == (8, 10)


def test_bag_images_reuse_the_frame_index_read_flight_built():
    bag = Path(__file__).resolve().parents[1] / "sample_data" / "group4" / "flight_ros2"
    log = read_flight([bag])
    reused = BagImages(bag, frames=log.frames)
    scanned = BagImages(bag)
    assert reused.frames is log.frames
    np.testing.assert_array_equal(scanned.frames.t_ns, reused.frames.t_ns)
    a, b = reused.read([5, 40]), scanned.read([5, 40])
    assert sorted(a) == [5, 40] and all(np.array_equal(a[i], b[i]) for i in (5, 40))
    # A frame index of another stream is not taken for this one.
    other = dataclasses.replace(log.frames, source="elsewhere:/topic")
    assert BagImages(bag, frames=other).frames is not other
