"""PX4 ULog and ArduPilot DataFlash readers on the real logs, checked against raw pyulog / DFReader values."""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from pipeline.errors import LogReadError
from pipeline.ingest import read_file, read_flight

LOGS = Path(__file__).resolve().parents[1] / ".." / "shared" / "logs"


def _raw_ulog(name, topic):
    from pyulog import ULog
    return ULog(str(LOGS / name), message_name_filter_list=[topic]).get_dataset(topic).data


def test_ulog_old_gps_int_fields_and_attitude():
    name = "px4_pyulog_sample_log_small.ulg"
    gps = _raw_ulog(name, "vehicle_gps_position")
    att = _raw_ulog(name, "vehicle_attitude")
    log = read_flight([LOGS / name])
    pos = log.position
    assert pos.source.endswith("vehicle_gps_position") and pos.clock == "unix"
    # int 1e-7 deg and mm (old vehicle_gps_position), ellipsoid height by default
    assert pos.lat_deg[0] == pytest.approx(gps["lat"][0] * 1e-7, abs=1e-12) == pytest.approx(63.4170622)
    assert pos.lon_deg[0] == pytest.approx(10.4082151)
    assert pos.alt_datum == "ellipsoid" and pos.alt_m[0] == pytest.approx(106.766)
    # boot -> UNIX through time_utc_usec: the first fix's UTC time within 50 ms
    assert abs(pos.t_ns[0] - int(gps["time_utc_usec"][0]) * 1000) < 50_000_000
    q_raw = np.array([att[f"q[{i}]"][0] for i in range(4)])
    q = log.attitude.quat_wxyz[0]
    np.testing.assert_allclose(q, q_raw * np.sign(q_raw[0]), atol=1e-7)
    assert log.attitude.t_ns.size == 1298
    amsl = read_flight([LOGS / name], mapping={"ulog": {"position": {"datum": "amsl"}}}).position
    assert amsl.alt_datum == "amsl" and amsl.alt_m[0] == pytest.approx(66.814)


def test_ulog_new_topics_and_global_position():
    log = read_flight([LOGS / "foxglove_mcap_test_ulog.ulg"])
    gp = _raw_ulog("foxglove_mcap_test_ulog.ulg", "vehicle_global_position")
    assert log.position.source.endswith("vehicle_global_position")
    assert log.position.lat_deg[0] == gp["lat"][0] and log.position.t_ns.size == 34
    assert log.position.alt_m[0] == pytest.approx(float(gp["alt_ellipsoid"][0]))
    log2 = read_flight([LOGS / "px4_pyulog_tagged_default_params.ulg"])
    assert log2.position.source.endswith("vehicle_gps_position")
    assert log2.position.lat_deg[0] == pytest.approx(47.397, abs=1e-3)
    assert log2.attitude.t_ns.size == 1730
    assert log2.missing_for_localization() == ["gimbal", "range", "frames"]
    raw = _raw_ulog("px4_pyulog_tagged_default_params.ulg", "vehicle_gps_position")
    no_fix = int((raw["fix_type"] < 3).sum())  # the samples without a 3-D fix, counted from pyulog's own read
    assert no_fix == 160 and log2.position.t_ns.size == len(raw["fix_type"]) - no_fix
    assert sum(f"{no_fix} of {len(raw['fix_type'])} vehicle_gps_position messages dropped: no fix" in w
               for w in log2.warnings) == 1
    assert not any("dropped: no fix" in w for w in log.warnings)


def test_global_positions_without_coordinates_are_not_said_to_lack_a_fix():
    """vehicle_global_position has no fix_type: its dropped samples lack coordinates, and the warning says that
    (not 'fix_type below 3', a field the topic does not have)."""
    from pipeline.ingest.mapping import mapping_for
    from pipeline.ingest.model import FlightLog
    from pipeline.ingest.ulog import fill_from_topics

    n = 10
    lat = np.full(n, 47.4)
    lat[:3] = np.nan
    data = {"vehicle_global_position": {"timestamp": np.arange(n, dtype=np.uint64) * 100_000, "lat": lat,
                                        "lon": np.full(n, 8.5), "alt": np.full(n, 500.0),
                                        "alt_ellipsoid": np.full(n, 550.0)}}
    log = FlightLog(path="x.ulg", formats=["ulog"])
    fill_from_topics(log, data, mapping_for("ulog"), Path("x.ulg"))
    assert log.position.t_ns.size == 7
    (w,) = [w for w in log.warnings if "dropped" in w]
    assert w == "x.ulg: 3 of 10 vehicle_global_position messages dropped: no coordinates (NaN or 0, 0)"


