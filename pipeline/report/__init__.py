"""Outputs people use: the run report (HTML), per-group figures and GIS exports (CSV, GeoJSON, KML).

Modules:
    answers: each target's one answer as the outputs write it (MGRS, CE90/LE90, TLE category).
    exports: targets.csv / .geojson / .kml (the answers) and estimates.csv / .geojson (every method).
    figures: per-group figures like the paper's Fig. 7 (map view, 3D view, residuals per frame).
    html: the self-contained `report.html` (figures embedded, Table-4-like summary, settings, versions).
    store: a `GroupResult` to and from JSON, so finished groups are reused on a re-run.
    outputs: `write_group_outputs` (one group's folder) and `write_run_outputs` (the whole OUTDIR).
    table4: report.md + table4.csv (the paper's Table 4), written by `ridgeloc run`.

Layout and column lists are documented in docs/outputs.md.
"""

import importlib

# Lazy, so importing pipeline.report.table4 does not pull in matplotlib.
_EXPORTS = {
    "write_run_outputs": "outputs", "write_group_outputs": "outputs", "load_finished_group": "outputs",
    "write_targets_csv": "exports", "write_targets_geojson": "exports", "write_targets_kml": "exports",
    "ESTIMATES_CSV_COLUMNS": "exports", "ANSWER_COLUMNS": "answers", "write_report_html": "html",
    "render_group_figures": "figures",
}
__all__ = sorted(_EXPORTS)


def __getattr__(name: str):
    if name in _EXPORTS:
        return getattr(importlib.import_module(f"pipeline.report.{_EXPORTS[name]}"), name)
    raise AttributeError(f"module 'pipeline.report' has no attribute {name!r}")
