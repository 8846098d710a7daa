"""File-type detection, one-file reading, and reading every file of one flight into one FlightLog."""

from __future__ import annotations

from pathlib import Path

from pipeline.errors import InputError, LogReadError
from pipeline.ingest.boundary import reader_boundary
from pipeline.ingest.mapping import check_override, mapping_for
from pipeline.ingest.merge import merge_logs
from pipeline.ingest.model import FlightLog
from pipeline.ingest.video import VIDEO_SUFFIXES

MAGIC = (
    (b"ULog\x01\x12\x35", "ulog"),
    (b"#ROSBAG V2.0", "ros1"),
    (b"\x89MCAP0\r\n", "mcap"),
    (b"\xa3\x95", "dataflash"),
    (b"SQLite format 3\x00", "ros2"),
    (bytes.fromhex("060e2b34"), "klv"),  # a SMPTE Universal Key: raw KLV packets (ffmpeg -map 0:d -f data)
)


def detect_format(path: str | Path) -> str:
    """One of tlog, dataflash (binary or text), ulog, ros1, ros2, mcap, video, srt, klv, by folder layout, magic bytes
    (an `FMT,` line for text DataFlash), then suffix. A video with a KLV data stream (MISB full-motion video) is
    "video" here and read as "fmv"."""
    p = Path(path)
    if not p.exists():
        raise InputError("no such file or folder", path=p)
    if p.is_dir():
        if (p / "metadata.yaml").is_file():
            return "ros2"
        raise LogReadError("folder is not a ROS 2 bag (no metadata.yaml)", path=p)
    suffix = p.suffix.lower()
    if suffix in VIDEO_SUFFIXES:
        return "video"
    if suffix == ".srt":
        return "srt"
    try:
        with open(p, "rb") as f:
            head = f.read(4096)
    except OSError as exc:
        raise LogReadError(f"cannot read: {exc.strerror}", path=p) from None
    for magic, fmt in MAGIC:
        if head.startswith(magic):
            if fmt in ("mcap", "ros2") and (p.parent / "metadata.yaml").is_file():
                return "ros2"
            return fmt
    from pipeline.ingest.dataflash import is_text_dataflash
    if is_text_dataflash(head):
        return "dataflash"  # text DataFlash (.log): Mission Planner's conversion, old firmware
    by_suffix = {".tlog": "tlog", ".bin": "dataflash", ".ulg": "ulog", ".bag": "ros1", ".mcap": "mcap",
                 ".db3": "ros2", ".log": "dataflash", ".klv": "klv"}
    if suffix in by_suffix:
        if not head:
            raise LogReadError("empty file", path=p)
        if suffix in (".tlog", ".klv"):  # no magic of their own (a .klv dump may start mid-packet)
            return by_suffix[suffix]
        what = "text DataFlash log (no FMT lines)" if suffix == ".log" else by_suffix[suffix] + " file"
        raise LogReadError(f"not a {what} (unexpected leading bytes {head[:8]!r})", path=p)
    raise LogReadError(f"unknown log type (suffix {suffix or 'none'!r}, leading bytes {head[:8]!r})", path=p)


def read_file(path: str | Path, mapping: dict | None = None, scan_all: bool = False) -> FlightLog:
    """Read one log, bag folder, video or SRT into a FlightLog. scan_all: also time every stream the
    quantities do not need (for `inspect`; otherwise those are only counted where the format allows).

    What a third-party parser raises on damaged bytes becomes one LogReadError naming the file
    (`boundary.reader_boundary`); one raised in ridgeloc's own code is a bug and is not translated."""
    with reader_boundary(path, "file", LogReadError):
        return _read_file(path, mapping, scan_all)


def _read_file(path: str | Path, mapping: dict | None, scan_all: bool) -> FlightLog:
    fmt = detect_format(path)
    p = Path(path)
    if p.is_file() and fmt == "ros2":
        p = p.parent
    if fmt == "tlog":
        from pipeline.ingest.tlog import read_tlog
        return read_tlog(p, mapping_for("tlog", mapping))
    if fmt == "dataflash":
        from pipeline.ingest.dataflash import read_dataflash
        return read_dataflash(p, mapping_for("dataflash", mapping), scan_all=scan_all)
    if fmt == "ulog":
        from pipeline.ingest.ulog import read_ulog
        return read_ulog(p, mapping_for("ulog", mapping), scan_all=scan_all)
    if fmt in ("ros1", "ros2"):
        from pipeline.ingest.rosbag import read_rosbag
        return read_rosbag(p, mapping_for("ros", mapping), scan_all=scan_all)
    if fmt == "mcap":
        from pipeline.ingest.mcap_plain import read_mcap
        return read_mcap(p, mapping_for("mcap", mapping), mapping_for("ros", mapping), scan_all=scan_all)
    if fmt == "klv":
        from pipeline.ingest.frame_centre import auto_north
        from pipeline.ingest.klv import read_klv_dump
        return read_klv_dump(p, mapping_for("klv", mapping), auto_north)
    if fmt == "video":
        from pipeline.ingest.video import demux_index, read_video
        index = demux_index(p, data_streams=True)
        if index.data_packets:  # MISB full-motion video: telemetry and frames from one file
            from pipeline.ingest.frame_centre import auto_north
            from pipeline.ingest.klv import read_fmv
            return read_fmv(p, index, mapping_for("klv", mapping), auto_north)
        frames = read_video(p, frames_csv=mapping_for("video", mapping)["frames_csv"], index=index)
        from pipeline.ingest.model import StreamInfo
        stream = StreamInfo(p.name, "video", int(frames.t_ns.size),
                            int(frames.t_ns[0]) if frames.t_ns.size else None,
                            int(frames.t_ns[-1]) if frames.t_ns.size else None, ("frames",))
        return FlightLog(path=str(p), frames=frames, streams=[stream], formats=["video"],
                         warnings=list(index.warnings))
    if fmt == "srt":
        from pipeline.ingest.srt import read_srt
        return read_srt(p, mapping_for("srt", mapping))
    raise LogReadError(f"unsupported format {fmt}", path=p)


def read_flight(paths, mapping: dict | None = None) -> FlightLog:
    """Read every file of one flight (logs, bag folders, video, SRT) and merge them into one FlightLog.

    `mapping` overrides the per-format defaults (mappings/<format>.yaml), keyed by format: see docs/ingest.md.
    Raises LogReadError (naming the file) for unreadable input; recoverable damage becomes a warning in
    `FlightLog.warnings`.
    """
    if isinstance(paths, (str, Path)):
        paths = [paths]
    if not paths:
        raise InputError("no input files given")
    check_override(mapping)
    return merge_logs([read_file(p, mapping) for p in paths])
