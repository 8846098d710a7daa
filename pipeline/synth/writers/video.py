"""Video as `video.mp4` (mp4v, what opencv-python-headless can encode) plus `video.frames.csv` giving each
written frame's presentation time on the video clock (bursts make the stream variable-rate, which the mp4v
writer cannot express: the container's own timestamps are a constant fps). The container states when recording
started (`creation_time`, whole UTC seconds, as cameras write it), remuxed in by PyAV: OpenCV's writer sets no
metadata."""

from __future__ import annotations

from collections.abc import Iterable
from pathlib import Path

import cv2
import numpy as np

from pipeline.errors import InputError


def write_video(path: Path, frames: Iterable[np.ndarray], pts_ns: np.ndarray, fps: int,
                size_px: tuple[int, int], start_ns: int | None = None) -> int:
    """Write BGR uint8 frames (h, w, 3) to `path` and the sidecar CSV next to it; returns the frame count.
    start_ns: the UNIX time of the video clock's zero (recording start), written as the container's creation
    time (truncated to the second, as the MP4 header keeps it)."""
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"mp4v"), fps, size_px)
    if not writer.isOpened():
        raise InputError("OpenCV cannot open an mp4v video writer", path)
    n = 0
    try:
        for img in frames:
            writer.write(img)
            n += 1
    finally:
        writer.release()
    if n != len(pts_ns):
        raise RuntimeError(f"wrote {n} frames but have {len(pts_ns)} timestamps")
    if start_ns is not None:
        _set_creation_time(path, start_ns)
    lines = ["frame_index,pts_ns"] + [f"{i},{int(t)}" for i, t in enumerate(pts_ns)]
    frames_csv_path(path).write_text("\n".join(lines) + "\n")
    return n


def _set_creation_time(path: Path, start_ns: int) -> None:
    """Rewrite the video at `path` with its packets unchanged and `creation_time` set to start_ns (UNIX ns)."""
    import datetime

    import av

    when = datetime.datetime.fromtimestamp(start_ns // 10**9, tz=datetime.timezone.utc)
    tmp = path.with_name(path.name + ".tmp.mp4")
    with av.open(str(path)) as src, av.open(str(tmp), "w") as dst:
        dst.metadata["creation_time"] = when.strftime("%Y-%m-%dT%H:%M:%S.000000Z")
        stream = src.streams.video[0]
        out = dst.add_stream_from_template(stream)
        for packet in src.demux(stream):
            if packet.dts is None:  # the demuxer's empty flush packet
                continue
            packet.stream = out
            dst.mux(packet)
    tmp.replace(path)


def frames_csv_path(video_path: Path) -> Path:
    return video_path.with_name(video_path.stem + ".frames.csv")


def read_video_frames(path: Path) -> list[np.ndarray]:
    """All decoded frames of a video (tests, checksums)."""
    cap = cv2.VideoCapture(str(path))
    out = []
    while True:
        ok, img = cap.read()
        if not ok:
            break
        out.append(img)
    cap.release()
    return out
