"""Video files through PyAV (FFmpeg): a frame index from the packet demux alone, and decoding of chosen frames.

Indexing reads packets, never pixels: each video packet's pts (dts when it has none) and key-frame flag, sorted
into display order, so a 10-minute 4K file is indexed in about the time of a bare demux and in constant memory
(numpy int64 per frame). Variable frame rates keep their own times, MPEG-TS included. Times are on the "video"
clock: 0 is the first frame's pts. `<stem>.frames.csv` (header `frame_index,pts_ns`), when present, overrides the
container's times (the synthetic mp4v flights write one: bursts make them variable-rate, which mp4v cannot say).

Decoding (`VideoFrames`) seeks to the key frame at or before a wanted frame and decodes forward to it, or simply
decodes forward when the wanted frame is later in the same group of pictures as the last one decoded; frames on
the way are decoded but not converted, and nothing is kept but the frames asked for.
"""

from __future__ import annotations

from array import array
from dataclasses import dataclass, field
from fractions import Fraction
from pathlib import Path

import numpy as np

from pipeline.errors import LogReadError
from pipeline.frames_csv import read_frames_csv
from pipeline.ingest.model import FrameSeries

VIDEO_SUFFIXES = {".mp4", ".mov", ".avi", ".mkv", ".m4v", ".mpg", ".mpeg", ".ts", ".webm"}


def _av():
    import av

    return av


def _why(exc) -> str:
    """FFmpeg's reason without the file name it appends (the message names the file once)."""
    return getattr(exc, "strerror", None) or str(exc)


def _open(path: Path):
    if not path.is_file():
        raise LogReadError("no such video file", path=path)
    if path.stat().st_size == 0:
        raise LogReadError("empty video file", path=path)
    av = _av()
    try:
        container = av.open(str(path))
    except (av.error.FFmpegError, OSError, ValueError) as exc:
        raise LogReadError(f"cannot open this video (not a video, or truncated): {_why(exc)}", path=path) from None
    if not container.streams.video:
        container.close()
        raise LogReadError("the file has no video stream", path=path)
    return container


def frames_csv_for(path: Path, frames_csv="auto") -> Path | None:
    """The frames CSV to use: explicit path, or `<stem>.frames.csv` beside the video (None/"auto"), or none
    (False)."""
    if frames_csv is False:
        return None
    if frames_csv in (None, "auto"):
        cand = path.with_suffix(".frames.csv")
        return cand if cand.is_file() else None
    return Path(frames_csv)


@dataclass
class DemuxIndex:
    """What one demux pass of a file gives. frames: FrameSeries (display order, container times);
    pts (n,) int64 raw pts of each frame in `time_base`; keyframe (n,) bool; data_packets: [(bytes, t_ns on the
    video clock or None)] of the data (KLV) streams when asked for; pos (n,) byte offsets of the packets."""

    frames: FrameSeries
    pts: np.ndarray
    keyframe: np.ndarray
    time_base: Fraction
    data_packets: list = field(default_factory=list)
    pos: np.ndarray | None = None  # (n,) int64 byte offset of each frame's packet (-1: unknown)


