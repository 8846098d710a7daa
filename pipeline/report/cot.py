"""The run's answers as Cursor on Target: OUTDIR/cot/<target>.cot (one event per located answer) and
OUTDIR/targets.zip (a TAK data package of them), from the same rows as targets.csv (pipeline.report.answers).

The uid of a target's event is derived from its flight's identity (the flight's name and the names and sizes
of its telemetry, video and photo files) and the target's name: a re-run of the same flight, whatever its
output folder, machine or config fixes, gives the same uid, so a device updates the marker instead of adding a
second one; another flight that happens to have the same name gets another uid.
"""

from __future__ import annotations

import json
import re
from collections.abc import Sequence
from dataclasses import dataclass
from datetime import datetime, timezone
from os import PathLike
from pathlib import Path

from pipeline.atomic import atomic_dir, atomic_write_bytes
from pipeline.errors import InputError
from pipeline.flight_config import RESERVED_FLIGHT_NAMES
from pipeline.report.answers import answer_row, answer_warnings
from pipeline.report.labels import count, one_decimal
from pipeline.results import GroupResult, per_target
from pipeline.tak import DEFAULT_STALE_S, DEFAULT_TYPE
from pipeline.tak.cot import CotTarget, check_type, event_xml, target_uid
from pipeline.tak.package import PackageEntry, data_package

COT_DIR = "cot"
PACKAGE_FILE = "targets.zip"
#: observation times before this are a clock counted from boot, not a date worth printing
_PLAUSIBLE_NS = 946_684_800 * 10**9  # 2000-01-01 UTC


@dataclass(frozen=True)
class CotOptions:
    """The events' CoT type and how long they stay valid (s)."""

    cot_type: str = DEFAULT_TYPE
    stale_s: float = DEFAULT_STALE_S


def flight_key(r: GroupResult) -> str:
    """A flight's identity for its targets' uids: its name and the (name, size) of each input file (telemetry,
    video, photos; a folder's files), as JSON. A file that is gone counts by its name."""
    files = r.settings.get("files") or {}
    listed = [*(files.get("telemetry") or []), files.get("video"), *(files.get("photos") or []),
              *(r.settings.get("photos") or [])]  # `ridgeloc locate`'s photos
    items = set()
    for f in listed:
        if not f:
            continue
        p = Path(f)
        if p.is_dir():
            items.update((q.name, q.stat().st_size) for q in p.rglob("*") if q.is_file())
        else:
            items.add((p.name, p.stat().st_size if p.is_file() else None))
    return json.dumps({"flight": r.name, "files": sorted(items, key=lambda x: (x[0], x[1] or 0))})


def check_flight_name(name: str) -> str:
    """`name` unless the run's TAK outputs take it (OUTDIR/cot/, targets.zip): InputError."""
    if name.lower() in RESERVED_FLIGHT_NAMES:
        raise InputError(f"the name {name!r} is taken by the run's TAK events (OUTDIR/cot/, targets.zip): give "
                         "the flight another name")
    return name


def mgrs_spaced(mgrs: str) -> str:
    """An MGRS reference with the spaces people read it with: "49SBU9399604341" -> "49S BU 93996 04341"."""
    digits = len(mgrs) - len(mgrs.rstrip("0123456789"))
    if digits % 2 or digits == 0 or len(mgrs) < digits + 2:
        return mgrs
    head, square, grid = mgrs[:-digits - 2], mgrs[-digits - 2:-digits], mgrs[-digits:]
    return f"{head} {square} {grid[:digits // 2]} {grid[digits // 2:]}"


def _flight_time(r: GroupResult) -> str | None:
    t = r.observations.t_ns
    if t is None or len(t) == 0 or int(t[0]) < _PLAUSIBLE_NS:
        return None
    when = datetime.fromtimestamp(int(t[0]) / 1e9, timezone.utc).strftime("%Y-%m-%d %H:%M")
    if r.settings.get("photo_time_zone") == "unknown":  # a photo's DateTimeOriginal without a zone or GPS time
        return f"{when} camera local time"
    return f"{when} UTC"


def _m(x) -> str:
    return "unknown" if x is None else f"{x:.1f} m"


