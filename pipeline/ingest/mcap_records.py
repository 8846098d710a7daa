"""MCAP records read without the summary section (files cut off while recording): the channels and schemas,
and the messages of chosen topics by a linear scan; the errors the mcap library raises on damaged files.
Used by the plain-MCAP reader and by the bag reader for ROS 2 bags rosbags cannot open."""

from __future__ import annotations

import struct
from pathlib import Path

from pipeline.errors import LogReadError


def mcap_errors():
    from mcap.exceptions import McapError
    errors = [McapError, ValueError, EOFError, AssertionError, KeyError, IndexError, struct.error, OSError,
              OverflowError, MemoryError, RuntimeError]  # seek before the start, huge declared lengths, lz4
    try:
        from zstandard import ZstdError
        errors.append(ZstdError)
    except ImportError:
        pass
    return tuple(errors)


def first_line(exc: Exception) -> str:
    return str(exc).splitlines()[0] if str(exc) else type(exc).__name__


def scan_channels(fh, path: Path):
    """Channels and schemas of an MCAP file without a summary section (e.g. cut off while recording)."""
    from mcap.records import Channel, Schema
    from mcap.stream_reader import StreamReader

    channels, schemas = {}, {}
    try:
        for rec in StreamReader(fh, skip_magic=False).records:
            if isinstance(rec, Schema):
                schemas[rec.id] = rec
            elif isinstance(rec, Channel):
                channels[rec.id] = rec
    except mcap_errors() as exc:
        if not channels:
            raise LogReadError(f"not a readable MCAP file: {first_line(exc)}", path=path) from None
    return channels, schemas


def linear_messages(fh, topics: set[str]):
    """(schema, channel, message) of the selected topics by a linear scan (no summary/index needed)."""
    from mcap.records import Channel, Message, Schema
    from mcap.stream_reader import StreamReader

    channels, schemas = {}, {}
    for rec in StreamReader(fh, skip_magic=False).records:
        if isinstance(rec, Schema):
            schemas[rec.id] = rec
        elif isinstance(rec, Channel):
            channels[rec.id] = rec
        elif isinstance(rec, Message):
            ch = channels.get(rec.channel_id)
            if ch is not None and ch.topic in topics:
                yield schemas.get(ch.schema_id), ch, rec
