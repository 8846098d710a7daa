"""Video files through PyAV (FFmpeg): a frame index from the packet demux alone, and decoding of chosen frames.

Indexing reads packets, never pixels: each video packet's pts (dts when it has none) and key-frame flag, sorted
into display order, so a 10-minute 4K file is indexed in about the time of a bare demux and in constant memory
(numpy int64 per frame). Variable frame rates keep their own times, MPEG-TS included. Times are on the "video"
clock: 0 is the first frame's pts. `<stem>.frames.csv` (header `frame_index,pts_ns`), when present, overrides the
container's times (the synthetic mp4v flights write one: bursts make them variable-rate, which mp4v cannot say).

Decoding (`VideoFrames`) seeks to the key frame at or before a wanted frame and decodes forward to it, or simply
decodes forward when the wanted frame is later in the same group of pictures as the last one decoded; frames on
the way are decoded but not converted, and nothing is kept but the frames asked for. `VideoFrames.prefetch(order)`
announces the frames a caller will ask for, in that order: worker threads, each with its own decoder, decode them
ahead (a group of pictures per worker at a time, a few groups ahead of the caller at most, so memory is bounded by
the frames in flight, not the video's length) while the caller works on the frames it has; FFmpeg decodes without
the interpreter lock, so the workers and the caller's OpenCV use every core.
"""

from __future__ import annotations

import functools
import threading
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


_MMAP_THRESHOLD_BYTES = 4 * 2**20


@functools.cache
def _large_buffers_to_the_os() -> None:
    """Have glibc serve allocations of 4 MiB and more (decoded 4K frames, SIFT's scale space) from their own
    mappings, returned to the OS when freed. By default glibc raises that threshold to the largest block freed
    so far (up to 32 MiB), after which 8 MiB frames freed by one thread stay in its heap arena while another
    thread allocates new ones: on the 4K bench the run's peak was 484 MiB with the default and 442 MiB with this
    (scripts/bench_video.py). A no-op where the C library is not glibc. Process-wide, once."""
    import ctypes
    import ctypes.util

    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
        mallopt = libc.mallopt
    except (OSError, AttributeError):
        return
    M_MMAP_THRESHOLD = -3
    mallopt(M_MMAP_THRESHOLD, _MMAP_THRESHOLD_BYTES)


def _why(exc) -> str:
    """FFmpeg's reason without the file name it appends (the message names the file once)."""
    return getattr(exc, "strerror", None) or str(exc)


def _open(path: Path):
    if path.is_dir():
        raise LogReadError("a folder, not a video file", path=path)
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
    warnings: list[str] = field(default_factory=list)  # a file that looks cut off


