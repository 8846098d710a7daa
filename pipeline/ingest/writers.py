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
