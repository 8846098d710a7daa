"""ROS message -> model samples, shared by bags (rosbags) and ROS 2 channels in plain MCAP (mcap_ros2).

Works on any decoded message object with ROS 2 attribute names (rosbags gives ROS 1 messages the same
`header.stamp.sec/nanosec`); ROS 1 CameraInfo `K D P` and ROS 2 `k d p` are both accepted.
"""

from __future__ import annotations

import math

import numpy as np

from pipeline.errors import ConfigError
from pipeline.ingest.columns import Columns, sort_by_time
from pipeline.ingest.frames import ORIENTATION_FRAMES, quat_ned_frd_from_frame
from pipeline.ingest.model import (
    AttitudeSeries,
    CameraInfo,
    FlightLog,
    FrameSeries,
    GimbalSeries,
    PositionSeries,
    RangeSeries,
)

NAVSAT = ("sensor_msgs/msg/NavSatFix",)
ORIENTATION = ("sensor_msgs/msg/Imu", "geometry_msgs/msg/QuaternionStamped", "geometry_msgs/msg/PoseStamped")
RANGE = ("sensor_msgs/msg/Range",)
IMAGES = ("sensor_msgs/msg/CompressedImage", "sensor_msgs/msg/Image")
CAMERA_INFO = ("sensor_msgs/msg/CameraInfo",)
TYPES = {"position": NAVSAT, "attitude": ORIENTATION, "gimbal": ORIENTATION, "range": RANGE, "images": IMAGES,
         "camera_info": CAMERA_INFO}
SUPPLIES = {t: q for q in ("position", "attitude", "range", "camera_info") for t in TYPES[q]}
SUPPLIES.update({t: "frames" for t in IMAGES})
ORIENTATION_SUPPLIES = ("attitude", "gimbal")


def normalize_type(msgtype: str) -> str:
    """'sensor_msgs/NavSatFix' (ROS 1) -> 'sensor_msgs/msg/NavSatFix'."""
    parts = msgtype.split("/")
    return f"{parts[0]}/msg/{parts[1]}" if len(parts) == 2 else msgtype


def supplies_of(msgtype: str) -> tuple[str, ...]:
    t = normalize_type(msgtype)
    if t in ORIENTATION:
        return ORIENTATION_SUPPLIES
    return (SUPPLIES[t],) if t in SUPPLIES else ()


def stamp_ns(msg, record_ns: int, mode: str) -> int:
    """header.stamp in ns (mode "header", falling back to record time when the stamp is zero) or record time."""
    if mode == "record":
        return record_ns
    if mode != "header":
        raise ConfigError(f"ros mapping: stamp must be 'header' or 'record', not {mode!r}")
    header = getattr(msg, "header", None)
    if header is None:
        return record_ns
    st = header.stamp
    ns = int(st.sec) * 1_000_000_000 + int(getattr(st, "nanosec", getattr(st, "nsec", 0)))
    return ns if ns > 0 else record_ns


def _stated_sigma(cov) -> float | None:
    """The standard deviation per axis a ROS covariance (3x3, row-major) states: the root of
    its diagonal's mean, or None when the diagonal is not positive and finite (unknown, -1: no estimate)."""
    try:
        diag = np.asarray(cov, dtype=float)[[0, 4, 8]]
    except (IndexError, TypeError, ValueError):
        return None
    return float(np.sqrt(diag.mean())) if np.isfinite(diag).all() and (diag > 0).all() else None


def _orientation(msg, msgtype: str):
    if msgtype.endswith("Imu"):
        cov = msg.orientation_covariance
        if len(cov) and cov[0] == -1:
            return None  # no orientation estimate
        o = msg.orientation
    elif msgtype.endswith("QuaternionStamped"):
        o = msg.quaternion
    else:
        o = msg.pose.orientation
    return o.w, o.x, o.y, o.z