def demux_index(path, data_streams: bool = False) -> DemuxIndex:
    """Index the first video stream of `path` (and collect its data-stream packets) by demuxing packets only."""
    path = Path(path)
    av = _av()
    container = _open(path)
    try:
        vs = container.streams.video[0]
        streams = [vs] + (list(container.streams.data) if data_streams else [])
        pts, key, pos = array("q"), array("b"), array("q")
        data: list[tuple[bytes, int | None, Fraction]] = []
        try:
            for pkt in container.demux(streams):
                if pkt.size == 0:
                    continue
                if pkt.stream is vs:
                    t = pkt.pts if pkt.pts is not None else pkt.dts
                    if t is None:
                        continue
                    pts.append(t)
                    key.append(pkt.is_keyframe)
                    pos.append(-1 if pkt.pos is None else pkt.pos)
                else:
                    t = pkt.pts if pkt.pts is not None else pkt.dts
                    data.append((bytes(pkt), t, pkt.time_base or pkt.stream.time_base))
        except av.error.FFmpegError as exc:  # damaged tail: keep what was read
            if not pts:
                raise LogReadError(f"cannot demux this video: {_why(exc)}", path=path) from None
        cc = vs.codec_context  # None when damage leaves the stream without a decoder
        width, height = (cc.width, cc.height) if cc is not None else (0, 0)
        tb = vs.time_base or Fraction(1, 90000)
    finally:
        container.close()
    if not pts or not width or not height:
        raise LogReadError("video has no frames", path=path)
    raw = np.frombuffer(pts, dtype=np.int64)
    order = np.argsort(raw, kind="stable")
    raw = raw[order]
    keyframe = np.frombuffer(key, dtype=np.int8)[order].astype(bool)
    offsets = np.frombuffer(pos, dtype=np.int64)[order]
    t0 = int(raw[0])
    t_ns = ((raw - t0) * (tb.numerator * 10**9) + tb.denominator // 2) // tb.denominator
    origin = Fraction(t0) * tb
    packets = [(b, None if t is None else round((Fraction(t) * dtb - origin) * 10**9)) for b, t, dtb in data]
    frames = FrameSeries(t_ns.astype(np.int64), np.arange(raw.size, dtype=np.int64), source=str(path), clock="video",
                         width_px=int(width), height_px=int(height))
    return DemuxIndex(frames, raw, keyframe, tb, packets, offsets)


def read_video(path, frames_csv="auto", index: DemuxIndex | None = None) -> FrameSeries:
    """FrameSeries of a video: t_ns (n,) presentation times on the "video" clock, index (n,) frame numbers.
    `index`: this file's demux index when the caller already has it."""
    path = Path(path)
    index = index if index is not None else demux_index(path)
    csv_path = frames_csv_for(path, frames_csv)
    if csv_path is None:
        return index.frames
    idx, t_ns = read_frames_csv(csv_path)
    n = index.frames.t_ns.size
    if idx.max() >= n:
        raise LogReadError(f"frames CSV {csv_path.name} lists frame {int(idx.max())} but the video has {n} frames",
                           path=path)
    order = np.argsort(t_ns, kind="stable")
    f = index.frames
    return FrameSeries(t_ns[order], idx[order], source=f.source, clock="video", width_px=f.width_px,
                       height_px=f.height_px)


class VideoFrames:
    """Decode chosen frames of a video: `frames[i]` or `frames.read([i, j, ...])` -> uint8 BGR (h, w, 3), or
    (h, w) grayscale with gray=True. Frame i is the i-th in display order (as `read_video` numbers them).

    `seek_after`: a wanted frame more than this many frames ahead of the decoder is reached by a seek to its key
    frame even within one group of pictures (None: only when a key frame lies in between)."""

    def __init__(self, path, seek_after: int | None = None, gray: bool = False, index: DemuxIndex | None = None):
        self.path = Path(path)
        self.seek_after = seek_after
        self.gray = gray
        self.index = index if index is not None else demux_index(self.path)
        self._key_pos = np.flatnonzero(self.index.keyframe)
        if self._key_pos.size == 0 or self._key_pos[0] != 0:
            self._key_pos = np.concatenate([[0], self._key_pos])
        self._container = _open(self.path)
        self._stream = self._container.streams.video[0]
        self._stream.thread_type = "AUTO"
        self._byte_seek = "mpegts" in (self._container.format.name or "")
        self._frames = None  # decoder generator, positioned after frame self._pos
        self._pos = -1
        self.decoded = 0  # frames decoded, wanted or not (for benchmarks)

    def close(self) -> None:
        self._frames = None
        self._container.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    def _seek_plans(self, i: int) -> list[tuple[str, int]]:
        """Ways to put the decoder at or before display position i, most exact first: a byte seek to the key
        frame's packet (MPEG-TS, where timestamp seeks can land a group of pictures late), timestamp seeks to the
        key frame and to the two before it, and the start of the file."""
        j = int(np.searchsorted(self._key_pos, i, side="right") - 1)
        keys = [int(self._key_pos[max(j - b, 0)]) for b in range(3)]
        plans: list[tuple[str, int]] = []
        pos = self.index.pos
        if self._byte_seek and pos is not None and pos[keys[0]] >= 0:
            plans.append(("byte", int(pos[keys[0]])))
        plans += [("pts", int(self.index.pts[k])) for k in dict.fromkeys(keys)]
        plans.append(("pts", int(self.index.pts[0])))
        return plans

    def _seek(self, how: str, offset: int) -> None:
        av = _av()
        try:
            if how == "byte":
                self._container.seek(offset, unsupported_byte_offset=True)
            else:
                self._container.seek(offset, stream=self._stream, backward=True, any_frame=False)
        except av.error.FFmpegError as exc:
            raise LogReadError(f"cannot seek in this video: {_why(exc)}", path=self.path) from None
        self._frames = self._container.decode(self._stream)
        self._pos = -1

    def _convert(self, frame) -> np.ndarray:
        return frame.to_ndarray(format="gray" if self.gray else "bgr24")

    def _decode_to(self, target: int, fresh: bool):
        """Decode forward to the frame with pts `target`: the frame, or None when the decoder is already past it
        (an inexact seek: the first frame after it is later than the target) or the stream ends."""
        av = _av()
        first = fresh
        try:
            for frame in self._frames:
                self.decoded += 1
                p = frame.pts if frame.pts is not None else frame.dts
                if p is None:
                    continue
                self._pos = int(np.searchsorted(self.index.pts, p))
                if p == target:
                    return frame
                if p > target:
                    if not first:
                        self._frames = None
                    return None
                first = False
        except av.error.FFmpegError as exc:
            raise LogReadError(f"cannot decode the video near pts {target}: {_why(exc)}", path=self.path) from None
        self._frames = None
        return None

    def __getitem__(self, i: int) -> np.ndarray:
        i = int(i)
        n = self.index.pts.size
        if i < 0:
            raise IndexError(i)
        if i >= n:
            raise LogReadError(f"video ends before frame {i} (has {n})", path=self.path)
        target = int(self.index.pts[i])
        key_before = int(self._key_pos[np.searchsorted(self._key_pos, i, side="right") - 1])
        far = self.seek_after is not None and i - self._pos > self.seek_after
        if self._frames is not None and self._pos < i and key_before <= self._pos and not far:
            frame = self._decode_to(target, fresh=False)  # same group of pictures: decode on
            if frame is not None:
                return self._convert(frame)
        for how, offset in self._seek_plans(i):
            self._seek(how, offset)
            frame = self._decode_to(target, fresh=True)
            if frame is not None:
                return self._convert(frame)
        raise LogReadError(f"video ends before frame {i} (frame not decodable)", path=self.path)

    def read(self, indices) -> dict[int, np.ndarray]:
        """Decode the given frame indices (any order, duplicates allowed) -> {index: image}."""
        return {i: self[i] for i in sorted(set(int(i) for i in indices))}
