"""Readers of flight logs, bags and video into one columnar time-series model (`pipeline.ingest.model`).

Public API:
- `read_flight(paths, mapping=None) -> FlightLog`: every file of one flight, merged;
- `read_video(path, frames_csv=None) -> FrameSeries` and `VideoFrames(path)` to decode chosen frames;
- `BagImages(path, topic)` to get the FrameSeries of an image topic in a bag and decode chosen messages;
- `inspect_paths(paths) -> list[InspectResult]` for `ridgeloc inspect`;
- `series_to_clock(series, links, "unix")`, `gimbal_to_earth(gimbal, attitude)`.
"""

from pipeline.ingest.clocks import series_to_clock
from pipeline.ingest.dispatch import detect_format, merge_logs, read_file, read_flight
from pipeline.ingest.frames import gimbal_to_earth
from pipeline.ingest.mapping import default_mapping, mapping_for
from pipeline.ingest.model import FlightLog


def read_video(path, frames_csv="auto", index=None):
    """Per-frame presentation times of a video (see `pipeline.ingest.video.read_video`)."""
    from pipeline.ingest.video import read_video as _read_video
    return _read_video(path, frames_csv=frames_csv, index=index)


def __getattr__(name):
    if name == "VideoFrames":
        from pipeline.ingest.video import VideoFrames
        return VideoFrames
    if name == "BagImages":
        from pipeline.ingest.rosbag import BagImages
        return BagImages
    if name in ("inspect_paths", "InspectResult"):
        from pipeline.ingest import inspect as _inspect
        return getattr(_inspect, name)
    raise AttributeError(name)


__all__ = ["BagImages", "FlightLog", "InspectResult", "VideoFrames", "default_mapping", "detect_format",
           "gimbal_to_earth", "inspect_paths", "mapping_for", "merge_logs", "read_file", "read_flight",
           "read_video", "series_to_clock"]
