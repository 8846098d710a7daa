"""When a video file says its recording started: the container's `creation_time` (MP4/QuickTime `mvhd`, Matroska
DateUTC), as FFmpeg reads it through PyAV.

Cameras write it from their own clock, to the whole second in MP4 (the header counts seconds since 1904), and some
at the start of recording, others when the file is closed, some in local time labelled UTC: it places a video on
the telemetry's UNIX clock to within a second or so when the camera's clock was set, not better. A missing or
zero date (1904, 1970: never set) is None.
"""

from __future__ import annotations

import datetime
from pathlib import Path

# earlier than this is a clock that was never set (the 1904 and 1970 epochs, a camera's default date)
EARLIEST = datetime.datetime(2000, 1, 1, tzinfo=datetime.timezone.utc)


def creation_time_ns(path) -> int | None:
    """UNIX ns of the container's creation_time (format-level, else the first video stream's), or None when the
    file states none (or an unset clock). A time without a zone is taken as UTC, as FFmpeg writes it."""
    import av

    try:
        with av.open(str(Path(path))) as container:
            text = container.metadata.get("creation_time")
            if text is None and container.streams.video:
                text = container.streams.video[0].metadata.get("creation_time")
    except (av.error.FFmpegError, OSError, ValueError):
        return None
    if not text:
        return None
    try:
        when = datetime.datetime.fromisoformat(text.strip().replace("Z", "+00:00"))
    except ValueError:
        return None
    if when.tzinfo is None:
        when = when.replace(tzinfo=datetime.timezone.utc)
    if when < EARLIEST:
        return None
    return round(when.replace(microsecond=0).timestamp()) * 10**9 + when.microsecond * 1000
