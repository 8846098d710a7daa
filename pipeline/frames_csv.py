"""The frames CSV (`frame_index,pts_ns` per row): a video's frame numbers and container times, written by
`ridgeloc synth` and by users who indexed a video themselves (docs/ingest.md). One parser, for the video reader and
for the flight config's check of its target marks at load."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from pipeline.errors import LogReadError


def read_frames_csv(csv_path: Path) -> tuple[np.ndarray, np.ndarray]:
    """(frame_index (n,) int64, pts_ns (n,) int64) of a frames CSV; LogReadError naming the file otherwise."""
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
