"""Small writers of each supported format, for tests and benchmarks (round trips through the real libraries)."""

from __future__ import annotations

import struct
from pathlib import Path

from pymavlink.dialects.v20 import ardupilotmega as mavlink


class TlogWriter:
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

    def close(self) -> None:
        self.f.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


def write_json_mcap(path, messages: dict[str, list[dict]]) -> None:
    """Plain MCAP with one JSON channel per topic (jsonschema schema); log_time = publish_time = msg["t_ns"]."""
    import json

    from mcap.writer import Writer

    with open(Path(path), "wb") as f:
        w = Writer(f)
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
