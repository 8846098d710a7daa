"""The common convention mistakes, as reinterpretations of what was read, and the config lines that fix each.

A convention is how the gimbal's logged orientation is read: the frame of its quaternion (<body>_<world>, body
frd, flu or optical, world ned or enu), whether its yaw is relative to the vehicle's heading, the quaternion's
element order (scalar first or last; plain MCAP JSON only: ROS and MAVLink name their fields), and the camera's
mounting in the gimbal (`camera.R_optical_from_gimbal`). `reinterpret` turns the gimbal series as read under the
configured convention into the series another convention would have read from the same file, so each
alternative is tried without reading the logs again.
"""

from __future__ import annotations

import dataclasses
import itertools
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import yaml

from pipeline.errors import RidgelocError
from pipeline.flight_config import FlightConfig
from pipeline.geometry.pose import R_OPTICAL_FROM_GIMBAL_DEFAULT
from pipeline.ingest.frames import ORIENTATION_FRAMES, frame_quat_from_ned_frd, quat_ned_frd_from_frame
from pipeline.ingest.mapping import mapping_for
from pipeline.ingest.model import FlightLog, GimbalSeries

# Camera mountings worth trying: the gimbal FRD default, a gimbal orientation that is already the camera's optical
# frame (identity), and a gimbal FLU frame.
MOUNTS = {
    "frd": R_OPTICAL_FROM_GIMBAL_DEFAULT,
    "optical": np.eye(3),
    "flu": R_OPTICAL_FROM_GIMBAL_DEFAULT @ np.diag([1.0, -1.0, -1.0]),
}


@dataclass(frozen=True)
class Reading:
    """How the flight's gimbal orientation is read now: the mapping format that supplied it ("ros", "mcap",
    "tlog", ...), its quaternion frame, element order, yaw flag (True/False, or None when the log flags each
    sample itself) and the camera mount (a MOUNTS key, or "custom")."""

    fmt: str
    frame: str
    quat_order: str
    yaw_in_vehicle_frame: bool | None
    mount: str
    mount_matrix: tuple


@dataclass(frozen=True)
class Convention:
    """An alternative reading: frame, quat_order, yaw flipped (every sample's yaw flag inverted), mount."""

    frame: str
    quat_order: str
    yaw_flipped: bool
    mount: str

    def changes(self, now: Reading) -> int:
        return ((self.frame != now.frame) + (self.quat_order != now.quat_order) + self.yaw_flipped
                + (self.mount != now.mount))


def _gimbal_format(config: FlightConfig, log: FlightLog) -> str:
    from pipeline.ingest.dispatch import detect_format

    source = log.gimbal.source if log.gimbal is not None else ""
    found = []
    for path in config.files.telemetry:
        try:
            fmt = detect_format(path)
        except RidgelocError:  # an unreadable file: the reader has said so already
            continue
        if fmt in ("ros1", "ros2"):
            fmt = "ros"
        if fmt == "mcap":
            ros_topic = mapping_for("ros", config.mapping)["gimbal"]["topic"]
            fmt = "ros" if ros_topic and ros_topic in source else "mcap"
        if fmt != "video":
            found.append((Path(path).name in source or Path(path).as_posix() in source, fmt))
    matched = [f for hit, f in found if hit]
    return (matched or [f for _, f in found] or ["unknown"])[0]


def current_reading(config: FlightConfig, log: FlightLog) -> Reading:
    fmt = _gimbal_format(config, log)
    frame, order, yaw = "frd_ned", "wxyz", None
    if fmt == "ros":
        g = mapping_for("ros", config.mapping)["gimbal"]
        frame, yaw = g.get("frame", "flu_enu"), bool(g.get("yaw_in_vehicle_frame", False))
    elif fmt == "mcap":
        order = mapping_for("mcap", config.mapping)["gimbal"].get("quat_order", "wxyz")
    elif fmt == "tlog" and log.gimbal is not None and "MOUNT_STATUS" in log.gimbal.source:
        yaw = mapping_for("tlog", config.mapping)["gimbal"]["mount_status_yaw"] == "vehicle"
    M = np.asarray(config.camera.R_optical_from_gimbal, dtype=float)
    mount = next((k for k, v in MOUNTS.items() if np.allclose(v, M, atol=1e-9)), "custom")
    return Reading(fmt, frame, order, yaw, mount, tuple(map(tuple, M.tolist())))


