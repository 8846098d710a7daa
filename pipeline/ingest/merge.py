"""Several files of one flight merged into one FlightLog."""

from __future__ import annotations

import dataclasses

import numpy as np

from pipeline.ingest.model import FlightLog

QUANTITIES = ("position", "attitude", "gimbal", "range", "frames", "camera_events", "field_of_view", "frame_centre",
              "payload_target")


def _concat(series_list: list, name: str, warnings: list[str]):
    first = series_list[0]
    same = [s for s in series_list if s.clock == first.clock and type(s) is type(first)]
    if len(same) < len(series_list):
        warnings.append(f"{name}: sources on different clocks ({', '.join(s.source for s in series_list)}); "
                        f"using {first.source}")
    if len(same) == 1:
        return first
    if hasattr(first, "alt_datum") and len({s.alt_datum for s in same}) > 1:
        warnings.append(f"{name}: sources with different altitude datums; using {first.source}")
        return first
    if name == "frames":
        warnings.append(f"frames: several frame sources; using {first.source}")
        return first
    t = np.concatenate([s.t_ns for s in same])
    order = np.argsort(t, kind="stable")
    changes = {"t_ns": t[order], "source": "+".join(s.source for s in same)}
    for f in dataclasses.fields(first):
        v = getattr(first, f.name)
        if f.name != "t_ns" and isinstance(v, np.ndarray):
            changes[f.name] = np.concatenate([getattr(s, f.name) for s in same])[order]
    return dataclasses.replace(first, **changes)


def merge_logs(logs: list[FlightLog]) -> FlightLog:
    """Several files of one flight -> one FlightLog (series of one quantity on one clock are concatenated)."""
    if len(logs) == 1:
        return logs[0]
    out = FlightLog(path=", ".join(log.path for log in logs))
    for log in logs:
        out.clock_links += log.clock_links
        out.streams += log.streams
        out.warnings += log.warnings
        out.formats += log.formats
        out.klv_tables.update(log.klv_tables)
        out.video_indexes.update(log.video_indexes)
        if out.camera_info is None:
            out.camera_info = log.camera_info
    for q in QUANTITIES:
        found = [getattr(log, q) for log in logs if getattr(log, q) is not None]
        if q == "position" and any(s.alt_datum != "missing" for s in found):  # a track without altitude
            out.warnings += [f"position: {s.source} has no altitudes; the positions of "
                             f"{', '.join(o.source for o in found if o.alt_datum != 'missing')} are used"
                             for s in found if s.alt_datum == "missing"]
            found = [s for s in found if s.alt_datum != "missing"]
        if found:
            setattr(out, q, _concat(found, q, out.warnings))
    return out
