"""Small writers of each supported format, for tests and benchmarks (round trips through the real libraries)."""

from __future__ import annotations

import struct
from pathlib import Path
from typing import ClassVar

from pymavlink.dialects.v20 import ardupilotmega as mavlink


class _BinaryFile:
    """A binary output file `self.f`, closed by `close()` or at the end of a `with` block."""

    def close(self) -> None:
        self.f.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


class TlogWriter(_BinaryFile):
    """Write a MAVLink 2 .tlog: `write(t_us, msg)` appends the 8-byte big-endian UNIX us time + packet."""

    def __init__(self, path, src_system: int = 1, src_component: int = 1):
        self.f = open(Path(path), "wb")
        self.mav = mavlink.MAVLink(None, srcSystem=src_system, srcComponent=src_component)

    def write(self, t_us: int, msg, src_system: int | None = None, src_component: int | None = None) -> None:
        if src_system is not None:
            self.mav.srcSystem = src_system
        if src_component is not None:
            self.mav.srcComponent = src_component
        self.f.write(struct.pack(">Q", int(t_us)) + msg.pack(self.mav))


def write_json_mcap(path, messages: dict[str, list[dict]], chunk_size: int = 1024 * 1024) -> None:
    """Plain MCAP with one JSON channel per topic (jsonschema schema); log_time = publish_time = msg["t_ns"]."""
    import json

    from mcap.writer import Writer

    with open(Path(path), "wb") as f:
        w = Writer(f, chunk_size=chunk_size)
        w.start()
        chans = {}
        for topic in messages:
            sid = w.register_schema(name=topic.strip("/").replace("/", "_"), encoding="jsonschema",
                                    data=json.dumps({"type": "object"}).encode())
            chans[topic] = w.register_channel(topic=topic, message_encoding="json", schema_id=sid)
        rows = sorted(((m["t_ns"], topic, m) for topic, msgs in messages.items() for m in msgs),
                      key=lambda r: r[0])
        for t, topic, m in rows:
            w.add_message(chans[topic], log_time=int(t), publish_time=int(t), data=json.dumps(m).encode())
        w.finish()


