"""`ridgeloc run`'s summary: report.md and table4.csv, laid out like the paper's Tables 3 and 4.

table4.csv: columns `method,<group>,<group>,...`; one row per method named as in `ridgeloc solve` with the
localization error in metres (empty when there is no truth or the method did not run: a method asked for that
failed keeps its row), then the rows `intersection_angle_deg` and `observations`, then for each method that did
not solve in some group the rows `status:<method>` and `reason:<method>` (its status, e.g. `degenerate`, and
the reason in those groups; empty where it solved). report.md: the same tables with the paper's figures beside
ours (never used for anything but display), the estimates as WGS84 coordinates, tracking and timing figures.
"""

from __future__ import annotations

import csv
import io
import math
from collections.abc import Sequence
from os import PathLike
from pathlib import Path

import numpy as np

from pipeline.geometry.frames import lla_from_enu
from pipeline.report.exports import unsolved_methods
from pipeline.report.labels import one_decimal
from pipeline.results import FlightResult, GroupFailure, GroupResult, per_target, target_failures

# Table-4 order, then ours.
METHOD_ROWS = ("vision", "range", "los", "fusion-raw", "fusion", "ridge", "dlt", "mle")
METHOD_NAMES = {
    "vision": "Vision", "range": "Laser ranging", "los": "Line of sight",
    "fusion-raw": "Fusion without normalization", "fusion": "Fusion", "ridge": "Ridge fusion",
    "dlt": "DLT triangulation (initial value)", "mle": "Weighted MLE (ours)",
    "dem": "Ray into the terrain model (DEM)", "dji": "DJI's own laser target", "ground": "Ray onto level ground",
}

# The paper's flight experiments (Huang et al., Tables 3 and 4), groups 1..6: for display beside ours only.
PAPER_TABLE4_M = {
    "vision": (10.75, 68.12, 42.87, 65.27, 69.34, 223.44),
    "range": (86.42, 148.09, 439.99, 250.92, 45.41, 56.04),
    "los": (175.17, 24252.97, 24283.62, 201.30, 198.18, 87.53),
    "fusion-raw": (10.16, 62.53, 42.68, 49.48, 12.17, 26.02),
    "fusion": (9.03, 58.86, 29.47, 44.51, 12.10, 14.56),
    "ridge": (8.68, 46.33, 17.32, 28.43, 11.48, 13.73),
}
PAPER_TABLE3 = {"intersection_angle_deg": (53.97, 24.03, 24.36, 31.42, 46.46, 36.41),
                "observations": (16, 17, 34, 11, 18, 11)}
PAPER_GROUPS = ("group1", "group2", "group3", "group4", "group5", "group6")


def _methods(results: Sequence[GroupResult]) -> list[str]:
    """Every method of any group: solved, or asked for and failed (it keeps its row, with empty values)."""
    present = {m for r in results for m in (*r.estimates, *(r.settings.get("solve_failures") or {}))}
    return [m for m in METHOD_ROWS if m in present] + sorted(present - set(METHOD_ROWS))


def _without_prefix(reason: str, method: str) -> str:
    """The reason without a leading "<method>: " (the note names the method already)."""
    return reason[len(method) + 2:] if reason.startswith(f"{method}: ") else reason


def _fmt(x, nd=2) -> str:
    return "" if x is None or (isinstance(x, float) and not math.isfinite(x)) else f"{x:.{nd}f}"


def table4_rows(results: Sequence[GroupResult | FlightResult]) -> list[list[str]]:
    """The table4.csv rows (header first): a column per group, or per target (`group:target`) of a flight that
    names its targets; a target that could not be located keeps its column, status `not_located` and reason."""
    failed = target_failures(results)
    located = per_target(results)
    methods = _methods(located)
    methods += [m for _, f in failed for m in f.methods if m not in methods]
    rows = [["method", *[r.label for r in located], *[f"{n}:{f.target}" for n, f in failed]]]
    for m in methods:
        rows.append([m, *[_fmt(r.errors_m().get(m), 3) for r in located], *[""] * len(failed)])
    rows.append(["intersection_angle_deg", *[_fmt(r.intersection_angle_deg, 2) for r in located],
                 *[""] * len(failed)])
    rows.append(["observations", *[str(r.n_observations) for r in located], *["0"] * len(failed)])
    unsolved = [unsolved_methods(r) for r in located] + [{m: ("not_located", f.message) for m in f.methods}
                                                         for _, f in failed]
    for m in methods:
        if any(m in u for u in unsolved):
            rows.append([f"status:{m}", *[u[m][0] if m in u else "" for u in unsolved]])
            rows.append([f"reason:{m}", *[u[m][1] if m in u else "" for u in unsolved]])
    return rows