def candidates(now: Reading) -> list[Convention]:
    """Every alternative reading worth trying for this source (the current one first)."""
    frames = ORIENTATION_FRAMES if now.fmt == "ros" else ("frd_ned", "frd_enu")
    orders = ("wxyz", "xyzw") if now.fmt == "mcap" else (now.quat_order,)
    mounts = list(MOUNTS) + ([now.mount] if now.mount == "custom" else [])
    out = [Convention(now.frame, now.quat_order, False, now.mount)]
    for f, o, y, m in itertools.product(frames, orders, (False, True), mounts):
        c = Convention(f, o, y, m)
        if c != out[0]:
            out.append(c)
    return out


def mount_matrix(conv: Convention, now: Reading) -> np.ndarray:
    return np.asarray(now.mount_matrix) if conv.mount == "custom" else MOUNTS[conv.mount]


def reinterpret(gimbal: GimbalSeries, conv: Convention, now: Reading) -> GimbalSeries:
    """The gimbal series `conv` would have read from the file `now` read `gimbal` from."""
    q = gimbal.quat_wxyz
    if (conv.frame, conv.quat_order) != (now.frame, now.quat_order):
        raw = frame_quat_from_ned_frd(q, now.frame)  # back to the numbers in the file, as read (w, x, y, z)
        if conv.quat_order != now.quat_order:
            raw = raw[:, [3, 0, 1, 2]] if conv.quat_order == "xyzw" else raw[:, [1, 2, 3, 0]]
        q = quat_ned_frd_from_frame(raw, conv.frame)
    flags = np.asarray(gimbal.yaw_in_vehicle_frame, dtype=bool)
    if conv.yaw_flipped:
        flags = ~flags
    return dataclasses.replace(gimbal, quat_wxyz=q, yaw_in_vehicle_frame=flags)


def fix(conv: Convention, now: Reading) -> tuple[dict, list[str]]:
    """(the flight-config changes that select `conv`, as a nested dict; notes for changes no key can make)."""
    changes: dict = {}
    notes: list[str] = []
    gimbal_keys: dict = {}
    if conv.frame != now.frame:
        if now.fmt == "ros":
            gimbal_keys["frame"] = conv.frame
        else:
            notes.append(f"the log's gimbal quaternion looks {conv.frame}, not {now.frame} as its format defines: no "
                         "config key converts it; convert the log")
    if conv.quat_order != now.quat_order:
        gimbal_keys["quat_order"] = conv.quat_order
    if conv.yaw_flipped:
        if now.yaw_in_vehicle_frame is None:
            notes.append("the log's own gimbal yaw flags (relative to the vehicle / earth-referenced) look inverted: "
                         "no config key overrides them; fix the log")
        elif now.fmt == "tlog":
            gimbal_keys["mount_status_yaw"] = "earth" if now.yaw_in_vehicle_frame else "vehicle"
        else:
            gimbal_keys["yaw_in_vehicle_frame"] = not now.yaw_in_vehicle_frame
    if gimbal_keys:
        changes["mapping"] = {now.fmt: {"gimbal": gimbal_keys}}
    if conv.mount != now.mount:
        changes["camera"] = {"R_optical_from_gimbal": [[int(v) if float(v).is_integer() else float(v) for v in row]
                                                       for row in mount_matrix(conv, now).tolist()]}
    return changes, notes


def fix_lines(changes: dict) -> list[str]:
    """Config lines (YAML, one top-level key per line, flow style) for `changes`."""
    return [f"{k}: " + yaml.safe_dump(v, default_flow_style=True, width=10**6, sort_keys=False).strip()
            for k, v in changes.items()]