def first_fields(pts: np.ndarray, average_rate, base_rate, time_base: Fraction) -> np.ndarray | None:
    """(n,) bool: the packets (pts sorted, time_base units) that start a frame, where the stream is coded as
    fields: FFmpeg's base rate twice the average frame rate, packets half a frame apart, and half of them on the
    frame grid of the first packet, the other half half a frame off it (a frame's second field, which decodes
    into the frame of the first). None for any other stream: every packet is a frame."""
    if not average_rate or not base_rate or pts.size < 4 or abs(base_rate / average_rate - 2) > 0.01:
        return None
    frame_ticks = float(1 / (Fraction(average_rate) * time_base))
    phase = ((pts - pts[0]) / frame_ticks) % 1.0
    first = (phase < 0.2) | (phase > 0.8)
    second = np.abs(phase - 0.5) < 0.2
    if not (first | second).all() or abs(int(first.sum()) - int(second.sum())) > max(2, 0.05 * pts.size):
        return None
    return first


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
        warnings = _cut_off(path, container)
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
            warnings.append(f"{path.name}: demuxing stopped early ({_why(exc)}): the frames and metadata after "
                            f"{len(pts)} frames are not read")
        cc = vs.codec_context  # None when damage leaves the stream without a decoder
        width, height = (cc.width, cc.height) if cc is not None else (0, 0)
        tb = vs.time_base or Fraction(1, 90000)
        rates = (vs.average_rate, vs.base_rate)
    finally:
        container.close()
    if not pts or not width or not height:
        raise LogReadError("video has no frames", path=path)
    raw = np.frombuffer(pts, dtype=np.int64)
    order = np.argsort(raw, kind="stable")
    raw = raw[order]
    keyframe = np.frombuffer(key, dtype=np.int8)[order].astype(bool)
    offsets = np.frombuffer(pos, dtype=np.int64)[order]
    frame = first_fields(raw, *rates, tb)
    if frame is not None:  # field-coded (interlaced H.264 PAFF): one frame per pair of field packets
        raw, keyframe, offsets = raw[frame], keyframe[frame], offsets[frame]
    t0 = int(raw[0])
    t_ns = ((raw - t0) * (tb.numerator * 10**9) + tb.denominator // 2) // tb.denominator
    origin = Fraction(t0) * tb
    packets = [(b, None if t is None else round((Fraction(t) * dtb - origin) * 10**9)) for b, t, dtb in data]
    frames = FrameSeries(t_ns.astype(np.int64), np.arange(raw.size, dtype=np.int64), source=str(path), clock="video",
                         width_px=int(width), height_px=int(height))
    return DemuxIndex(frames, raw, keyframe, tb, packets, offsets, warnings)


def _cut_off(path: Path, container) -> list[str]:
    """A warning when an MPEG transport stream's size is no whole number of 188-byte packets (nor of the 192-byte
    ones of M2TS): the file was cut off mid-packet (a copy or a recording that stopped), so its tail is lost."""
    if "mpegts" not in (container.format.name or ""):
        return []
    size = path.stat().st_size
    if size % 188 == 0 or size % 192 == 0:
        return []
    return [f"{path.name}: ends inside a transport packet ({size:,} bytes, {size % 188} past the last whole "
            "188-byte packet): the file looks cut off, and the frames and metadata after its end are missing"]


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

    def __init__(self, path, seek_after: int | None = None, gray: bool = False, index: DemuxIndex | None = None,
                 thread_type: str = "SLICE"):
        _large_buffers_to_the_os()
        self.path = Path(path)
        self.seek_after = seek_after
        self.gray = gray
        self.index = index if index is not None else demux_index(self.path)
        self._key_pos = np.flatnonzero(self.index.keyframe)
        if self._key_pos.size == 0 or self._key_pos[0] != 0:
            self._key_pos = np.concatenate([[0], self._key_pos])
        self._container = _open(self.path)
        self._stream = self._container.streams.video[0]
        self._stream.thread_type = thread_type
        self._byte_seek = "mpegts" in (self._container.format.name or "")
        self._frames = None  # decoder generator, positioned after frame self._pos
        self._pos = -1
        self.decoded = 0  # frames decoded, wanted or not (for benchmarks)
        self._prefetch: _Prefetch | None = None

    def close(self) -> None:
        self.prefetch(())
        self._frames = None
        self._container.close()

    def prefetch(self, order, workers: int = 2, ahead: int = 2) -> None:
        """Decode the frames `order` (display positions, in the order they will be asked for) ahead, on `workers`
        threads each holding at most `ahead` groups of pictures' worth of wanted frames beyond the caller's
        position; `read` and `[]` take them from there. A new call replaces the previous plan; `()` ends it."""
        if self._prefetch is not None:
            self.decoded += self._prefetch.close()
            self._prefetch = None
        order = [int(i) for i in order if 0 <= int(i) < self.index.pts.size]
        if order and workers > 0:
            self._prefetch = _Prefetch(self, order, workers, ahead)

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
        # a copy: PyAV's array is a view of the frame's buffer, which would keep the whole picture (and the
        # decoder's buffer pool behind it) alive as long as the image is
        return np.array(frame.to_ndarray(format="gray" if self.gray else "bgr24"), copy=True)

    def key_before(self, i: int) -> int:
        """The display position of the key frame at or before display position i."""
        return int(self._key_pos[np.searchsorted(self._key_pos, i, side="right") - 1])

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
        if self._prefetch is not None:
            got = self._prefetch.take(i)
            if got is not None:
                return got
        return self._decode(i)

    def _decode(self, i: int) -> np.ndarray:
        n = self.index.pts.size
        if i < 0:
            raise IndexError(i)
        if i >= n:
            raise LogReadError(f"video ends before frame {i} (has {n})", path=self.path)
        target = int(self.index.pts[i])
        key_before = self.key_before(i)
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


class _Prefetch:
    """Worker threads decoding a planned order of frames ahead of the caller (`VideoFrames.prefetch`).

    The order is cut into runs of frames going forward within one group of pictures (decoded on without a seek);
    runs go to the workers in turn, and a worker starts a run only when it begins fewer than `ahead` runs of the
    caller's position. A frame the caller asks for is removed when taken (asked for again, a retry, it is decoded
    by the caller's own reader); frames of the plan the caller has gone past are dropped."""

    def __init__(self, video: VideoFrames, order: list[int], workers: int, ahead: int):
        self.position = {}  # frame -> its first place in the order
        for k, i in enumerate(order):
            self.position.setdefault(i, k)
        runs: list[list[int]] = []
        for k, i in enumerate(order):
            if runs and i > order[k - 1] and video.key_before(i) <= order[k - 1]:
                runs[-1].append(k)
            else:
                runs.append([k])
        self.order, self.runs, self.ahead = order, runs, ahead
        self.done: dict[int, object] = {}  # frame -> image, or the exception its decode raised
        self.taken: set[int] = set()  # frames handed to the caller: no worker decodes them again
        self.caller = 0  # place in the order the caller has reached
        self.stopped = False
        self.decoded = 0
        self.cond = threading.Condition()
        args = (video.path, video.gray, video.index, video._stream.thread_type)
        self.threads = [threading.Thread(target=self._work, args=(w, workers, args), daemon=True)
                        for w in range(min(workers, len(runs)))]
        for t in self.threads:
            t.start()

    def _work(self, w: int, workers: int, args) -> None:
        path, gray, index, thread_type = args
        try:
            reader = VideoFrames(path, gray=gray, index=index, thread_type=thread_type)
        except BaseException as exc:  # handed to the caller with the frames it concerns
            reader, failure = None, exc
        try:
            for r in range(w, len(self.runs), workers):
                run = self.runs[r]
                start = run[0]
                with self.cond:
                    self.cond.wait_for(lambda s=start: self.stopped or s - self.caller < self.ahead * workers)
                    if self.stopped:
                        return
                for k in run:
                    i = self.order[k]
                    with self.cond:
                        if self.stopped:
                            return
                        if k < self.caller or i in self.done:
                            continue
                    try:
                        if reader is None:
                            raise failure
                        got = reader._decode(i)
                    except BaseException as exc:  # re-raised by take() in the caller's thread
                        got = exc
                    with self.cond:
                        self.done[i] = got
                        self.cond.notify_all()
        finally:
            if reader is not None:
                with self.cond:
                    self.decoded += reader.decoded
                reader.close()

    def take(self, i: int) -> np.ndarray | None:
        """Frame i from the plan (waiting for its worker), or None when it is not in the plan still ahead or was
        taken already."""
        k = self.position.get(i)
        with self.cond:
            if k is None or i in self.taken or (k < self.caller and i not in self.done):
                return None
            self.caller = max(self.caller, k)
            for j in [j for j in self.done if self.position[j] < self.caller and j != i]:
                del self.done[j]  # planned frames the caller went past
            self.cond.notify_all()
            self.cond.wait_for(lambda: i in self.done or not any(t.is_alive() for t in self.threads))
            got = self.done.pop(i, None)
            self.taken.add(i)
        if isinstance(got, BaseException):
            raise got
        return got

    def close(self) -> int:
        """Stop the workers; the number of frames they decoded."""
        with self.cond:
            self.stopped = True
            self.cond.notify_all()
        for t in self.threads:
            t.join()
        return self.decoded