class RosAccumulator:
    """Collects samples of one quantity from one topic; `series()` builds the model series."""

    def __init__(self, quantity: str, topic: str, msgtype: str, cfg: dict, stamp_mode: str, source: str):
        self.quantity, self.topic, self.msgtype = quantity, topic, normalize_type(msgtype)
        self.cfg, self.stamp_mode, self.source = cfg, stamp_mode, source
        self.dropped = 0
        self.info: CameraInfo | None = None
        self.size = (0, 0)
        if quantity == "position":
            self.cols = Columns(t="q", lat="d", lon="d", alt="d")
        elif quantity in ("attitude", "gimbal"):
            self.cols = Columns(t="q", w="d", x="d", y="d", z="d")
        elif quantity == "range":
            self.cols = Columns(t="q", r="d", lo="d", hi="d")
        else:
            self.cols = Columns(t="q", i="q")
        self.n = 0
        self.sigma: float | None = None  # the first stated standard deviation (m or rad), position and Imu only
        self._want_sigma = quantity == "position" or (quantity in ("attitude", "gimbal") and
                                                      self.msgtype.endswith("Imu"))
        self._header_stamp = stamp_mode == "header"
        if stamp_mode not in ("header", "record"):
            raise ConfigError(f"ros mapping: stamp must be 'header' or 'record', not {stamp_mode!r}")
        kind = "orientation" if quantity in ("attitude", "gimbal") else quantity
        self._add_kind = getattr(self, "_add_" + kind)  # one specialised method per message kind
        self._append = self.cols.appenders()

    def add(self, msg, record_ns: int) -> None:
        """One decoded message; a message decoded by a damaged schema (missing or mistyped fields) is dropped."""
        try:
            self._add_kind(msg, record_ns)
        except (AttributeError, TypeError, ValueError, OverflowError):
            self.dropped += 1

    def _t(self, msg, record_ns: int) -> int:
        if self._header_stamp:
            try:
                st = msg.header.stamp
                ns = st.sec * 1_000_000_000 + st.nanosec
                return ns if ns > 0 else record_ns
            except AttributeError:
                return stamp_ns(msg, record_ns, "header")
        return record_ns

    def _add_position(self, msg, record_ns: int) -> None:
        self.n += 1
        lat, lon = msg.latitude, msg.longitude
        if msg.status.status < 0 or not (math.isfinite(lat) and math.isfinite(lon)):
            self.dropped += 1  # STATUS_NO_FIX
            return
        t, alt = self._t(msg, record_ns), float(msg.altitude)  # every field read before any column grows
        if self._want_sigma and getattr(msg, "position_covariance_type", 0) > 0:
            self.sigma = _stated_sigma(msg.position_covariance)
            self._want_sigma = self.sigma is None
        at, alat, alon, aalt = self._append
        at(t)
        alat(lat)
        alon(lon)
        aalt(alt)

    def _add_orientation(self, msg, record_ns: int) -> None:
        self.n += 1
        o = _orientation(msg, self.msgtype)
        if o is None:
            self.dropped += 1
            return
        t, o = self._t(msg, record_ns), [float(v) for v in o]
        if self._want_sigma:
            self.sigma = _stated_sigma(msg.orientation_covariance)
            self._want_sigma = self.sigma is None
        at, aw, ax, ay, az = self._append
        at(t)
        aw(o[0])
        ax(o[1])
        ay(o[2])
        az(o[3])

    def _add_range(self, msg, record_ns: int) -> None:
        self.n += 1
        t, r, lo, hi = self._t(msg, record_ns), float(msg.range), float(msg.min_range), float(msg.max_range)
        at, ar, alo, ahi = self._append
        at(t)
        ar(r)
        alo(lo)
        ahi(hi)

    def _add_images(self, msg, record_ns: int) -> None:
        if self.size == (0, 0):
            if hasattr(msg, "width"):
                self.size = (int(msg.width), int(msg.height))
            else:  # CompressedImage: the size is only known by decoding one
                try:
                    img = decode_image(msg, self.msgtype)
                    self.size = (img.shape[1], img.shape[0])
                except ValueError:
                    pass
        self.cols.add(t=self._t(msg, record_ns), i=self.n)
        self.n += 1

    def _add_camera_info(self, msg, record_ns: int) -> None:
        self.n += 1
        if self.info is not None:
            return

        def get(*names):
            for n in names:
                if hasattr(msg, n):
                    return np.asarray(getattr(msg, n), float)
            return np.zeros(0)
        self.info = CameraInfo(int(msg.width), int(msg.height), get("k", "K").reshape(3, 3), get("d", "D"),
                               get("p", "P").reshape(3, 4), str(msg.distortion_model), source=self.source)

    def series(self):
        a = self.cols.arrays()
        self.cols = None  # the buffers now live only as long as the views that still need them
        q, src = self.quantity, self.source
        if q == "camera_info":
            return self.info
        if a["t"].size == 0:
            return None
        if q == "position":
            t, lat, lon, alt = sort_by_time(a["t"], a["lat"], a["lon"], a["alt"])
            return PositionSeries(t, lat, lon, alt, "ellipsoid", source=src, clock="unix", sigma_m=self.sigma)
        if q in ("attitude", "gimbal"):
            raw = np.column_stack([a["w"], a["x"], a["y"], a["z"]])
            frame = self.cfg.get("frame", "flu_enu")
            if frame not in ORIENTATION_FRAMES:
                raise ConfigError(f"ros mapping: {q}.frame must be one of {', '.join(ORIENTATION_FRAMES)} "
                                  f"(body axes _ world axes; optical = REP-103 camera optical), not {frame!r}")
            quat = quat_ned_frd_from_frame(raw, frame)
            t, quat = sort_by_time(a["t"], quat)
            sigma_deg = None if self.sigma is None else math.degrees(self.sigma)
            if q == "attitude":
                return AttitudeSeries(t, quat, source=src, clock="unix", sigma_deg=sigma_deg)
            veh = np.full(t.shape, bool(self.cfg.get("yaw_in_vehicle_frame", False)))
            return GimbalSeries(t, quat, veh, source=src, clock="unix", sigma_deg=sigma_deg)
        if q == "range":
            r = a["r"]
            with np.errstate(invalid="ignore"):
                valid = np.isfinite(r) & (r >= a["lo"]) & (r <= a["hi"])
            t, r, valid = sort_by_time(a["t"], r, valid)
            return RangeSeries(t, r, valid, source=src, clock="unix")
        t, idx = sort_by_time(a["t"], a["i"])
        return FrameSeries(t, idx, source=src, clock="unix", width_px=self.size[0], height_px=self.size[1])


