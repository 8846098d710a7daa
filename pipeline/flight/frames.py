"""The frames of a flight: their index (frame numbers and video-clock times, no pixels) and a decoder of chosen
frames. `FrameSource` is the interface every kind of frames gives (a video file, a full-motion video stream, a
bag's image topic; an image folder would be one more `open_frames` branch); it is a context manager that closes
the reader."""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence

import cv2
import numpy as np

from pipeline.errors import ConfigError, RidgelocError
from pipeline.flight_config import FlightConfig
from pipeline.ingest.model import FlightLog, FrameSeries


def cut_off_warnings(warnings: Sequence[str]) -> list[str]:
    """The warnings of a video or log that looks cut off or whose demuxing stopped early (`ingest.video`)."""
    return [w for w in warnings if "looks cut off" in w or "demuxing stopped early" in w]


def with_cut_off(exc: RidgelocError, warnings: Sequence[str]) -> RidgelocError:
    """`exc` with the cut-off warnings among `warnings` added to its one line (what is missing may be in the
    part of the file that was lost)."""
    cut = cut_off_warnings(warnings)
    if cut:
        exc.args = (str(exc) + "".join(f"; {w}" for w in cut), *exc.args[1:])
    return exc


class TimedDecoder:
    """Decodes chosen frame numbers to grayscale and accumulates the time spent. `prefetch(order)` announces the
    frame numbers that will be asked for, in that order, to a reader that can decode ahead (a video file: worker
    threads); a no-op for others."""

    def __init__(self, read: Callable[[list[int]], dict[int, np.ndarray]],
                 prefetch: Callable[[list[int]], None] | None = None):
        self._read = read
        self._prefetch = prefetch
        self.seconds = 0.0
        self.cpu_seconds = 0.0
        self.decoded = 0
        self.failed: list[int] = []

    def __call__(self, indices: Sequence[int]) -> dict[int, np.ndarray]:
        t, c = time.perf_counter(), time.process_time()
        wanted = sorted(set(int(i) for i in indices))
        try:
            images = self._read(wanted)
        except RidgelocError:  # a truncated or damaged stream: keep the frames that decode, the others are lost
            images = {}
            for i in wanted:
                try:
                    images.update(self._read([i]))
                except RidgelocError:
                    self.failed.append(i)
        out = {i: (img if img.ndim == 2 else cv2.cvtColor(img, cv2.COLOR_BGR2GRAY)) for i, img in images.items()}
        self.seconds += time.perf_counter() - t
        self.cpu_seconds += time.process_time() - c
        self.decoded += len(out)
        return out

    def prefetch(self, order: Sequence[int]) -> None:
        if self._prefetch is not None:
            self._prefetch([int(i) for i in order])


class FrameSource:
    """`frames`: the FrameSeries (index, t_ns on the video clock); `decoder(indices)` -> {index: gray image}
    (a TimedDecoder); `keyframe` (n,) bool, aligned with `frames`: the frames that decode on their own (None
    where every frame does, or it is not known); `close()` releases the reader (also on leaving a `with` block;
    closing twice is harmless). `warnings`: the video file's own (it looks cut off), for the flight's notes."""

    def __init__(self, frames: FrameSeries, read: Callable[[list[int]], dict[int, np.ndarray]], closable=None,
                 prefetch: Callable[[list[int]], None] | None = None, keyframe: np.ndarray | None = None,
                 warnings: Sequence[str] = ()):
        self.frames = frames
        self.keyframe = keyframe
        self.warnings = list(warnings)
        self.decoder = TimedDecoder(read, prefetch)
        self._closable = closable

    def colour(self, indices: Sequence[int]) -> dict[int, np.ndarray]:
        """{index: BGR image} of a video's frames, for a person to look at (`ridgeloc mark`); the tracker's gray
        images where the frames are not a video file's (a bag's image topic). Not timed, no prefetch."""
        from pipeline import ingest

        video = self._closable
        if not isinstance(video, ingest.VideoFrames):
            return self.decoder(indices)
        try:
            with ingest.VideoFrames(video.path, index=video.index) as colour:
                return colour.read(sorted(set(int(i) for i in indices)))
        except RidgelocError:  # a damaged stream: the tracker's reader keeps the frames that decode
            return self.decoder(indices)

    def close(self) -> None:
        closable, self._closable = self._closable, None
        close = getattr(closable, "close", None)
        if close is not None:
            close()

    def __enter__(self) -> FrameSource:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def _keyframes(video, frames: FrameSeries) -> np.ndarray | None:
    """(n,) bool: which of `frames` (numbered in the video's display order) are key frames; None when all are."""
    flags = np.asarray(video.index.keyframe, dtype=bool)
    index = np.asarray(frames.index, dtype=np.int64)
    if index.size == 0 or index.max() >= flags.size:
        return None
    key = flags[index]
    return None if key.all() else key


def open_frames(config: FlightConfig, log: FlightLog) -> FrameSource:
    """The flight's frames: the video file when the config names one, else the full-motion video the telemetry
    came from, else the image topic of a bag the telemetry came from."""
    from pipeline import ingest

    if config.files.video is not None:
        video = ingest.VideoFrames(config.files.video, gray=True)  # demuxes the file once: its index serves both
        try:
            frames = ingest.read_video(config.files.video, frames_csv=config.files.frames_csv or "auto",
                                       index=video.index)
        except RidgelocError as exc:  # a frames CSV longer than a cut-off video: say that it looks cut off
            video.close()
            raise with_cut_off(exc, video.index.warnings) from None
        except BaseException:
            video.close()
            raise
        return FrameSource(frames, video.read, video, video.prefetch, _keyframes(video, frames),
                           video.index.warnings)
    if log.frames is not None and "fmv" in log.formats:  # full-motion video: the frames of the telemetry file
        video = ingest.VideoFrames(log.frames.source, gray=True, index=log.video_indexes.get(log.frames.source))
        return FrameSource(log.frames, video.read, video, video.prefetch, _keyframes(video, log.frames))
    if log.frames is None:
        raise ConfigError("the flight has no video (files.video) and its logs carry no images", config.path)
    for path in config.files.telemetry:
        try:
            images = ingest.BagImages(path, None, mapping=config.mapping, frames=log.frames)
        except (RidgelocError, ValueError, KeyError):
            continue
        return FrameSource(images.frames, images.read)
    raise ConfigError(f"cannot open the image stream {log.frames.source!r} of the flight's logs", config.path)
