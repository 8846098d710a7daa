"""ROS 1 (.bag) and ROS 2 (sqlite3 or MCAP storage) bags via rosbags, REP-103 frames.

Topics: /uav/gps/fix NavSatFix (ellipsoid altitude), /uav/imu Imu (body FLU -> local ENU at the vehicle),
/uav/gimbal/attitude QuaternionStamped (gimbal FLU -> local ENU), /uav/laser/range Range, /uav/camera/camera_info
CameraInfo (1 Hz), optionally /uav/camera/image/compressed CompressedImage (jpeg). header.stamp is the
measurement time on the telemetry clock and the bag's record time equals it.
"""

from __future__ import annotations

import heapq
from collections.abc import Callable, Iterator
from pathlib import Path

import cv2
import numpy as np
from rosbags.rosbag1 import Writer as Writer1
from rosbags.rosbag2 import StoragePlugin
from rosbags.rosbag2 import Writer as Writer2
from rosbags.typesys import Stores, get_typestore
from scipy.spatial.transform import Rotation

from pipeline.geometry.frames import R_ENU_FROM_NED
from pipeline.ingest.frames import frame_quat_from_ned_frd
from pipeline.synth.telemetry import Telemetry

FLU_FROM_FRD = np.diag([1.0, -1.0, -1.0])
TOPICS = {
    "gps": ("/uav/gps/fix", "sensor_msgs/msg/NavSatFix"),
    "imu": ("/uav/imu", "sensor_msgs/msg/Imu"),
    "gimbal": ("/uav/gimbal/attitude", "geometry_msgs/msg/QuaternionStamped"),
    "laser": ("/uav/laser/range", "sensor_msgs/msg/Range"),
    "info": ("/uav/camera/camera_info", "sensor_msgs/msg/CameraInfo"),
    "image": ("/uav/camera/image/compressed", "sensor_msgs/msg/CompressedImage"),
}


def enu_flu_quat_xyzw(quat_wxyz_frd_to_ned: np.ndarray) -> np.ndarray:
    """(n, 4) x, y, z, w quaternions of FLU -> ENU from (n, 4) w, x, y, z quaternions of FRD -> NED."""
    R = Rotation.from_quat(quat_wxyz_frd_to_ned, scalar_first=True).as_matrix()
    return Rotation.from_matrix(R_ENU_FROM_NED @ R @ FLU_FROM_FRD).as_quat(canonical=True)


