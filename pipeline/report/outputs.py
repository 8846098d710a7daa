"""Writing a run's output folder.

    OUTDIR/
      report.html                  self-contained report (html.py)
      targets.csv / .geojson / .kml  the answer per target (answers.py, exports.py)
      cot/<target>.cot, targets.zip  the answers as Cursor on Target events and a TAK data package (cot.py)
      estimates.csv / .geojson     every method's estimate, for the comparison (exports.py)
      run.json                     groups done, failures with their messages, settings, clock offsets estimated
                                   (clock.estimate), software versions
      <group>/                     one folder per group, written atomically, then marked finished:
        result.json                the GroupResult (store.py), reused by a re-run
        map.png view3d.png residuals.png
        estimates.geojson          this group's features alone
        .done                      hash of the configuration that produced the folder

Every file and folder is written atomically (pipeline.atomic): after a crash or Ctrl-C a file is either the old
one, the new one, or absent, and a group folder without `.done` is never reused.
"""

from __future__ import annotations

import json
import os
import shutil
import time
from collections.abc import Mapping, Sequence
from os import PathLike
from pathlib import Path

from pipeline.atomic import (
    atomic_dir,
    atomic_write_text,
    is_done,
    remove_stale_temporaries,
    write_done_marker,
)
from pipeline.errors import InputError
from pipeline.report.answers import answer_rows
from pipeline.report.cot import CotOptions, check_flight_name, write_cot_outputs
from pipeline.report.exports import (
    estimates_geojson,
    write_estimates_csv,
    write_estimates_geojson,
    write_targets_csv,
    write_targets_geojson,
    write_targets_kml,
)
from pipeline.report.html import write_report_html
from pipeline.report.store import load_group_result, save_group_result
from pipeline.report.versions import software_versions
from pipeline.results import FlightResult, GroupFailure, GroupResult, per_target

RESULT_FILE = "result.json"


def group_dir(outdir: str | PathLike, name: str) -> Path:
    return Path(outdir) / name


def write_group_outputs(outdir: str | PathLike, r: GroupResult, config_digest: str = "",
                        extra_files: Mapping[str, bytes | str] | None = None, figures: bool = True) -> Path:
    """Write OUTDIR/<group>/ atomically (result.json, figures, targets.geojson, `extra_files` name -> content) and
    mark it finished for `config_digest` (see pipeline.atomic.config_hash). Returns the folder."""
    t0 = time.perf_counter()
    from pipeline.report.figures import render_group_figures  # matplotlib: its import counts as report time

    final = group_dir(outdir, r.name)
    pngs = {}
    for t in per_target([r]):  # a flight with named targets: <target>/map.png ... per target
        prefix = "" if t.target is None else f"{t.target}/"
        pngs.update({f"{prefix}{k}": v for k, v in (render_group_figures(t) if figures else {}).items()})
    geojson = json.dumps(estimates_geojson([r]), allow_nan=False) + "\n"
    r.timings_s["report"] = time.perf_counter() - t0  # the group's figures and GeoJSON, itemised with the stages
    with atomic_dir(final) as tmp:
        save_group_result(tmp / RESULT_FILE, r)
        for name, png in pngs.items():
            (tmp / f"{name}.png").parent.mkdir(parents=True, exist_ok=True)
            (tmp / f"{name}.png").write_bytes(png)
        (tmp / "estimates.geojson").write_text(geojson)
        for name, content in (extra_files or {}).items():
            p = tmp / name
            p.parent.mkdir(parents=True, exist_ok=True)
            if isinstance(content, Path):  # a file written beside the folder: moved in
                os.replace(content, p)
            else:
                p.write_bytes(content if isinstance(content, bytes) else content.encode("utf-8"))
        write_done_marker(tmp, config_digest)
    return final


def add_overlay(outdir: str | PathLike, result) -> dict[str, Path]:
    """Render a video flight's overlay.mp4 (`pipeline.report.overlay`) into a temporary file beside its group
    folder; book its time as the result's "overlay" stage and name it in the settings (report.html shows it).
    Returns {"overlay.mp4": that file} for `write_group_outputs`' extra files, {} for a flight without video."""
    from pipeline.report.overlay import OVERLAY_FILE, video_of, write_overlay
    from pipeline.results import per_target

    targets = per_target([result])
    if not targets or video_of(targets[0].settings) is None or not targets[0].tracking.get("frame_index"):
        return {}
    t0 = time.perf_counter()
    Path(outdir).mkdir(parents=True, exist_ok=True)
    tmp = Path(outdir) / f".{result.name}.{OVERLAY_FILE}"
    info = write_overlay(result, tmp)
    seconds = time.perf_counter() - t0
    for r in [result, *targets]:
        r.timings_s["overlay"] = seconds
        r.settings["overlay"] = {"file": OVERLAY_FILE, **info}
    return {OVERLAY_FILE: tmp}


