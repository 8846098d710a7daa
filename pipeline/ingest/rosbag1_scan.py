"""ROS 1 bags without a usable index (recording cut off: the index is written last) read by a linear scan of
their records with rosbags' own record-header parser, chunk decompressors and type system.

rosbags' Reader needs the index; `rosbag reindex` needs ROS. The record layout (bag format 2.0): a 13-byte magic,
then records of `uint32 header_len, header fields (uint32 len + name=value), uint32 data_len, data`; chunks
(op 5) hold connection (op 7) and message (op 2) records, compressed as their `compression` field says.
"""

from __future__ import annotations

import struct
from io import BytesIO
from pathlib import Path

from rosbags.rosbag1.reader import Header, ReaderError, RecordType, decompressors, read_uint32
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

from pipeline.ingest.ros_messages import normalize_type

MAGIC = b"#ROSBAG V2.0\n"


def _records(src):
    """(op, header, data, whole) of consecutive records; the last one may be cut short (whole False)."""
    while True:
        try:
            header = Header.read(src)
        except ReaderError:
            if src.read(1) == b"":
                return  # clean end
            raise
        size = read_uint32(src)
        data = src.read(size)
        yield header.get_uint8("op"), header, data, len(data) == size
        if len(data) < size:
            return


class UnindexedBag1:
    """Connections and messages of a ROS 1 bag found by scanning; `complete` is False when the file ends inside
    a record (what was before it is still read)."""

    def __init__(self, path: str | Path):
        self.path = Path(path)
        self.connections: dict[int, tuple[str, str, str]] = {}  # conn id -> (topic, msgtype, msgdef)
        self.complete = True
        self.error = ""
        for kind, hdr, data in self._walk(messages=False):
            if kind == "conn":
                fields = Header.read(BytesIO(struct.pack("<I", len(data)) + data))
                self.connections.setdefault(hdr.get_uint32("conn"), (
                    hdr.get_string("topic"), normalize_type(fields.get_string("type")),
                    fields.get_string("message_definition")))
        self.typestore = get_typestore(Stores.EMPTY)
        for _topic, msgtype, msgdef in self.connections.values():
            try:
                self.typestore.register(get_types_from_msg(msgdef, msgtype))
            except Exception:  # a broken definition only matters if that topic is needed
                continue

    def _walk(self, messages: bool):
        self.complete = True
        with open(self.path, "rb") as f:
            if f.read(len(MAGIC)) != MAGIC:
                raise ReaderError("not a ROS 1 bag (no '#ROSBAG V2.0' magic)")
            try:
                for op, hdr, data, whole in _records(f):
                    if not whole:
                        self.complete = False
                        self.error = "file ends inside a record"
                    if op == RecordType.CHUNK:
                        comp = hdr.get_string("compression")
                        if not whole and comp != "none":
                            break  # a compressed chunk cut short cannot be decompressed
                        raw = decompressors[comp](data)
                        for op2, hdr2, data2, whole2 in _records(BytesIO(raw)):
                            if not whole2:
                                break
                            if op2 == RecordType.CONNECTION:
                                yield "conn", hdr2, data2
                            elif op2 == RecordType.MSGDATA and messages:
                                yield "msg", hdr2, data2
                    elif not whole:
                        break
                    elif op == RecordType.CONNECTION:
                        yield "conn", hdr, data
                    elif op == RecordType.MSGDATA and messages:
                        yield "msg", hdr, data
            except (ReaderError, KeyError, ValueError, OSError, struct.error) as exc:
                self.complete = False
                self.error = str(exc).splitlines()[0] if str(exc) else type(exc).__name__

    def messages(self, topics=None):
        """(topic, msgtype, record time ns, raw bytes) in file order, for the connections of `topics` (all: None)."""
        want = {cid for cid, (t, _, _) in self.connections.items() if topics is None or t in topics}
        for kind, hdr, data in self._walk(messages=True):
            if kind == "msg":
                cid = hdr.get_uint32("conn")
                if cid in want:
                    topic, msgtype, _ = self.connections[cid]
                    yield topic, msgtype, hdr.get_time("time"), data

    def deserialize(self, raw: bytes, msgtype: str):
        return self.typestore.deserialize_ros1(raw, msgtype)