def ros_message(kind: str, t_ns: int, **kw):
    """Build one ROS message (rosbags ROS 2 Humble types) by short kind name: navsat, imu, quat, range,
    compressed, image, camera_info. Returns (msgtype, message)."""
    import numpy as np
    from rosbags.typesys import Stores, get_typestore

    ts = get_typestore(Stores.ROS2_HUMBLE)
    T = ts.types
    header = T["std_msgs/msg/Header"](stamp=T["builtin_interfaces/msg/Time"](sec=int(t_ns // 10**9),
                                                                             nanosec=int(t_ns % 10**9)),
                                      frame_id=kw.get("frame_id", "base_link"))
    Q = T["geometry_msgs/msg/Quaternion"]
    V = T["geometry_msgs/msg/Vector3"]
    z9 = np.zeros(9)
    if kind == "navsat":
        st = T["sensor_msgs/msg/NavSatStatus"](status=kw.get("status", 0), service=1)
        return "sensor_msgs/msg/NavSatFix", T["sensor_msgs/msg/NavSatFix"](
            header=header, status=st, latitude=kw["lat"], longitude=kw["lon"], altitude=kw["alt"],
            position_covariance=z9, position_covariance_type=0)
    if kind == "imu":
        x, y, z, w = kw["q_xyzw"]
        cov = np.zeros(9)
        cov[0] = kw.get("cov0", 0.0)
        return "sensor_msgs/msg/Imu", T["sensor_msgs/msg/Imu"](
            header=header, orientation=Q(x=x, y=y, z=z, w=w), orientation_covariance=cov,
            angular_velocity=V(x=0.0, y=0.0, z=0.0), angular_velocity_covariance=z9,
            linear_acceleration=V(x=0.0, y=0.0, z=9.81), linear_acceleration_covariance=z9)
    if kind == "quat":
        x, y, z, w = kw["q_xyzw"]
        return "geometry_msgs/msg/QuaternionStamped", T["geometry_msgs/msg/QuaternionStamped"](
            header=header, quaternion=Q(x=x, y=y, z=z, w=w))
    if kind == "range":
        return "sensor_msgs/msg/Range", T["sensor_msgs/msg/Range"](
            header=header, radiation_type=1, field_of_view=0.001, min_range=kw.get("min_range", 1.0),
            max_range=kw.get("max_range", 5000.0), range=kw["range"])
    if kind == "compressed":
        return "sensor_msgs/msg/CompressedImage", T["sensor_msgs/msg/CompressedImage"](
            header=header, format=kw.get("format", "jpeg"), data=np.frombuffer(kw["data"], np.uint8))
    if kind == "image":
        img = kw["img"]
        return "sensor_msgs/msg/Image", T["sensor_msgs/msg/Image"](
            header=header, height=img.shape[0], width=img.shape[1], encoding=kw["encoding"], is_bigendian=0,
            step=img.strides[0], data=np.frombuffer(img.tobytes(), np.uint8))
    if kind == "camera_info":
        return "sensor_msgs/msg/CameraInfo", T["sensor_msgs/msg/CameraInfo"](
            header=header, height=kw["height"], width=kw["width"], distortion_model="plumb_bob",
            d=np.asarray(kw["d"], float), k=np.asarray(kw["k"], float).ravel(), r=np.eye(3).ravel(),
            p=np.asarray(kw["p"], float).ravel(), binning_x=0, binning_y=0,
            roi=T["sensor_msgs/msg/RegionOfInterest"](x_offset=0, y_offset=0, height=0, width=0, do_rectify=False))
    raise ValueError(kind)


def write_ros_bag(path, messages: list[tuple[str, int, str, object]], storage: str = "ros1") -> None:
    """Write (topic, record_time_ns, msgtype, message) rows to a ROS 1 .bag ("ros1") or a ROS 2 bag folder
    ("sqlite3" or "mcap" storage), through rosbags' writers."""
    from rosbags.typesys import Stores, get_typestore

    ts = get_typestore(Stores.ROS2_HUMBLE)
    path = Path(path)
    if storage == "ros1":
        from rosbags.rosbag1 import Writer

        writer, ser = Writer(path), lambda m, t: ts.serialize_ros1(m, t)
        open_kw = {}
    else:
        from rosbags.rosbag2 import StoragePlugin, Writer

        plugin = StoragePlugin.MCAP if storage == "mcap" else StoragePlugin.SQLITE3
        writer, ser = Writer(path, version=8, storage_plugin=plugin), lambda m, t: ts.serialize_cdr(m, t)
        open_kw = {}
    conns = {}
    with writer:
        for topic, t_ns, msgtype, msg in sorted(messages, key=lambda r: r[1]):
            if topic not in conns:
                conns[topic] = writer.add_connection(topic, msgtype, typestore=ts, **open_kw)
            writer.write(conns[topic], int(t_ns), ser(msg, msgtype))


class DataFlashWriter(_BinaryFile):
    """Minimal ArduPilot DataFlash (.bin) writer: FMT records then data records (`fmt()` then `write()`), with
    the firmware's format characters (e.g. L = int32 degE7, C = uint16 * 0.01), so DFReader's scaling applies."""

    _STRUCT: ClassVar[dict[str, str]] = {
        "B": "B", "b": "b", "H": "H", "h": "h", "I": "I", "i": "i", "f": "f", "d": "d", "Q": "Q", "q": "q",
        "n": "4s", "N": "16s", "Z": "64s", "c": "h", "C": "H", "e": "i", "E": "I", "L": "i", "M": "b"}

    def __init__(self, path):
        self.f = open(Path(path), "wb")
        self.formats: dict[str, tuple[int, str]] = {}
        self._write_fmt(128, "FMT", "BBnNZ", "Type,Length,Name,Format,Columns")

    def _struct(self, fmt: str) -> str:
        return "<" + "".join(self._STRUCT[c] for c in fmt)

    def _write_fmt(self, type_id: int, name: str, fmt: str, columns: str) -> None:
        length = 3 + struct.calcsize(self._struct(fmt))
        body = struct.pack("<BB4s16s64s", type_id, length, name.encode(), fmt.encode(), columns.encode())
        self.f.write(b"\xa3\x95\x80" + body)
        self.formats[name] = (type_id, fmt)

    def fmt(self, name: str, fmt: str, columns: str) -> None:
        self._write_fmt(129 + len(self.formats) - 1, name, fmt, columns)

    def write(self, name: str, *values) -> None:
        type_id, fmt = self.formats[name]
        self.f.write(bytes([0xA3, 0x95, type_id]) + struct.pack(self._struct(fmt), *values))


def dataflash_text_from_binary(src, dst, newline: str = "\n") -> int:
    """Write a binary DataFlash log as a text DataFlash log (`FMT, type, len, name, format, columns` lines, then
    `NAME, v1, v2, ...` with the values pymavlink decodes, scaled as Mission Planner prints them). Returns the
    number of data records written."""
    from pymavlink import DFReader

    df = DFReader.DFReader_binary(str(src), zero_time_base=True)
    n = 0
    with open(Path(dst), "w", newline="") as out:
        while (m := df.recv_msg()) is not None:
            if m.get_type() == "FMT":
                out.write(f"FMT, {m.Type}, {m.Length}, {m.Name}, {m.Format}, {m.Columns}{newline}")
                continue
            vals = [repr(v) if isinstance(v, float) else str(v) for v in (getattr(m, c) for c in m.fmt.columns)]
            out.write(", ".join([m.get_type(), *vals]) + newline)
            n += 1
    return n


# ---- MISB EG 0104 (no library writes it) -----------------------------------------------------------------------

EG0104_SET_KEY = bytes.fromhex("060E2B34020101010E01010201010000")  # EG 0104.5: Predator UAV Basic Universal Set


def klv_item(key: bytes, value: bytes) -> bytes:
    """One KLV triplet: key, BER length (stanag4609's encoder, not the reader's parser), value."""
    from stanag4609.klv import encode_ber_length

    return key + encode_ber_length(len(value)) + value


def eg0104_set(items) -> bytes:
    """An EG 0104 universal set holding `items` (each a `klv_item` with a 16-byte SMPTE key), for the tests'
    hand-worked sets and the fuzz seeds."""
    return klv_item(EG0104_SET_KEY, b"".join(items))
