"""Plain MCAP: JSON channels (the synthetic-flight layout), ROS 2 CDR channels, truncation and garbage."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from pipeline.errors import LogReadError
from pipeline.ingest import read_flight
from support.writers import ros_message, write_json_mcap

T0 = 1_700_000_000_000_000_000


def _msgs(n=30):
    c, s = math.cos(math.radians(20)), math.sin(math.radians(20))
    return {
        "/uav/gps": [{"t_ns": T0 + i * 10**8, "latitude_deg": 46.5 + i * 1e-6, "longitude_deg": 7.25,
                      "altitude_m": 1500.5, "altitude_datum": "ellipsoid"} for i in range(n)],
        # yaw 40 deg about NED z: q = (cos 20, 0, 0, sin 20)
        "/uav/attitude": [{"t_ns": T0 + i * 10**8 + 1, "q_wxyz": [c, 0, 0, s], "frame": "body_frd_to_ned"}
                          for i in range(n)],
        "/uav/gimbal": [{"t_ns": T0 + i * 10**8 + 2, "q_wxyz": [1, 0, 0, 0], "frame": "gimbal_frd_to_ned",
                         "yaw_in_vehicle_frame": i % 2 == 1} for i in range(n)],
        "/uav/laser": [{"t_ns": T0 + i * 10**8 + 3, "range_m": 1234.5 if i % 3 else None, "valid": i % 3 != 0}
                       for i in range(n)],
    }


def test_json_mcap(tmp_path):
    p = tmp_path / "flight.mcap"
    write_json_mcap(p, _msgs())
    log = read_flight([p])
    assert log.position.alt_datum == "ellipsoid" and log.position.t_ns[0] == T0
    assert log.position.lat_deg[1] == pytest.approx(46.500001)
    heading = Rotation.from_quat(log.attitude.quat_wxyz[0], scalar_first=True).apply([1, 0, 0])
    np.testing.assert_allclose(heading, [math.cos(math.radians(40)), math.sin(math.radians(40)), 0], atol=1e-12)
    assert log.gimbal.yaw_in_vehicle_frame[:3].tolist() == [False, True, False]
    assert log.range.valid[:3].tolist() == [False, True, True] and np.isnan(log.range.range_m[0])
    assert log.missing_for_localization() == ["frames"]
    streams = {s.name: s for s in log.streams}
    assert streams["/uav/gps"].count == 30 and streams["/uav/gps"].supplies == ("position",)


def test_json_mcap_field_mapping_override(tmp_path):
    p = tmp_path / "renamed.mcap"
    msgs = {"/drone/fix": [{"time": T0 + i, "lat": 1.0, "lon": 2.0, "h": 3.0} for i in range(3)]}
    write_json_mcap(p, {"/drone/fix": [dict(m, t_ns=m["time"]) for m in msgs["/drone/fix"]]})
    mapping = {"mcap": {"position": {"topic": "/drone/fix", "default_datum": "amsl",
                                     "fields": {"lat_deg": "lat", "lon_deg": "lon", "alt_m": "h", "t_ns": "time"}}}}
    log = read_flight([p], mapping=mapping)
    assert log.position.alt_datum == "amsl" and log.position.alt_m.tolist() == [3.0, 3.0, 3.0]


def test_ros2_cdr_channels_in_plain_mcap(tmp_path):
    from mcap_ros2.writer import Writer as Ros2Writer
    from rosbags.typesys import Stores, get_typestore

    ts = get_typestore(Stores.ROS2_HUMBLE)
    p = tmp_path / "ros2.mcap"
    with open(p, "wb") as f:
        w = Ros2Writer(f)
        ty, _ = ros_message("navsat", T0, lat=1.0, lon=2.0, alt=3.0)
        schema = w.register_msgdef(ty, ts.generate_msgdef(ty, ros_version=2)[0])
        for i in range(4):
            msg = {"header": {"stamp": {"sec": T0 // 10**9, "nanosec": i}, "frame_id": "gps"},
                   "status": {"status": 0, "service": 1}, "latitude": 10.0 + i, "longitude": 20.0,
                   "altitude": 30.0, "position_covariance": [0.0] * 9, "position_covariance_type": 0}
            w.write_message("/uav/gps/fix", schema, msg, log_time=T0 + i, publish_time=T0 + i)
        w.finish()
    log = read_flight([p])
    assert log.position.lat_deg.tolist() == [10.0, 11.0, 12.0, 13.0]
    assert log.position.alt_datum == "ellipsoid" and log.position.t_ns[1] == T0 + 1


def test_truncated_and_garbage_mcap(tmp_path):
    p = tmp_path / "flight.mcap"
    write_json_mcap(p, _msgs(200), chunk_size=4096)
    data = p.read_bytes()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[: int(len(data) * 0.6)])
    log = read_flight([cut])
    assert any("reading stopped after" in w for w in log.warnings)
    assert 50 < log.position.t_ns.size < 200
    g = tmp_path / "g.mcap"
    g.write_bytes(b"\x89MCAP0\r\n" + bytes(range(256)) * 8)
    with pytest.raises(LogReadError, match=r"g\.mcap: not a readable MCAP"):
        read_flight([g])
    e = tmp_path / "e.mcap"
    e.write_bytes(b"")
    with pytest.raises(LogReadError, match=r"e\.mcap: empty file"):
        read_flight([e])


def test_mcap_wrong_datum_rejected(tmp_path):
    p = tmp_path / "d.mcap"
    write_json_mcap(p, {"/uav/gps": [{"t_ns": T0, "latitude_deg": 1, "longitude_deg": 2, "altitude_m": 3,
                                      "altitude_datum": "egm96"}]})
    with pytest.raises(LogReadError, match=r"altitude datum \['egm96'\]"):
        read_flight([p])


_ = Path
