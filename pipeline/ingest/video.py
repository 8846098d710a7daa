"""Video files through OpenCV: per-frame presentation times and decoding of chosen frames only.

Frame times come from `<stem>.frames.csv` (header `frame_index,pts_ns`) when present — the synthetic flights
write one because their streams are variable-rate, which mp4v cannot express — else from the container's
timestamp of each grabbed frame (`CAP_PROP_POS_MSEC` after `grab()`, which the FFmpeg backend takes from the
packet's pts, so variable frame rate keeps its timing). Times are on the "video" clock, starting at the
container's first pts.
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from pipeline.errors import LogReadError
from pipeline.ingest.model import FrameSeries


def _open(path: Path) -> cv2.VideoCapture:
    if not path.is_file():
        raise LogReadError("no such video file", path=path)
    if path.stat().st_size == 0:
        raise LogReadError("empty video file", path=path)
    cap = cv2.VideoCapture(str(path))
    if not cap.isOpened():
        raise LogReadError("OpenCV cannot open this video (not a video, or truncated)", path=path)
    return cap


def frames_csv_for(path: Path, frames_csv="auto") -> Path | None:
    """The frames CSV to use: explicit path, or `<stem>.frames.csv` beside the video (None/"auto"), or none
    (False)."""
    if frames_csv is False:
        return None
    if frames_csv in (None, "auto"):
        cand = path.with_suffix(".frames.csv")
        return cand if cand.is_file() else None
    return Path(frames_csv)


def _read_frames_csv(csv_path: Path) -> tuple[np.ndarray, np.ndarray]:
    try:
        with open(csv_path) as f:
            header = f.readline().strip().split(",")
            if header[:2] != ["frame_index", "pts_ns"]:
                raise LogReadError(f"expected header 'frame_index,pts_ns', got {','.join(header)!r}", path=csv_path)
            data = np.loadtxt(f, delimiter=",", dtype=np.int64, ndmin=2)
    except OSError as exc:
        raise LogReadError(f"cannot read frames CSV: {exc.strerror}", path=csv_path) from None
    except ValueError as exc:
        raise LogReadError(f"malformed frames CSV: {exc}", path=csv_path) from None
    if data.size == 0:
        raise LogReadError("frames CSV has no rows", path=csv_path)
    if data.shape[1] < 2:
        raise LogReadError("malformed frames CSV: rows need frame_index,pts_ns", path=csv_path)
    return data[:, 0].copy(), data[:, 1].copy()


def read_video(path, frames_csv="auto") -> FrameSeries:
    """FrameSeries of a video: t_ns (n,) presentation times on the "video" clock, index (n,) frame numbers."""
    path = Path(path)
    cap = _open(path)
    try:
        width = int(cap.get(cv2.CAP_PROP_FRAME_WIDTH))
        height = int(cap.get(cv2.CAP_PROP_FRAME_HEIGHT))
        n_container = int(cap.get(cv2.CAP_PROP_FRAME_COUNT))
        csv_path = frames_csv_for(path, frames_csv)
        if csv_path is not None:
            index, t_ns = _read_frames_csv(csv_path)
            if n_container > 0 and index.max() >= n_container:
                raise LogReadError(f"frames CSV {csv_path.name} lists frame {int(index.max())} but the video has "
                                   f"{n_container} frames", path=path)
        else:
            ts = []
            while cap.grab():
                ts.append(cap.get(cv2.CAP_PROP_POS_MSEC))
            if not ts:
                raise LogReadError("video has no frames", path=path)
            t_ns = np.round(np.asarray(ts) * 1e6).astype(np.int64)
            index = np.arange(t_ns.size, dtype=np.int64)
    finally:
        cap.release()
    if width == 0 or height == 0:
        raise LogReadError("video has no frames", path=path)
    order = np.argsort(t_ns, kind="stable")
    return FrameSeries(t_ns[order], index[order], source=str(path), clock="video", width_px=width,
                       height_px=height)


class VideoFrames:
    """Decode chosen frames of a video: `frames[i]` or `frames.read([i, j, ...])` -> BGR uint8 (h, w, 3).

    Frames are reached by `grab()` (demux + decode, no colour conversion) from the current position; a
    backward step reopens the file, a forward jump of more than `seek_after` frames seeks and checks that the
    reported position is the one asked for (falling back to grabbing when it is not).
    """

    def __init__(self, path, seek_after: int = 250):
        self.path = Path(path)
        self.seek_after = seek_after
        self._cap = _open(self.path)
        self._next = 0  # index of the frame the next grab() returns

    def close(self) -> None:
        self._cap.release()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    def _goto(self, index: int) -> None:
        if index < self._next:
            self._cap.release()
            self._cap = _open(self.path)
            self._next = 0
        if index - self._next > self.seek_after:
            self._cap.set(cv2.CAP_PROP_POS_FRAMES, index)
            if int(self._cap.get(cv2.CAP_PROP_POS_FRAMES)) == index:
                self._next = index
            else:
                self._cap.release()
                self._cap = _open(self.path)
                self._next = 0
        while self._next < index:
            if not self._cap.grab():
                raise LogReadError(f"video ends before frame {index} (has {self._next})", path=self.path)
            self._next += 1

    def __getitem__(self, index: int) -> np.ndarray:
        index = int(index)
        if index < 0:
            raise IndexError(index)
        self._goto(index)
        ok, img = self._cap.read()
        if not ok:
            raise LogReadError(f"video ends before frame {index}", path=self.path)
        self._next += 1
        return img

    def read(self, indices) -> dict[int, np.ndarray]:
        """Decode the given frame indices (any order, duplicates allowed) -> {index: image}."""
        return {i: self[i] for i in sorted(set(int(i) for i in indices))}