class _Msgs:
    def __init__(self, ros1: bool):
        self.ts = get_typestore(Stores.ROS1_NOETIC if ros1 else Stores.ROS2_HUMBLE)
        self.ros1 = ros1
        T = self.ts.types
        self.Header, self.Time = T["std_msgs/msg/Header"], T["builtin_interfaces/msg/Time"]
        self.T = T
        self.seq = 0

    def header(self, t_ns: int, frame_id: str):
        stamp = self.Time(sec=int(t_ns) // 1_000_000_000, nanosec=int(t_ns) % 1_000_000_000)
        if self.ros1:
            self.seq += 1
            return self.Header(seq=self.seq, stamp=stamp, frame_id=frame_id)
        return self.Header(stamp=stamp, frame_id=frame_id)

    def serialize(self, msg, msgtype: str) -> bytes:
        return self.ts.serialize_ros1(msg, msgtype) if self.ros1 else self.ts.serialize_cdr(msg, msgtype)


def _streams(m: _Msgs, tel: Telemetry, camera: dict, gps_sigma_m: float, att_sigma_rad: float,
             laser_limits: tuple[float, float], images: Iterator[tuple[int, bytes]] | None,
             gimbal_frame: str = "flu_enu") -> list[Iterator[tuple[int, str, Callable]]]:
    T = m.T
    Vec3, Quat = T["geometry_msgs/msg/Vector3"], T["geometry_msgs/msg/Quaternion"]

    def gps():
        status = T["sensor_msgs/msg/NavSatStatus"](status=0, service=1)
        cov = np.diag([gps_sigma_m ** 2] * 3).ravel()
        for t, lla in zip(tel.gps_t_ns, tel.gps_lla, strict=True):
            yield int(t), "gps", lambda t=t, lla=lla: T["sensor_msgs/msg/NavSatFix"](
                header=m.header(t, "gps"), status=status, latitude=float(lla[0]), longitude=float(lla[1]),
                altitude=float(lla[2]), position_covariance=cov, position_covariance_type=2)

    def imu():
        q = enu_flu_quat_xyzw(tel.att_quat_wxyz)
        w_flu = tel.att_rates_frd * np.array([1.0, -1.0, -1.0])
        ocov = np.diag([att_sigma_rad ** 2] * 3).ravel()
        acov = np.zeros(9)
        acov[0] = -1.0  # no linear acceleration
        for t, qi, wi in zip(tel.att_t_ns, q, w_flu, strict=True):
            yield int(t), "imu", lambda t=t, qi=qi, wi=wi: T["sensor_msgs/msg/Imu"](
                header=m.header(t, "base_link"), orientation=Quat(x=qi[0], y=qi[1], z=qi[2], w=qi[3]),
                orientation_covariance=ocov, angular_velocity=Vec3(x=wi[0], y=wi[1], z=wi[2]),
                angular_velocity_covariance=np.zeros(9), linear_acceleration=Vec3(x=0.0, y=0.0, z=0.0),
                linear_acceleration_covariance=acov)

    def gimbal():
        if gimbal_frame == "flu_enu":
            q = enu_flu_quat_xyzw(tel.gimbal_quat_wxyz)
        else:  # another vehicle's convention (synth gimbal.ros_frame)
            q = frame_quat_from_ned_frd(tel.gimbal_quat_wxyz, gimbal_frame)[:, [1, 2, 3, 0]]
        for t, qi in zip(tel.gimbal_t_ns, q, strict=True):
            yield int(t), "gimbal", lambda t=t, qi=qi: T["geometry_msgs/msg/QuaternionStamped"](
                header=m.header(t, "gimbal"), quaternion=Quat(x=qi[0], y=qi[1], z=qi[2], w=qi[3]))

    def laser():
        for t, r in zip(tel.laser_t_ns, tel.laser_range_m, strict=True):
            yield int(t), "laser", lambda t=t, r=r: T["sensor_msgs/msg/Range"](
                header=m.header(t, "rangefinder"), radiation_type=1, field_of_view=0.002,
                min_range=laser_limits[0], max_range=laser_limits[1], range=float(r))

    def info():
        K = np.array(camera["K"], dtype=np.float64)
        P = np.hstack([K, np.zeros((3, 1))]).ravel()
        roi = T["sensor_msgs/msg/RegionOfInterest"](x_offset=0, y_offset=0, height=0, width=0, do_rectify=False)
        names = ("D", "K", "R", "P") if m.ros1 else ("d", "k", "r", "p")
        for t in tel.system_time_t_ns:
            arrays = dict(zip(names, (np.array(camera["dist"], dtype=np.float64), K.ravel(), np.eye(3).ravel(), P),
                              strict=True))
            yield int(t), "info", lambda t=t, arrays=arrays: T["sensor_msgs/msg/CameraInfo"](
                header=m.header(t, "camera_optical"), height=camera["height"], width=camera["width"],
                distortion_model="plumb_bob", binning_x=0, binning_y=0, roi=roi, **arrays)

    def image():
        for t, jpeg in images:
            yield int(t), "image", lambda t=t, jpeg=jpeg: T["sensor_msgs/msg/CompressedImage"](
                header=m.header(t, "camera_optical"), format="jpeg", data=np.frombuffer(jpeg, dtype=np.uint8))

    streams = [gps(), imu(), gimbal(), laser(), info()]
    if images is not None:
        streams.append(image())
    return streams


def write_bag(path: Path, kind: str, tel: Telemetry, camera: dict, gps_sigma_m: float, att_sigma_rad: float,
              laser_limits: tuple[float, float], images: Iterator[tuple[int, bytes]] | None = None,
              gimbal_frame: str = "flu_enu") -> dict[str, int]:
    """kind: "ros1" (path = .bag file), "ros2-sqlite3" or "ros2-mcap" (path = bag folder). `images` yields
    (t_ns, jpeg bytes) in time order. gps_sigma_m, att_sigma_rad: the stated accuracies (covariances).
    gimbal_frame: the frame of the gimbal topic's orientation (pipeline.ingest.frames.ORIENTATION_FRAMES).
    Returns message counts per topic."""
    ros1 = kind == "ros1"
    m = _Msgs(ros1)
    streams = _streams(m, tel, camera, gps_sigma_m, att_sigma_rad, laser_limits, images, gimbal_frame)
    if ros1:
        writer = Writer1(path)
    else:
        plugin = StoragePlugin.MCAP if kind == "ros2-mcap" else StoragePlugin.SQLITE3
        writer = Writer2(path, version=8, storage_plugin=plugin)
    counts: dict[str, int] = {}
    with writer:
        conns = {}
        kinds = ["gps", "imu", "gimbal", "laser", "info"] + (["image"] if images is not None else [])
        for k in kinds:
            topic, msgtype = TOPICS[k]
            conns[k] = writer.add_connection(topic, msgtype, typestore=m.ts)
        for t, k, make in heapq.merge(*streams, key=lambda r: r[0]):
            writer.write(conns[k], t, m.serialize(make(), TOPICS[k][1]))
            counts[TOPICS[k][0]] = counts.get(TOPICS[k][0], 0) + 1
    return counts


def encode_jpeg(img: np.ndarray, quality: int) -> bytes:
    ok, buf = cv2.imencode(".jpg", img, [cv2.IMWRITE_JPEG_QUALITY, quality])
    if not ok:
        raise RuntimeError("JPEG encoding failed")
    return buf.tobytes()