def table4_csv_text(results: Sequence[GroupResult]) -> str:
    buf = io.StringIO()
    csv.writer(buf, lineterminator="\n").writerows(table4_rows(results))
    return buf.getvalue()


def _md_table(header: list[str], rows: list[list[str]]) -> str:
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(r) + " |" for r in rows]
    return "\n".join(lines)


def _best(values: list[float | None]) -> float | None:
    finite = [v for v in values if v is not None and math.isfinite(v)]
    return min(finite) if finite else None


def _answers_markdown(results, failures) -> list[str]:
    """The answers (targets.csv's) as the report's first table."""
    from pipeline.report.answers import answer_rows

    rows = []
    for a in answer_rows(results, failures):
        if a["status"] != "located":
            rows.append([a["name"], "not located", "", "", "", "", "", "", a["reason"]])
            continue
        rows.append([a["name"], f"{a['lat_deg']:.7f}", f"{a['lon_deg']:.7f}", one_decimal(a['alt_msl_m']), a["mgrs"],
                     _fmt(a["ce90_m"]) or "—", a["tle_category"] or "—", a["method"], _fmt(a["error_m"]) or "—"])
    return ["## Answers: one per target", "",
            _md_table(["Target", "Latitude", "Longitude", "MSL m", "MGRS", "CE90 m", "Category", "Method",
                       "Error m / why not located"], rows), "",
            "The rule that chooses each answer, and the columns: docs/outputs.md (\"The answer\"); every method's "
            "estimate below and in estimates.csv.", ""]


