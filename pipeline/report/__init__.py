"""Outputs people use: the run report (HTML), per-group figures and GIS exports (CSV, GeoJSON, KML).

Modules:
    exports: targets.csv / targets.geojson / targets.kml from `GroupResult`s (ENU -> WGS84 via pymap3d).
    figures: per-group figures like the paper's Fig. 7 (map view, 3D view, residuals per frame).
    html: the self-contained `report.html` (figures embedded, Table-4-like summary, settings, versions).
    store: a `GroupResult` to and from JSON, so finished groups are reused on a re-run.
    outputs: `write_group_outputs` (one group's folder) and `write_run_outputs` (the whole OUTDIR).
    table4: report.md + table4.csv (the paper's Table 4), written by `ridgeloc run`.

Layout and column lists are documented in docs/outputs.md.
"""
