"""Summaries of logs for `ridgeloc inspect`: streams (type, count, rate, span, what they supply), what was read,
and what is missing for localization."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from pipeline.errors import InputError, RidgelocError
from pipeline.ingest.dispatch import detect_format, merge_logs, read_file
from pipeline.ingest.model import FlightLog

QUANTITY_ATTRS = ("position", "attitude", "gimbal", "range", "frames", "camera_events", "field_of_view")


@dataclass
class InspectResult:
    """One input: its format and FlightLog, or the one-line error that made it unreadable. `group`: the flight
    folder it was found in ("" for a file named on the command line)."""

    path: str
    format: str | None = None
    log: FlightLog | None = None
    error: str | None = None
    group: str = ""


def expand_flight_folders(paths) -> list[tuple[str, Path]]:
    """(group, path) pairs: each flight folder (a folder that is not a ROS 2 bag) is replaced by the logs, bags
    and videos in it, grouped under the folder (truth.json, frame CSVs and other companions are left out); a
    flight folder with none stays, as (folder, folder)."""
    out: list[tuple[str, Path]] = []
    for p in map(Path, paths):
        if _is_flight_folder(p):
            found = []
            for child in sorted(p.iterdir()):
                try:
                    detect_format(child)
                except RidgelocError:
                    continue
                found.append((str(p), child))
            out += found or [(str(p), p)]
        else:
            out.append(("", p))
    return out


def _is_flight_folder(p: Path) -> bool:
    return p.is_dir() and not (p / "metadata.yaml").is_file()


def inspect_paths(paths, mapping: dict | None = None) -> list[InspectResult]:
    """Read each path on its own (every stream timed); unreadable inputs become results with `error` set. A flight
    folder stands for the readable files in it."""
    out = []
    for group, p in expand_flight_folders(paths):
        try:
            if _is_flight_folder(p):
                raise InputError("no logs, videos or photos found", p)
            fmt = detect_format(p)
            out.append(InspectResult(str(p), fmt, read_file(p, mapping, scan_all=True), group=group))
        except RidgelocError as exc:
            out.append(InspectResult(str(p), error=str(exc), group=group))
    return out


def _rate_span(s) -> tuple[float | None, float | None]:
    if s.t_first_ns is None or s.t_last_ns is None:
        return None, None
    span = (s.t_last_ns - s.t_first_ns) / 1e9
    return ((s.count - 1) / span if span > 0 and s.count > 1 else None), span


def _read_line(log: FlightLog) -> list[str]:
    parts = []
    for q in QUANTITY_ATTRS:
        s = getattr(log, q)
        if s is None:
            continue
        extra = f", {s.alt_datum}" if q == "position" else ""
        if q == "range":
            extra = f", {int(s.valid.sum())} valid"
        parts.append(f"{q} {s.t_ns.size} from {s.source} ({s.clock} clock{extra})")
    if log.camera_info is not None:
        ci = log.camera_info
        parts.append(f"camera_info {ci.width_px}x{ci.height_px} fx={ci.K[0, 0]:.1f} from {ci.source}")
    return parts


def format_result(r: InspectResult) -> str:
    if r.error is not None:
        return f"{r.path}: ERROR {r.error}"
    log = r.log
    lines = [f"{r.path}  [{r.format}]"]
    rows = [("stream", "type", "count", "rate Hz", "span s", "supplies")]
    for s in log.streams:
        rate, span = _rate_span(s)
        rows.append((s.name, s.msg_type, str(s.count), "-" if rate is None else f"{rate:.2f}",
                     "-" if span is None else f"{span:.2f}", ", ".join(s.supplies)))
    widths = [min(max(len(row[i]) for row in rows), 44) for i in range(5)]
    for row in rows:
        cells = [row[0].ljust(widths[0]), row[1].ljust(widths[1]), row[2].rjust(widths[2]),
                 row[3].rjust(widths[3]), row[4].rjust(widths[4]), row[5]]
        lines.append("  " + "  ".join(cells).rstrip())
    read = _read_line(log)
    lines.append("  read: " + ("; ".join(read) if read else "nothing the model uses"))
    missing = log.missing_for_localization()
    lines.append("  missing for localization: " + (", ".join(missing) if missing else "nothing"))
    lines += [f"  warning: {w}" for w in log.warnings]
    return "\n".join(lines)


def result_as_dict(r: InspectResult) -> dict:
    if r.error is not None:
        return {"path": r.path, "error": r.error}
    log = r.log
    streams = []
    for s in log.streams:
        rate, span = _rate_span(s)
        streams.append({"name": s.name, "type": s.msg_type, "count": s.count, "rate_hz": rate, "span_s": span,
                        "t_first_ns": s.t_first_ns, "t_last_ns": s.t_last_ns, "supplies": list(s.supplies)})
    read = {}
    for q in QUANTITY_ATTRS:
        s = getattr(log, q)
        if s is not None:
            read[q] = {"source": s.source, "count": int(s.t_ns.size), "clock": s.clock}
            if q == "position":
                read[q]["alt_datum"] = s.alt_datum
    return {"path": r.path, "format": r.format, "streams": streams, "read": read,
            "missing_for_localization": log.missing_for_localization(), "warnings": list(log.warnings)}


def combined_missing(results: list[InspectResult]) -> dict[str, list[str]]:
    """What the readable inputs of each group (a flight folder, or "" for the files named on their own) lack
    together, for groups of two or more files."""
    groups: dict[str, list[FlightLog]] = {}
    for r in results:
        if r.log is not None:
            groups.setdefault(r.group, []).append(r.log)
    return {g: merge_logs(logs).missing_for_localization() for g, logs in groups.items() if len(logs) > 1}


__all__ = ["InspectResult", "combined_missing", "format_result", "inspect_paths", "result_as_dict"]