def load_finished_group(outdir: str | PathLike, name: str, config_digest: str | None = None) -> GroupResult | None:
    """The GroupResult of a finished group folder (for `config_digest` when given), or None when the folder is
    missing, unfinished, made with another configuration, or unreadable (it is then simply redone)."""
    folder = group_dir(outdir, name)
    if not is_done(folder, config_digest):
        return None
    try:
        return load_group_result(folder / RESULT_FILE)
    except InputError:
        return None


def _group_figures(outdir: Path, name: str, target: str | None = None) -> dict[str, bytes]:
    out = {}
    for key in ("map", "view3d", "residuals"):
        p = outdir / name / ("" if target is None else target) / f"{key}.png"
        if p.is_file():
            out[key] = p.read_bytes()
    return out


def foreign_results(outdir: str | PathLike, names) -> list[str]:
    """The finished group folders in `outdir` that are not among `names`: another run's results."""
    outdir = Path(outdir)
    if not outdir.is_dir():
        return []
    names = set(names)
    return sorted(p.name for p in outdir.iterdir() if p.is_dir() and p.name not in names and is_done(p))


def claim_output_folder(outdir: str | PathLike, names, overwrite: bool = False) -> list[str]:
    """Make `outdir` this run's, for the flights `names`, before any work: InputError naming the folder when it
    holds another run's results (finished group folders of other flights), unless `overwrite`, which removes
    them, so that the run-level files and the folders beside them are always one run's. Returns what was
    removed."""
    foreign = foreign_results(outdir, names)
    if foreign and not overwrite:
        shown = ", ".join(foreign[:5]) + (f" and {len(foreign) - 5} more" if len(foreign) > 5 else "")
        raise InputError(f"holds another run's results ({shown}): choose another output folder, or give --overwrite "
                         "to replace them", outdir)
    for name in foreign:
        shutil.rmtree(group_dir(outdir, name))
    return foreign


def write_run_outputs(outdir: str | PathLike, results: Sequence[GroupResult], failures: Sequence[GroupFailure],
                      settings: Mapping, figures: bool = True, rewrite_groups: bool = False,
                      cot: CotOptions | None = None) -> dict[str, Path]:
    """Write the run-level outputs (targets.csv/.geojson/.kml, estimates.csv/.geojson, cot/ and targets.zip,
    report.html, run.json) and every group folder that is not written yet (`rewrite_groups`: each result's folder
    written again). A failed flight's folder left by an earlier run is removed: it no longer describes the flight.
    `figures=False` leaves the figures out of new group folders and of the report (fast); `cot` sets the CoT
    events' type and stale time. Returns name -> path of the run-level files."""
    outdir = Path(outdir)
    results, failures = list(results), list(failures)  # in the run's order (the run config's)
    for r in results:
        check_flight_name(r.name)  # its folder would be the TAK events' (cot/)
    outdir.mkdir(parents=True, exist_ok=True)
    remove_stale_temporaries(outdir)
    for f in failures:
        stale = group_dir(outdir, f.name)
        if stale.is_dir() and f.name not in {r.name for r in results}:
            shutil.rmtree(stale)
    pngs = {}
    for r in results:
        if rewrite_groups or not is_done(group_dir(outdir, r.name)):
            write_group_outputs(outdir, r, figures=figures)
        # figures missing from a folder are rendered by the page itself
        for t in per_target([r]):
            pngs[t.label] = _group_figures(outdir, t.name, t.target) if figures else {}
    paths = {k: outdir / f for k, f in (("csv", "targets.csv"), ("geojson", "targets.geojson"),
                                        ("kml", "targets.kml"), ("estimates_csv", "estimates.csv"),
                                        ("estimates_geojson", "estimates.geojson"), ("html", "report.html"),
                                        ("run", "run.json"))}
    write_targets_csv(paths["csv"], results, failures)
    write_targets_geojson(paths["geojson"], results, failures)
    write_targets_kml(paths["kml"], results, failures)
    write_estimates_csv(paths["estimates_csv"], results)
    write_estimates_geojson(paths["estimates_geojson"], results)
    write_cot_outputs(outdir, results, cot)
    write_report_html(paths["html"], results, failures, settings,
                      {k: v for k, v in pngs.items() if v or not figures})
    atomic_write_text(paths["run"], json.dumps({
        "answers": answer_rows(results, failures),
        "groups": [r.name for r in results],
        "failures": [{"name": f.name, "source": f.source, "message": f.message,
                      **({"traceback": f.detail} if getattr(f, "detail", "") else {})} for f in failures],
        "settings": dict(settings),
        "clock_estimates": {r.name: r.settings["clock_estimate"] for r in results if r.settings.get("clock_estimate")},
        **({"targets": {r.name: {"located": [t.target for t in r.targets], "not_located": {
            f.target: f.message for f in r.failed}} for r in results if isinstance(r, FlightResult)}}
           if any(isinstance(r, FlightResult) for r in results) else {}),
        "software": software_versions(),
    }, indent=1, default=str) + "\n")
    return paths