def test_ulog_truncated_and_garbage(tmp_path):
    data = (LOGS / "px4_pyulog_tagged_default_params.ulg").read_bytes()
    cut = tmp_path / "cut.ulg"
    cut.write_bytes(data[: len(data) // 2])
    log = read_flight([cut])
    assert 0 < log.attitude.t_ns.size < 1730
    assert any("corrupt or cut off" in w and "covering" in w for w in log.warnings)
    # the sample log cut after about a second of its streams, read as `ridgeloc inspect` reads it (every topic)
    # and for a flight: the warning's span is that of the streams read, as inspect lists them, not pyulog's
    # last_timestamp - start_timestamp (1174 s: the log's one `mission` message is stamped 1194 s)
    short = tmp_path / "short.ulg"
    short.write_bytes((LOGS / "px4_pyulog_sample_log_small.ulg").read_bytes()[:100_000])
    for log, topics in ((read_file(short, scan_all=True), "every topic"), (read_flight([short]), "the selected")):
        (warning,) = [w for w in log.warnings if "corrupt or cut off" in w]
        assert f"messages of {topics}" in warning
        covering_s = float(re.search(r"covering ([0-9.]+) s", warning).group(1))
        streams = [st for st in log.streams if st.count >= 2]
        listed_s = (max(st.t_last_ns for st in streams) - min(st.t_first_ns for st in streams)) / 1e9
        assert covering_s == pytest.approx(listed_s, abs=0.05) and covering_s < 2.0
        assert covering_s >= (log.attitude.t_ns[-1] - log.attitude.t_ns[0]) / 1e9 - 0.05
    bad = tmp_path / "bad.ulg"
    bad.write_bytes(b"ULog\x01\x12\x35" + bytes(range(256)) * 3)
    with pytest.raises(LogReadError, match=r"bad\.ulg: "):
        read_flight([bad])


def test_dataflash_truncated_real_log():
    from pymavlink import DFReader

    path = LOGS / "ardupilot_pymavlink_test.BIN"
    raw = DFReader.DFReader_binary(str(path), zero_time_base=True)
    gps = raw.recv_match(type="GPS")
    raw.rewind()
    att = raw.recv_match(type="ATT")
    log = read_flight([path])
    assert any("truncated" in w and "1.0 s" in w for w in log.warnings)
    pos = log.position
    assert pos.alt_datum == "amsl" and pos.clock == "unix" and pos.t_ns.size == 5
    assert (pos.lat_deg[0], pos.lon_deg[0], pos.alt_m[0]) == (gps.Lat, gps.Lng, gps.Alt)
    assert pos.lat_deg[0] == pytest.approx(-35.3626277)
    # GPS week 1973, 6448000 ms: 315964800 + 1973 * 604800 + 6448 - 18 (leap) = 1509241630 s UTC
    assert (gps.GWk, gps.GMS) == (1973, 6448000)
    assert abs(pos.t_ns[0] - 1_509_241_630 * 10**9) < 20_000_000
    # ATT degrees, ZYX: roll -7.18, pitch 2.58, yaw 337.1
    r, p, y = map(math.radians, (att.Roll, att.Pitch, att.Yaw))
    fwd = Rotation.from_quat(log.attitude.quat_wxyz[0], scalar_first=True).apply([1, 0, 0])
    np.testing.assert_allclose(fwd, [math.cos(y) * math.cos(p), math.sin(y) * math.cos(p), -math.sin(p)], atol=1e-9)
    right = Rotation.from_quat(log.attitude.quat_wxyz[0], scalar_first=True).apply([0, 1, 0])
    assert right[2] == pytest.approx(math.sin(r) * math.cos(p), abs=1e-9)


def test_dataflash_garbage(tmp_path):
    g = tmp_path / "g.bin"
    g.write_bytes(b"\xa3\x95" + bytes(range(256)) * 4)
    with pytest.raises(LogReadError, match=r"g\.bin: "):
        read_flight([g])


def test_ulog_gimbal_flags_distance_sensor_units():
    """PX4 topics the real logs lack, as pyulog hands them over (columns of instance 0)."""
    from pipeline.ingest.mapping import mapping_for
    from pipeline.ingest.model import FlightLog
    from pipeline.ingest.ulog import fill_from_topics

    ts = np.array([1_000_000, 2_000_000, 3_000_000, 4_000_000], np.uint64)
    c, s = math.cos(math.radians(10)), math.sin(math.radians(10))  # pitch -20 deg about y: (cos -10, 0, sin -10, 0)
    data = {
        "gimbal_device_attitude_status": {
            "timestamp": ts, "device_flags": np.array([32, 64, 16, 0], np.uint16),
            "q[0]": np.full(4, c), "q[1]": np.zeros(4), "q[2]": np.full(4, -s), "q[3]": np.zeros(4)},
        "distance_sensor": {
            "timestamp": ts, "current_distance": np.array([12.5, 0.05, 70.0, 12.5], np.float32),
            "min_distance": np.full(4, 0.1, np.float32), "max_distance": np.full(4, 50.0, np.float32),
            "signal_quality": np.array([-1, 100, 100, 0], np.int8)},
        "vehicle_gps_position": {  # boot 1..4 s <-> UTC 1700000000..3 s
            "timestamp": ts, "time_utc_usec": (np.arange(4, dtype=np.uint64) + 1_700_000_000) * 1_000_000,
            "lat": np.full(4, 473977419, np.int32), "lon": np.full(4, 85455939, np.int32),
            "alt": np.full(4, 488000, np.int32), "alt_ellipsoid": np.full(4, 536000, np.int32),
            "fix_type": np.array([2, 3, 3, 3], np.uint8)},
    }
    log = FlightLog(path="x.ulg")
    fill_from_topics(log, data, mapping_for("ulog"), Path("x.ulg"))
    # flags: 32 vehicle, 64 earth, 16 (YAW_LOCK) earth, none: vehicle
    assert log.gimbal.yaw_in_vehicle_frame.tolist() == [True, False, False, True]
    ypr = Rotation.from_quat(log.gimbal.quat_wxyz[0], scalar_first=True).as_euler("ZYX", degrees=True)
    np.testing.assert_allclose(ypr, [0, -20, 0], atol=1e-9)
    # distance_sensor in metres; below min, above max, signal_quality 0 invalid (-1 = unknown is fine)
    np.testing.assert_allclose(log.range.range_m, [12.5, 0.05, 70.0, 12.5], rtol=1e-6)
    assert log.range.valid.tolist() == [True, False, False, False]
    # boot -> UNIX through time_utc_usec; fix_type 2 dropped; ellipsoid height by default
    assert log.range.clock == "unix" and log.range.t_ns[0] == 1_700_000_000 * 10**9
    assert log.position.t_ns.tolist() == [(1_700_000_000 + k) * 10**9 for k in (1, 2, 3)]
    assert log.position.alt_m[0] == pytest.approx(536.0) and log.position.alt_datum == "ellipsoid"


def test_ulog_distance_sensor_instances_by_orientation():
    """Instance 0 is the down-facing altimeter (orientation 25), instance 1 the forward laser: the laser is used."""
    from pipeline.ingest.mapping import mapping_for
    from pipeline.ingest.model import FlightLog
    from pipeline.ingest.ulog import fill_from_topics

    ts = np.array([1_000_000, 2_000_000], np.uint64)

    def sensor(dist, orient):
        return {"timestamp": ts, "current_distance": np.array(dist, np.float32),
                "min_distance": np.full(2, 0.1, np.float32), "max_distance": np.full(2, 3000.0, np.float32),
                "signal_quality": np.full(2, -1, np.int8), "orientation": np.full(2, orient, np.uint8)}

    data = {"distance_sensor": sensor([3.5, 3.6], 25), "distance_sensor[1]": sensor([1520.0, 1519.5], 0)}
    log = FlightLog(path="x.ulg")
    fill_from_topics(log, data, mapping_for("ulog"), Path("x.ulg"))
    np.testing.assert_allclose(log.range.range_m, [1520.0, 1519.5])
    log = FlightLog(path="x.ulg")
    fill_from_topics(log, {"distance_sensor": sensor([3.5, 3.6], 25)}, mapping_for("ulog"), Path("x.ulg"))
    assert log.range is None and any("2 of 2 distance_sensor samples with orientation 25 ignored" in w
                                     for w in log.warnings)
    data = {"distance_sensor": sensor([1500.0, 1500.5], 100), "distance_sensor[1]": sensor([1520.0, 1519.5], 0)}
    log = FlightLog(path="x.ulg")
    fill_from_topics(log, data, mapping_for("ulog"), Path("x.ulg"))  # two lasers: the lowest instance, a warning
    np.testing.assert_allclose(log.range.range_m, [1500.0, 1500.5])
    assert any("range from instance 0 (set ulog.range.instance" in w for w in log.warnings)
    log = FlightLog(path="x.ulg")
    fill_from_topics(log, data, mapping_for("ulog", {"ulog": {"range": {"instance": 1}}}), Path("x.ulg"))
    np.testing.assert_allclose(log.range.range_m, [1520.0, 1519.5])