def report_markdown(results: Sequence[GroupResult | FlightResult], failures: Sequence[GroupFailure] = ()) -> str:
    out = ["# ridgeloc run report", ""]
    if results:
        out += _answers_markdown(results, failures)
    not_located = target_failures(results)
    results = per_target(results)  # a column per target of a flight with named targets (label group:target)
    if results:
        names = [r.label for r in results]
        methods = _methods(results)
        errs = {r.label: r.errors_m() for r in results}
        has_truth = any(r.truth_m is not None for r in results)
        out += ["## Localization error (m), as the paper's Table 4", ""]
        if not has_truth:
            out += ["No group has a known truth: errors cannot be computed. Estimates are listed below.", ""]
        best = {n: _best([errs[n].get(m) for m in methods]) for n in names}
        rows = []
        for m in methods:
            cells = []
            for n in names:
                v = errs[n].get(m)
                s = _fmt(v)
                cells.append(f"**{s}**" if s and v == best[n] else (s or "—"))
            rows.append([METHOD_NAMES.get(m, m), f"`{m}`", *cells])
        out += [_md_table(["Method", "name", *names], rows), "", "Bold: the smallest error of the group. "
                "`—`: no truth or the method could not run (see the notes).", ""]
        paper_cols = [n for n in names if n in PAPER_GROUPS]
        if paper_cols:
            out += ["### The paper's Table 4 beside ours (same groups)", "",
                    "Paper: Huang et al., flight experiments (real flights); ours: the sample flights of this "
                    "repository (synthetic, generated to resemble Table 3's geometry). Shown for comparison only; "
                    "nothing is tuned to them.", ""]
            rows = []
            for m in methods:
                if m in PAPER_TABLE4_M:
                    rows.append([f"paper:{m}", *[_fmt(PAPER_TABLE4_M[m][PAPER_GROUPS.index(n)]) for n in paper_cols]])
                ours = [_fmt(errs[n].get(m)) for n in paper_cols]
                if m in PAPER_TABLE4_M or any(ours):  # no row of dashes for a photo method on video flights
                    rows.append([f"ours:{m}", *[c or "—" for c in ours]])
            out += [_md_table(["method", *paper_cols], rows), ""]
        out += ["## Flight parameters, as the paper's Table 3", ""]
        rows = [["Intersection angle (deg)", *[_fmt(r.intersection_angle_deg) for r in results]],
                ["Observations", *[str(r.n_observations) for r in results]],
                ["with a tracked pixel", *[str(int(r.observations.has_pixel.sum())) for r in results]],
                ["with a valid range", *[str(int(r.observations.has_range.sum())) for r in results]]]
        for key, label in (("intersection_angle_deg", "paper: intersection angle (deg)"),
                           ("observations", "paper: observations")):
            if any(n in PAPER_GROUPS for n in names):
                rows.append([label, *[str(PAPER_TABLE3[key][PAPER_GROUPS.index(n)]) if n in PAPER_GROUPS else ""
                                      for n in names]])
        out += [_md_table(["", *names], rows), ""]
        out += ["## Estimates", "",
                "WGS84 latitude/longitude (deg) and ellipsoidal height (m); ENU metres relative to each group's "
                "origin. The MLE's 1-sigma is the square root of its covariance's diagonal (E, N, U).", ""]
        for r in results:
            out += [f"### {r.label}", "",
                    f"Origin (lat, lon, h): {r.origin_lla[0]:.7f}, {r.origin_lla[1]:.7f}, {r.origin_lla[2]:.2f} m", ""]
            rows = []
            failed = unsolved_methods(r)
            for m in methods:
                e = r.estimates.get(m)
                if e is None:
                    if m in failed:
                        rows.append([m, "—", "—", "—", "—", "", failed[m][0], "—"])
                    continue
                p = np.asarray(e.position_m, dtype=np.float64)
                if np.isfinite(p).all():
                    lat, lon, h = lla_from_enu(p, r.origin_lla)
                    geo = [f"{lat:.7f}", f"{lon:.7f}", f"{h:.2f}"]
                else:
                    geo = ["—"] * 3
                sd = "" if e.covariance_m2 is None else ", ".join(
                    f"{math.sqrt(max(v, 0.0)):.2f}" for v in np.diag(e.covariance_m2))
                rows.append([m, *geo, ", ".join(f"{v:.2f}" for v in p), sd, e.status.name.lower(),
                             _fmt(r.errors_m().get(m)) or "—"])
            if r.truth_m is not None:
                lat, lon, h = lla_from_enu(r.truth_m, r.origin_lla)
                rows.append(["truth", f"{lat:.7f}", f"{lon:.7f}", f"{h:.2f}", ", ".join(f"{v:.2f}" for v in r.truth_m),
                             "", "", ""])
            out += [_md_table(["method", "lat_deg", "lon_deg", "h_m", "ENU m", "1-sigma m", "status", "error m"], rows),
                    ""]
            notes = list(r.settings.get("notes", [])) + [
                f"{m} not solved ({status}): {_without_prefix(reason, m)}" for m, (status, reason) in failed.items()]
            if notes:
                out += ["Notes:", *[f"- {n}" for n in notes], ""]
        out += ["## Tracking and timing", ""]
        rows = []
        for r in results:
            t = r.timings_s
            total = sum(t.values())
            corr = [c for c, lost in zip(r.tracking.get("correlation", []), r.tracking.get("lost", []), strict=False)
                    if c is not None and not lost]
            lost = r.tracking.get("lost")
            n_lost = int(sum(bool(v) for v in lost)) if lost is not None else int((~r.observations.has_pixel).sum())
            rows.append([r.label, str(r.n_observations), str(n_lost),
                         _fmt(float(np.median(corr)) if corr else None, 3),
                         *[_fmt(t.get(k), 3) for k in ("ingest", "decode", "track", "sync", "solve", "report")],
                         _fmt(total, 3), _fmt(10 * total / max(r.n_observations, 1), 3)])
        out += ["`lost`: observation frames where the target was not tracked (tracking.json: `lost`, `reason`), "
                "including those then dropped for having no valid range either; `obs`: observations solved.", ""]
        out += [_md_table(["group", "obs", "lost", "median NCC", "ingest s", "decode s", "track s", "sync s", "solve s",
                           "report s", "total s", "s per 10 obs"], rows), ""]
    if not_located:
        out += ["## Targets not located", ""] + [f"- {n}:{f.target}: {f.message}" for n, f in not_located] + [""]
    if failures:
        out += ["## Failed groups", ""] + [f"- {f.name} ({f.source}): {f.message}" for f in failures] + [""]
    return "\n".join(out)


def write_table4(outdir: str | PathLike, results: Sequence[GroupResult],
                 failures: Sequence[GroupFailure] = ()) -> tuple[Path, Path]:
    """Write OUTDIR/report.md and OUTDIR/table4.csv (atomically). Returns their paths."""
    from pipeline.atomic import atomic_write_text

    outdir = Path(outdir)
    md, tab = outdir / "report.md", outdir / "table4.csv"
    atomic_write_text(tab, table4_csv_text(results))
    atomic_write_text(md, report_markdown(results, failures))
    return md, tab
