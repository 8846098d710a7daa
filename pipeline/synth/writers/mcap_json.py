"""Plain MCAP with JSON messages and jsonschema schemas (self-describing, no ROS needed).

Channels: /uav/gps {t_ns, latitude_deg, longitude_deg, altitude_m, altitude_datum: "ellipsoid"},
/uav/attitude {t_ns, q_wxyz, frame: "body_frd_to_ned"}, /uav/gimbal {t_ns, q_wxyz, frame: "gimbal_frd_to_ned",
yaw_in_vehicle_frame}, /uav/laser {t_ns, range_m, valid}. log_time = publish_time = t_ns (telemetry clock).
"""

from __future__ import annotations

import heapq
import json
from pathlib import Path

from mcap.writer import CompressionType, Writer

from pipeline.synth.telemetry import Telemetry

_NUM = {"type": "number"}
_INT = {"type": "integer"}
_Q = {"type": "array", "items": _NUM, "minItems": 4, "maxItems": 4, "description": "quaternion w, x, y, z"}
SCHEMAS = {
    "/uav/gps": ("ridgeloc.GnssFix", {"t_ns": _INT, "latitude_deg": _NUM, "longitude_deg": _NUM,
                                      "altitude_m": _NUM, "altitude_datum": {"type": "string",
                                                                             "enum": ["ellipsoid", "amsl"]}}),
    "/uav/attitude": ("ridgeloc.Attitude", {"t_ns": _INT, "q_wxyz": _Q, "frame": {"type": "string"}}),
    "/uav/gimbal": ("ridgeloc.GimbalAttitude", {"t_ns": _INT, "q_wxyz": _Q, "frame": {"type": "string"},
                                                "yaw_in_vehicle_frame": {"type": "boolean"}}),
    "/uav/laser": ("ridgeloc.LaserRange", {"t_ns": _INT, "range_m": _NUM, "valid": {"type": "boolean"}}),
}


def _schema(name: str, props: dict) -> bytes:
    return json.dumps({"$schema": "https://json-schema.org/draft/2020-12/schema", "title": name, "type": "object",
                       "properties": props, "required": sorted(props)}).encode()


def write_mcap(path: Path, tel: Telemetry, gimbal_quat_order: str = "wxyz") -> dict[str, int]:
    """Write the telemetry; returns message counts per topic. gimbal_quat_order "xyzw" writes the gimbal's
    quaternion array scalar last (another vehicle's convention, under the same field name)."""
    order = [0, 1, 2, 3] if gimbal_quat_order == "wxyz" else [1, 2, 3, 0]
    def gps():
        for t, lla in zip(tel.gps_t_ns, tel.gps_lla, strict=True):
            yield int(t), "/uav/gps", {"t_ns": int(t), "latitude_deg": float(lla[0]), "longitude_deg": float(lla[1]),
                                       "altitude_m": float(lla[2]), "altitude_datum": "ellipsoid"}

    def att():
        for t, q in zip(tel.att_t_ns, tel.att_quat_wxyz, strict=True):
            yield int(t), "/uav/attitude", {"t_ns": int(t), "q_wxyz": [float(x) for x in q], "frame": "body_frd_to_ned"}

    def gim():
        for t, q in zip(tel.gimbal_t_ns, tel.gimbal_quat_wxyz, strict=True):
            yield int(t), "/uav/gimbal", {"t_ns": int(t), "q_wxyz": [float(x) for x in q[order]],
                                          "frame": "gimbal_frd_to_ned",
                                          "yaw_in_vehicle_frame": bool(tel.gimbal_yaw_in_vehicle)}

    def laser():
        for t, r, ok in zip(tel.laser_t_ns, tel.laser_range_m, tel.laser_valid, strict=True):
            yield int(t), "/uav/laser", {"t_ns": int(t), "range_m": float(r), "valid": bool(ok)}

    counts: dict[str, int] = {}
    with open(path, "wb") as f:
        w = Writer(f, compression=CompressionType.ZSTD)
        w.start(profile="", library="ridgeloc-synth")
        channels = {}
        for topic, (name, props) in SCHEMAS.items():
            sid = w.register_schema(name=name, encoding="jsonschema", data=_schema(name, props))
            channels[topic] = w.register_channel(topic=topic, message_encoding="json", schema_id=sid)
        seq: dict[str, int] = {}
        for t, topic, doc in heapq.merge(gps(), att(), gim(), laser(), key=lambda r: r[0]):
            seq[topic] = seq.get(topic, 0) + 1
            w.add_message(channels[topic], log_time=t, data=json.dumps(doc).encode(), publish_time=t,
                          sequence=seq[topic])
            counts[topic] = counts.get(topic, 0) + 1
        w.finish()
    return counts
