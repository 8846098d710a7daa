"""Video as `video.mp4` (mp4v, what opencv-python-headless can encode) plus `video.frames.csv` giving each
written frame's presentation time on the video clock (bursts make the stream variable-rate, which the mp4v
writer cannot express: the container's own timestamps are a constant fps)."""

from __future__ import annotations

from collections.abc import Iterable
from pathlib import Path

import cv2
import numpy as np

from pipeline.errors import InputError


def write_video(path: Path, frames: Iterable[np.ndarray], pts_ns: np.ndarray, fps: int,
                size_px: tuple[int, int]) -> int:
    """Write BGR uint8 frames (h, w, 3) to `path` and the sidecar CSV next to it; returns the frame count."""
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
    lines = ["frame_index,pts_ns"] + [f"{i},{int(t)}" for i, t in enumerate(pts_ns)]
    frames_csv_path(path).write_text("\n".join(lines) + "\n")
    return n


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