def decode_image(msg, msgtype: str) -> np.ndarray:
    """sensor_msgs CompressedImage (cv2.imdecode) or Image (by encoding) -> BGR uint8 (h, w, 3) or mono (h, w)
    (mono16 stays uint16)."""
    import cv2

    data = np.frombuffer(bytes(msg.data), np.uint8)
    if normalize_type(msgtype).endswith("CompressedImage"):
        img = cv2.imdecode(data, cv2.IMREAD_UNCHANGED)
        if img is None:
            raise ValueError(f"cannot decode compressed image (format {msg.format!r})")
        return img
    enc = msg.encoding.lower()
    h, w, step = int(msg.height), int(msg.width), int(msg.step)
    layouts = {"mono8": (np.uint8, 1), "8uc1": (np.uint8, 1), "rgb8": (np.uint8, 3), "bgr8": (np.uint8, 3),
               "rgba8": (np.uint8, 4), "bgra8": (np.uint8, 4), "mono16": (np.uint16, 1), "16uc1": (np.uint16, 1)}
    if enc not in layouts:
        raise ValueError(f"unsupported image encoding {msg.encoding!r}")
    dtype, ch = layouts[enc]
    itemsize = np.dtype(dtype).itemsize
    rows = data[: h * step].reshape(h, step)[:, : w * ch * itemsize]
    img = rows.copy().view(dtype if not msg.is_bigendian else np.dtype(dtype).newbyteorder(">"))
    img = img.astype(dtype).reshape(h, w, ch) if ch > 1 else img.astype(dtype).reshape(h, w)
    if enc == "rgb8":
        img = cv2.cvtColor(img, cv2.COLOR_RGB2BGR)
    elif enc == "rgba8":
        img = cv2.cvtColor(img, cv2.COLOR_RGBA2BGR)
    elif enc == "bgra8":
        img = cv2.cvtColor(img, cv2.COLOR_BGRA2BGR)
    return img


# ---- shared by the bag and MCAP readers ------------------------------------------------------------------

ROS_QUANTITIES = ("position", "attitude", "gimbal", "range", "images", "camera_info")


def resolve_topics(cfg: dict, topic_types: dict[str, str], warnings: list[str], where: str) -> dict[str, str]:
    """quantity -> topic chosen from the mapping: the named topic, else the first fallback present, else (by_type)
    the only topic of a matching type. A topic of the wrong type is a warning, not a guess."""
    chosen: dict[str, str] = {}
    for q in ROS_QUANTITIES:
        c = cfg[q]
        types = TYPES[q]
        for topic in [c["topic"], *c["fallback_topics"]]:
            if topic in topic_types:
                if normalize_type(topic_types[topic]) in types:
                    chosen[q] = topic
                    break
                warnings.append(f"{where}: topic {topic} has type {topic_types[topic]}, not one of "
                                f"{', '.join(types)}; not used for {q}")
        if q in chosen or not c["by_type"]:
            continue
        taken = set(chosen.values())
        cands = [t for t, ty in topic_types.items() if normalize_type(ty) in types and t not in taken]
        if len(cands) == 1:
            chosen[q] = cands[0]
            warnings.append(f"{where}: {q} from {cands[0]} (the only {topic_types[cands[0]]} topic; "
                            f"set ros.{q}.topic to silence)")
        elif len(cands) > 1:
            warnings.append(f"{where}: several topics could supply {q} ({', '.join(cands)}); set ros.{q}.topic")
    return chosen


def fill_log(log: FlightLog, accs: dict[str, RosAccumulator], warnings: list[str], path) -> None:
    """Put the series of the accumulators into log (images as frames), with warnings on dropped messages."""
    for q, acc in accs.items():
        s = acc.series()
        if acc.dropped:
            what = "without a GPS fix" if q == "position" else "without an orientation"
            warnings.append(f"{path}: {acc.dropped} of {acc.n} {acc.topic} messages {what} dropped")
        if q == "position" and s is None and acc.n:
            warnings.append(f"{path}: no GPS fix in {acc.n} {acc.topic} messages; no position read")
        if q == "images":
            log.frames = s
        elif q == "camera_info":
            log.camera_info = s
        else:
            setattr(log, q, s)