def remarks(row: dict, when: str | None, warnings=()) -> str:
    """The remarks ATAK shows under the marker: the method, MGRS, CE90/LE90 and category, the 95 % ellipse, the
    heights, the flight, and the head of each of the answer's warnings (`answer_warnings`: its words before the
    first colon, what is wrong, not the advice), which targets.csv's reason gives in full."""
    lines = [f"ridgeloc {row['method']} from {count(row['n_observations'], 'observation')}",
             f"MGRS {mgrs_spaced(row['mgrs'])}",
             f"CE90 {_m(row['ce90_m'])}, LE90 {_m(row['le90_m'])}"
             + (f" (TLE {row['tle_category']})" if row.get("tle_category") else "")]
    if row.get("ellipse95_semi_major_m") is not None:
        lines.append(f"95% ellipse {row['ellipse95_semi_major_m']:.1f} x {row['ellipse95_semi_minor_m']:.1f} m, "
                     f"major axis {row['ellipse95_azimuth_deg']:.0f} deg from north")
    lines.append(f"height {one_decimal(row['alt_msl_m'])} m MSL (EGM2008), {one_decimal(row['alt_m'])} m WGS84 "
                 "ellipsoid")
    flight = f"flight {row['group']}" + (f", target {row['target']}" if row.get("target") else "")
    lines.append(flight + (f", {when}" if when else ""))
    lines += [f"WARNING: {w.split(': ', 1)[0]}" for w in warnings]
    return "\n".join(lines)


_ATTRIBUTES = ("method", "n_observations", "mgrs", "ce90_m", "le90_m", "tle_category", "cep50_m",
               "ellipse95_semi_major_m", "ellipse95_semi_minor_m", "ellipse95_azimuth_deg", "sigma_up_m",
               "alt_msl_m", "geoid_undulation_m")


def cot_target(r: GroupResult, row: dict) -> CotTarget:
    """The CoT view of a located answer (its targets.csv row `row`)."""
    attributes = {"flight": r.name, **({"target": r.target} if r.target else {}),
                  **{k: str(row[k]) for k in _ATTRIBUTES if row.get(k) is not None}}
    return CotTarget(uid=target_uid(flight_key(r) + "\n" + (r.target or "")), callsign=row["name"],
                     lat_deg=row["lat_deg"], lon_deg=row["lon_deg"], hae_m=row["alt_m"], ce90_m=row["ce90_m"],
                     le90_m=row["le90_m"], attributes=attributes,
                     remarks=remarks(row, _flight_time(r), answer_warnings(r)))


def cot_entries(results, now: datetime | None = None, options: CotOptions | None = None) -> list[PackageEntry]:
    """One event per located answer of `results` (GroupResults and FlightResults, in the run's order), valid
    from `now` (default: the current time)."""
    options = options or CotOptions()
    check_type(options.cot_type)
    now = now or datetime.now(timezone.utc)
    entries: list[PackageEntry] = []
    names: set[str] = set()
    for r in per_target(results):
        row = answer_row(r)
        if row["status"] != "located":
            continue
        target = cot_target(r, row)
        stem = re.sub(r"[^\w.-]+", "_", target.callsign).strip("._") or "target"
        name, i = f"{stem}.cot", 1
        while name.lower() in names:
            i += 1
            name = f"{stem}-{i}.cot"
        names.add(name.lower())
        entries.append(PackageEntry(target.uid, target.callsign, name,
                                    event_xml(target, now, options.cot_type, options.stale_s)))
    return entries


def write_cot_outputs(outdir: str | PathLike, results: Sequence, options: CotOptions | None = None,
                      now: datetime | None = None) -> list[PackageEntry]:
    """Write OUTDIR/cot/ (replacing an earlier run's) and OUTDIR/targets.zip (removed when nothing is located);
    returns the events written."""
    outdir = Path(outdir)
    entries = cot_entries(results, now, options)
    with atomic_dir(outdir / COT_DIR) as tmp:
        for e in entries:
            (tmp / e.file_name).write_bytes(e.xml)
    package = outdir / PACKAGE_FILE
    if entries:
        atomic_write_bytes(package, data_package(entries, f"ridgeloc {outdir.resolve().name}"))
    else:
        package.unlink(missing_ok=True)
    return entries
