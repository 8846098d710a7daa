"""GIS exports of a run: the answers (`targets.csv`, `targets.geojson` (RFC 7946), `targets.kml` (KML 2.2): one row,
feature or placemark per target, `pipeline.report.answers`), and every method's estimate for the comparison
(`estimates.csv`, `estimates.geojson`: the estimates the flight determines, the truth, 95 % ellipses, flight paths
and lines of sight).

Every position is converted from the group's local ENU frame to WGS84 with pymap3d. Heights: `alt_m` is above
the WGS84 ellipsoid (EPSG:4979), which is what RFC 7946 prescribes for GeoJSON coordinates; `alt_msl_m` is above
the EGM2008 geoid (pipeline.geometry.geoid), which is what KML's `absolute` altitude mode wants, so KML coordinates
carry it. Columns and properties are documented in docs/outputs.md. All files are written atomically.
"""

from __future__ import annotations

import csv
import io
import json
import xml.etree.ElementTree as ET
from collections.abc import Iterable
from os import PathLike
from pathlib import Path

import numpy as np

from pipeline.atomic import atomic_write_bytes, atomic_write_text
from pipeline.geometry.geoid import geoid_undulation_m
from pipeline.report.answers import (
    ALT_MSL_DATUM,
    ANSWER_COLUMNS,
    answer_of,
    answer_rows,
    determined_estimates,
    shown_covariance,
)
from pipeline.report.geometry import (
    ALT_DATUM,
    best_reference_m,
    geodetic_from_enu,
    lines_of_sight_m,
    uncertainty,
)
from pipeline.report.labels import count, method_label, one_decimal, ordered_methods
from pipeline.results import FlightResult, GroupFailure, GroupResult, per_target
from pipeline.solve.uncertainty import ELLIPSE_CONFIDENCE, ellipse_points_en_m, horizontal

# The documented columns of estimates.csv, in order (docs/outputs.md describes each).
ESTIMATES_CSV_COLUMNS = (
    "group", "target", "method", "method_label", "answer", "determined",
    "lat_deg", "lon_deg", "alt_m", "alt_datum", "alt_msl_m", "geoid_undulation_m", "alt_msl_datum",
    "e_m", "n_m", "u_m", "origin_lat_deg", "origin_lon_deg", "origin_alt_m",
    "error_m", "error_horizontal_m", "error_up_m",
    "cep50_m", "cep90_m", "sigma_up_m",
    "ellipse95_semi_major_m", "ellipse95_semi_minor_m", "ellipse95_azimuth_deg", "covariance_source",
    "converged", "status", "reason", "iterations", "n_observations", "intersection_angle_deg",
)

DEG_DECIMALS = 8  # ~1 mm: more than any estimate's accuracy, so rounding never shows
GEOJSON_DEG_DECIMALS = 7  # ~1 cm, the precision RFC 7946 section 11.2 suggests is plenty
M_DECIMALS = 3
MIN_ELLIPSE_M = 0.05  # below this an ellipse polygon would collapse at 7-decimal coordinates
KML_NS = "http://www.opengis.net/kml/2.2"


# ---- rows: one per group and method --------------------------------------------------------------------------

def _num(x, decimals: int = M_DECIMALS):
    """A finite float rounded, else None."""
    if x is None:
        return None
    x = float(x)
    return round(x, decimals) if np.isfinite(x) else None


def msl_lla(lla: np.ndarray) -> np.ndarray:
    """(..., 3) lat, lon, ellipsoidal h -> lat, lon, height above the EGM2008 geoid (h - N)."""
    lla = np.asarray(lla, dtype=np.float64)
    out = lla.copy()
    out[..., 2] = lla[..., 2] - geoid_undulation_m(lla[..., 0], lla[..., 1])
    return out


def failure_status_reason(failure) -> tuple[str, str]:
    """(status, reason) of a method that could not run, from its entry in settings["solve_failures"]: a message,
    or a {"status", "reason"} mapping (as `ridgeloc solve --json` lists unsolved methods)."""
    if isinstance(failure, dict):
        return str(failure.get("status") or "failed"), str(failure.get("reason", ""))
    return "failed", str(failure)


def unsolved_methods(r: GroupResult) -> dict[str, tuple[str, str]]:
    """{method: (status, reason)} of the methods a group asked for that gave no estimate."""
    failures = r.settings.get("solve_failures") or {}
    return {m: failure_status_reason(f) for m, f in failures.items() if m not in r.estimates}


def _status_reason(r: GroupResult, method: str) -> tuple[str, str | None]:
    """(status, reason) of a method: its status and reason when it could not run, else the estimate's status
    and why it is not to be trusted blindly, if anything says so: the reason the solver gives (`reason`/`message`
    in its extras, or the mle's fit message when its error model does not fit the flight: the covariance was
    inflated), then, for a finite estimate, the group's geometry warnings (settings["geometry_warnings"], from
    `ridgeloc run`'s checks: lines of sight too nearly parallel to fix where they meet), joined by "; "."""
    failures = r.settings.get("solve_failures") or {}
    e = r.estimates.get(method)
    if e is None:
        return failure_status_reason(failures.get(method, "not solved"))
    extras = e.extras if isinstance(e.extras, dict) else {}
    reason = extras.get("reason", extras.get("message"))
    fit = extras.get("fit")
    if reason is None and isinstance(fit, dict) and fit.get("message"):
        reason = fit["message"]
    warnings = (r.settings.get("geometry_warnings") or []) if np.isfinite(e.position_m).all() else []
    reasons = [str(x) for x in (reason, *warnings) if x is not None]
    return e.status.name.lower(), ("; ".join(reasons) or None)


def group_methods(r: GroupResult) -> list[str]:
    """Every method the group asked for: solved ones and those that could not run, in Table-4 order."""
    return ordered_methods([*r.estimates, *[m for m in (r.settings.get("solve_failures") or {})
                                            if m not in r.estimates]])



def _units(results) -> list:
    """GroupResults (one per located target) and (flight name, TargetFailure) of the targets not located, in the
    run's order: a flight's located targets, then its failed ones."""
    out: list = []
    for r in results:
        if isinstance(r, FlightResult):
            out += [*r.targets, *[(r.name, f) for f in r.failed]]
        else:
            out.append(r)
    return out


def _failed_rows(name: str, f) -> list[dict]:
    """A target that could not be located: one row per method asked for, status `not_located`, the reason."""
    return [{**dict.fromkeys(ESTIMATES_CSV_COLUMNS), "group": name, "target": f.target, "method": m,
             "method_label": method_label(m), "answer": False, "determined": False, "alt_datum": ALT_DATUM,
             "alt_msl_datum": ALT_MSL_DATUM, "status": "not_located", "reason": f.message, "n_observations": 0}
            for m in f.methods]


def estimate_rows(results: Iterable[GroupResult | FlightResult]) -> list[dict]:
    """One dict per target and method with the keys of ESTIMATES_CSV_COLUMNS (None where undefined). A method that
    could not run, gave no finite position, or whose estimate the flight does not determine keeps its row with empty
    values, its status and the reason; so does a target that could not be located."""
    rows = []
    for r in _units(results):
        if isinstance(r, tuple):
            rows.extend(_failed_rows(*r))
            continue
        lat0, lon0, alt0 = r.origin_lla
        answer, shown = answer_of(r), determined_estimates(r)
        methods = group_methods(r)
        positions = np.full((len(methods), 3), np.nan)  # every shown method's position converted at once
        for i, method in enumerate(methods):
            if method in shown:
                positions[i] = r.estimates[method].position_m
        ok = np.isfinite(positions).all(axis=1)
        llas = np.full(positions.shape, np.nan)
        llas[ok] = geodetic_from_enu(positions[ok], r.origin_lla)
        undulations = geoid_undulation_m(llas[:, 0], llas[:, 1])
        for method, pos, finite, lla, n_m in zip(methods, positions, ok, llas, undulations, strict=True):
            e = r.estimates.get(method)
            status, reason = _status_reason(r, method)
            verdict = answer.verdicts.get(method)
            if verdict is not None and not verdict.determined and e is not None:
                reason = "; ".join(x for x in (f"not determined: {verdict.reason}", reason) if x)
            n_m = float(n_m) if finite else None
            err = None if (e is None or not finite) else e.error_m(r.truth_m)
            d = None if (err is None or r.truth_m is None) else pos - r.truth_m
            u = dict.fromkeys(("cep50_m", "cep90_m", "sigma_up_m", "ellipse95_semi_major_m",
                               "ellipse95_semi_minor_m", "ellipse95_azimuth_deg"))
            source = None
            if e is not None and finite:  # the estimator's own covariance, else the one the answer rule propagated
                if verdict is not None and verdict.covariance_m2 is not None:
                    u, source = horizontal(verdict.covariance_m2), verdict.covariance_source
                else:
                    u = uncertainty(e)
                    source = "estimator" if e.covariance_m2 is not None else None
            rows.append({
                "group": r.name, "target": r.target, "method": method, "method_label": method_label(method),
                "answer": method == answer.method, "determined": bool(finite),
                "lat_deg": _num(lla[0], DEG_DECIMALS), "lon_deg": _num(lla[1], DEG_DECIMALS),
                "alt_m": _num(lla[2]), "alt_datum": ALT_DATUM,
                "alt_msl_m": None if n_m is None else _num(lla[2] - n_m),
                "geoid_undulation_m": _num(n_m), "alt_msl_datum": ALT_MSL_DATUM,
                "e_m": _num(pos[0]), "n_m": _num(pos[1]), "u_m": _num(pos[2]),
                "origin_lat_deg": _num(lat0, DEG_DECIMALS), "origin_lon_deg": _num(lon0, DEG_DECIMALS),
                "origin_alt_m": _num(alt0),
                "error_m": _num(err),
                "error_horizontal_m": None if d is None else _num(np.hypot(d[0], d[1])),
                "error_up_m": None if d is None else _num(d[2]),
                "cep50_m": _num(u["cep50_m"]), "cep90_m": _num(u["cep90_m"]), "sigma_up_m": _num(u["sigma_up_m"]),
                "ellipse95_semi_major_m": _num(u["ellipse95_semi_major_m"]),
                "ellipse95_semi_minor_m": _num(u["ellipse95_semi_minor_m"]),
                "ellipse95_azimuth_deg": _num(u["ellipse95_azimuth_deg"], 2), "covariance_source": source,
                "converged": None if e is None else bool(e.converged), "status": status, "reason": reason,
                "iterations": None if e is None else int(e.iterations),
                "n_observations": int(r.n_observations), "intersection_angle_deg": _num(r.intersection_angle_deg, 2),
            })
    return rows


# ---- CSV -------------------------------------------------------------------------------------------------------

def _csv_text(rows: list[dict], columns: tuple[str, ...]) -> str:
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=columns, lineterminator="\n")
    w.writeheader()
    for row in rows:
        w.writerow({k: ("" if row.get(k) is None else
                        ("true" if row[k] is True else "false" if row[k] is False else row[k])) for k in columns})
    return buf.getvalue()


def targets_csv_text(results: Iterable[GroupResult | FlightResult], failures: Iterable[GroupFailure] = ()) -> str:
    """targets.csv: one row per target, the answer (`pipeline.report.answers`, columns ANSWER_COLUMNS)."""
    return _csv_text(answer_rows(list(results), list(failures)), ANSWER_COLUMNS)


#: targets.csvt's types (GDAL's CSV driver, GeoCSV): numbers as numbers, lon/lat as the point's coordinates
_CSVT_TYPES = {"lat_deg": "CoordY", "lon_deg": "CoordX", "n_observations": "Integer"}
_CSVT_TEXT = ("name", "group", "target", "status", "mgrs", "tle_category", "method", "reason", "alt_datum",
              "alt_msl_datum", "covariance_source")


def targets_csvt_text() -> str:
    """targets.csvt: the column types GDAL and QGIS read beside targets.csv (points from lon_deg, lat_deg)."""
    return ",".join(f'"{_CSVT_TYPES.get(c, "String" if c in _CSVT_TEXT else "Real")}"' for c in ANSWER_COLUMNS) + "\n"


def write_targets_csv(path: str | PathLike, results: Iterable[GroupResult], failures=()) -> None:
    """targets.csv, with targets.csvt (column types, the point's columns) and targets.prj (WGS84 longitude and
    latitude) beside it, so that GDAL, QGIS and ArcGIS open it as points."""
    from pyproj import CRS
    from pyproj.enums import WktVersion

    path = Path(path)
    atomic_write_text(path, targets_csv_text(results, failures))
    atomic_write_text(path.with_suffix(".csvt"), targets_csvt_text())
    atomic_write_text(path.with_suffix(".prj"), CRS.from_epsg(4326).to_wkt(WktVersion.WKT1_ESRI) + "\n")


def estimates_csv_text(results: Iterable[GroupResult | FlightResult]) -> str:
    """estimates.csv: one row per target and method, columns ESTIMATES_CSV_COLUMNS; empty cell = undefined."""
    return _csv_text(estimate_rows(list(results)), ESTIMATES_CSV_COLUMNS)


def write_estimates_csv(path: str | PathLike, results: Iterable[GroupResult]) -> None:
    atomic_write_text(path, estimates_csv_text(results))


# ---- GeoJSON (RFC 7946) -------------------------------------------------------------------------------------

def _positions(lla: np.ndarray) -> list:
    """(k, 3) lat, lon, alt -> RFC 7946 positions [lon, lat, alt], rounded."""
    lla = np.atleast_2d(lla)
    return [[round(float(lon), GEOJSON_DEG_DECIMALS), round(float(lat), GEOJSON_DEG_DECIMALS),
             round(float(alt), 2)] for lat, lon, alt in lla]


def _feature(geometry: dict, properties: dict) -> dict:
    return {"type": "Feature", "geometry": geometry, "properties": properties}


def group_features(r: GroupResult, max_lines_of_sight: int | None = 200) -> list[dict]:
    """The GeoJSON Features of one group: estimates (Point), truth (Point), 95 % ellipses (Polygon), flight path
    and lines of sight (LineString). Each has a `kind` and a `group` property."""
    feats = []
    rows = {row["method"]: row for row in estimate_rows([r])}
    shown = determined_estimates(r)
    for method in ordered_methods(r.estimates):
        e = r.estimates[method]
        if method not in shown:
            continue  # no position to draw, or not determined: estimates.csv lists it with its status and reason
        lla = geodetic_from_enu(e.position_m, r.origin_lla)
        props = {"kind": "estimate", **{k: v for k, v in rows[method].items()
                                        if k not in ("lat_deg", "lon_deg", "origin_lat_deg", "origin_lon_deg",
                                                     "origin_alt_m")}}
        feats.append(_feature({"type": "Point", "coordinates": _positions(lla)[0]}, props))
        row = rows[method]
        if row["ellipse95_semi_major_m"] is not None and row["ellipse95_semi_major_m"] >= MIN_ELLIPSE_M:
            ring_en = ellipse_points_en_m(shown_covariance(r, method)[:2, :2], ELLIPSE_CONFIDENCE)
            ring_enu = np.column_stack([ring_en + e.position_m[:2], np.full(len(ring_en), e.position_m[2])])
            ring = _positions(geodetic_from_enu(ring_enu, r.origin_lla))
            ring[-1] = ring[0]  # closed exactly, whatever the rounding
            feats.append(_feature({"type": "Polygon", "coordinates": [ring]}, {
                "kind": "error_ellipse", "group": r.name, "method": method, "method_label": method_label(method),
                "confidence": ELLIPSE_CONFIDENCE, "semi_major_m": row["ellipse95_semi_major_m"],
                "semi_minor_m": row["ellipse95_semi_minor_m"], "azimuth_deg": row["ellipse95_azimuth_deg"],
                "covariance_source": row["covariance_source"], "alt_datum": ALT_DATUM}))
    if r.truth_m is not None:
        lla = geodetic_from_enu(r.truth_m, r.origin_lla)
        feats.append(_feature({"type": "Point", "coordinates": _positions(lla)[0]}, _truth_props(r, lla)))
    obs = r.observations
    if obs.n >= 2:
        path = _positions(geodetic_from_enu(obs.platform_m, r.origin_lla))
        feats.append(_feature({"type": "LineString", "coordinates": path}, {
            "kind": "flight_path", "group": r.name, "n_positions": obs.n, "alt_datum": ALT_DATUM,
            "t_start_ns": int(obs.t_ns[0]), "t_end_ns": int(obs.t_ns[-1])}))
    a = answer_of(r)
    seg, idx = lines_of_sight_m(obs, a.position_m if a.located else best_reference_m(r), max_lines_of_sight)
    rejected = _mle_rejected(r)
    for s, i in zip(seg, idx, strict=True):
        feats.append(_feature({"type": "LineString", "coordinates": _positions(geodetic_from_enu(s, r.origin_lla))},
                              {"kind": "line_of_sight", "group": r.name, "frame": int(i), "t_ns": int(obs.t_ns[i]),
                               "has_pixel": bool(obs.has_pixel[i]),
                               "range_m": _num(obs.range_m[i]) if obs.has_range[i] else None,
                               "mle_rejected": rejected.get(int(i))}))
    if r.target is not None:  # every feature of a named target says which (and its name is group:target)
        for f in feats:
            p = f["properties"]
            f["properties"] = {"group": p.get("group", r.name), "target": r.target, "name": r.label,
                               **{k: v for k, v in p.items() if k not in ("group", "target")}}
    return feats


def _mle_rejected(r: GroupResult) -> dict[int, str]:
    """{observation row: "range" | "u" | "v" | "u, v" ...}: the residuals the mle gave zero weight (gross
    outliers), from its extras' `rejected` list."""
    e = r.estimates.get("mle")
    listed = e.extras.get("rejected") if e is not None and isinstance(e.extras, dict) else None
    out: dict[int, list[str]] = {}
    for x in listed or []:
        out.setdefault(int(x["frame"]), []).append(str(x["residual"]))
    return {i: ", ".join(v) for i, v in out.items()}


def _truth_props(r: GroupResult, lla: np.ndarray) -> dict:
    n_m = float(geoid_undulation_m(lla[0], lla[1]))
    return {"kind": "truth", "group": r.name, "alt_m": _num(lla[2]), "alt_datum": ALT_DATUM,
            "alt_msl_m": _num(lla[2] - n_m), "geoid_undulation_m": _num(n_m), "alt_msl_datum": ALT_MSL_DATUM,
            "e_m": _num(r.truth_m[0]), "n_m": _num(r.truth_m[1]), "u_m": _num(r.truth_m[2])}


def estimates_geojson(results: Iterable[GroupResult], max_lines_of_sight: int | None = 200) -> dict:
    """Every target's `group_features` as a GeoJSON FeatureCollection (RFC 7946: WGS84 lon/lat, ellipsoidal
    height, no `crs` member)."""
    feats = []
    for r in per_target(results):
        feats.extend(group_features(r, max_lines_of_sight))
    return {"type": "FeatureCollection", "features": feats}


def _answer_ring_lla(r: GroupResult) -> np.ndarray | None:
    """(k, 3) lat, lon, ellipsoidal h of the answer's 95 % horizontal ellipse (a closed ring at the answer's height),
    None without one."""
    a = answer_of(r)
    if not a.located or a.covariance_m2 is None or not np.isfinite(a.covariance_m2).all():
        return None
    ring_en = ellipse_points_en_m(np.asarray(a.covariance_m2)[:2, :2], ELLIPSE_CONFIDENCE)
    if np.abs(ring_en).max() < MIN_ELLIPSE_M:
        return None
    ring_enu = np.column_stack([ring_en + a.position_m[:2], np.full(len(ring_en), a.position_m[2])])
    ring = geodetic_from_enu(ring_enu, r.origin_lla)
    ring[-1] = ring[0]
    return ring


def targets_geojson(results: Iterable[GroupResult | FlightResult], failures: Iterable[GroupFailure] = ()) -> dict:
    """The answers as a GeoJSON FeatureCollection (RFC 7946): per located target a Point (`kind` "target", the
    properties of its targets.csv row) and its 95 % ellipse (Polygon, `kind` "error_ellipse"); a target without an
    answer is a feature with a null geometry, its status and reason."""
    results = list(results)
    by_name = {t.label: t for t in per_target(results)}
    feats = []
    for row in answer_rows(results, list(failures)):
        props = {"kind": "target", **{k: v for k, v in row.items() if k not in ("lat_deg", "lon_deg")}}
        r = by_name.get(row["name"])
        if row["status"] != "located" or r is None:
            feats.append(_feature(None, props))
            continue
        a = answer_of(r)
        lla = geodetic_from_enu(a.position_m, r.origin_lla)
        feats.append(_feature({"type": "Point", "coordinates": _positions(lla)[0]}, props))
        ring = _answer_ring_lla(r)
        if ring is not None:
            pos = _positions(ring)
            pos[-1] = pos[0]
            feats.append(_feature({"type": "Polygon", "coordinates": [pos]}, {
                "kind": "error_ellipse", "name": row["name"], "group": row["group"], "target": row["target"],
                "method": row["method"], "confidence": ELLIPSE_CONFIDENCE,
                "semi_major_m": row["ellipse95_semi_major_m"], "semi_minor_m": row["ellipse95_semi_minor_m"],
                "azimuth_deg": row["ellipse95_azimuth_deg"], "alt_datum": ALT_DATUM}))
    return {"type": "FeatureCollection", "features": feats}


def _write_json(path, doc) -> None:
    atomic_write_text(path, json.dumps(doc, allow_nan=False, separators=(",", ":")) + "\n")


def write_targets_geojson(path: str | PathLike, results, failures=()) -> None:
    """targets.geojson: see `targets_geojson`."""
    _write_json(path, targets_geojson(results, failures))


def write_estimates_geojson(path: str | PathLike, results, max_lines_of_sight: int | None = 200) -> None:
    """estimates.geojson: see `estimates_geojson`."""
    _write_json(path, estimates_geojson(results, max_lines_of_sight))


# ---- KML 2.2 --------------------------------------------------------------------------------------------------

# KML SimpleField types of the attributes (KML 2.2 section 9.9: string, int, uint, short, ushort, float, double,
# bool); GIS clients (GDAL's LIBKML driver, Google Earth) read the typed <Schema> instead of treating all as text.
_KML_STRING_FIELDS = {"name", "group", "target", "status", "mgrs", "tle_category", "method", "reason", "alt_datum",
                      "alt_msl_datum", "covariance_source"}
_KML_INT_FIELDS = {"n_observations"}
TARGET_KML_FIELDS = tuple(c for c in ANSWER_COLUMNS if c not in ("name", "lat_deg", "lon_deg"))  # name: <name>
ELLIPSE_KML_FIELDS = ("group", "target", "method", "confidence", "semi_major_m", "semi_minor_m",
                      "azimuth_deg", "alt_msl_m")
KML_SCHEMAS = {"target": TARGET_KML_FIELDS, "error_ellipse": ELLIPSE_KML_FIELDS}


def kml_field_type(name: str) -> str:
    """The KML SimpleField type of an attribute."""
    if name in _KML_STRING_FIELDS:
        return "string"
    if name in _KML_INT_FIELDS:
        return "int"
    return "double"


def _kml_color(hex_rgb: str, alpha: int = 0xFF) -> str:
    """'#RRGGBB' -> KML 'aabbggrr'."""
    rr, gg, bb = hex_rgb[1:3], hex_rgb[3:5], hex_rgb[5:7]
    return f"{alpha:02x}{bb}{gg}{rr}".lower()


def _sub(parent: ET.Element, tag: str, text: str | None = None, **attrib) -> ET.Element:
    el = ET.SubElement(parent, f"{{{KML_NS}}}{tag}", attrib)
    if text is not None:
        el.text = text
    return el


def _kml_coords(lla: np.ndarray) -> str:
    return " ".join(f"{lon:.{GEOJSON_DEG_DECIMALS}f},{lat:.{GEOJSON_DEG_DECIMALS}f},{alt:.2f}"
                    for lat, lon, alt in np.atleast_2d(lla))


def _geometry(parent: ET.Element, tag: str, lla_msl: np.ndarray) -> ET.Element:
    """A Point/LineString with absolute altitudes (heights above the geoid, KML's mean sea level)."""
    g = _sub(parent, tag)
    _sub(g, "altitudeMode", "absolute")
    _sub(g, "coordinates", _kml_coords(lla_msl))
    return g



def _schema_data(pm: ET.Element, schema: str, props: dict) -> None:
    sd = _sub(_sub(pm, "ExtendedData"), "SchemaData", schemaUrl=f"#{schema}")
    for k in KML_SCHEMAS[schema]:
        v = props.get(k)
        if v is None:
            continue  # an absent SimpleData is a null attribute
        _sub(sd, "SimpleData", str(v).lower() if isinstance(v, bool) else str(v), name=k)


def _placemark(parent: ET.Element, name: str, style: str, schema: str, props: dict) -> ET.Element:
    pm = _sub(parent, "Placemark")
    _sub(pm, "name", name)
    _sub(pm, "styleUrl", f"#{style}")
    _schema_data(pm, schema, props)
    return pm


def _metres(x) -> str:
    """A CE90 / LE90 as the CoT remarks give it: one decimal, or 'unknown'."""
    return "unknown" if x is None else f"{one_decimal(x)} m"


def _description(row: dict) -> str:
    """The balloon text of a target's placemark: the answer as a user reads it."""
    return (f"{row['mgrs']}; {one_decimal(row['alt_msl_m'])} m above sea level (EGM2008), "
            f"{one_decimal(row['alt_m'])} m WGS84 ellipsoidal; CE90 {_metres(row['ce90_m'])}, LE90 "
            f"{_metres(row['le90_m'])} "
            f"({row['tle_category']}); method {row['method']}, {count(row['n_observations'], 'observation')}")


def targets_kml(results: Iterable[GroupResult | FlightResult], failures: Iterable[GroupFailure] = ()) -> bytes:
    """The answers as a KML 2.2 document: one placemark per located target and its 95 % ellipse. Coordinates are
    absolute altitudes: heights above the EGM2008 geoid (ellipsoidal height minus the geoid undulation), as KML
    defines altitude (above sea level); the ellipsoidal height is kept in `alt_m`. Attributes are typed by a
    <Schema> per kind of placemark (target, error_ellipse)."""
    results = list(results)
    by_name = {t.label: t for t in per_target(results)}
    ET.register_namespace("", KML_NS)
    root = ET.Element(f"{{{KML_NS}}}kml")
    doc = _sub(root, "Document")
    _sub(doc, "name", "ridgeloc targets")
    _sub(doc, "description", f"One answer per target. Coordinates: {ALT_MSL_DATUM} (altitudeMode absolute); "
                             f"attribute alt_m: {ALT_DATUM}.")
    for sid, fields in KML_SCHEMAS.items():
        schema = _sub(doc, "Schema", name=sid, id=sid)
        for f in fields:
            _sub(schema, "SimpleField", name=f, type=kml_field_type(f))
    st = _sub(doc, "Style", id="target")
    icon = _sub(st, "IconStyle")
    _sub(icon, "color", _kml_color("#D55E00"))
    _sub(_sub(icon, "Icon"), "href", "http://maps.google.com/mapfiles/kml/shapes/target.png")
    _sub(_sub(st, "LineStyle"), "color", _kml_color("#D55E00"))
    _sub(_sub(st, "PolyStyle"), "color", _kml_color("#D55E00", 0x40))
    for row in answer_rows(results, list(failures)):
        r = by_name.get(row["name"])
        if row["status"] != "located" or r is None:
            continue  # targets.csv and targets.geojson list it with its reason
        a = answer_of(r)
        pm = _placemark(doc, row["name"], "target", "target", row)
        _sub(pm, "description", _description(row))
        _geometry(pm, "Point", msl_lla(geodetic_from_enu(a.position_m, r.origin_lla)))
        ring = _answer_ring_lla(r)
        if ring is not None:
            pm = _placemark(doc, f"{row['name']}: 95 % error ellipse", "target", "error_ellipse", {
                "name": row["name"], "group": row["group"], "target": row["target"], "method": row["method"],
                "confidence": ELLIPSE_CONFIDENCE, "semi_major_m": row["ellipse95_semi_major_m"],
                "semi_minor_m": row["ellipse95_semi_minor_m"], "azimuth_deg": row["ellipse95_azimuth_deg"],
                "alt_msl_m": row["alt_msl_m"]})
            poly = _sub(pm, "Polygon")
            _sub(poly, "altitudeMode", "absolute")
            _sub(_sub(_sub(poly, "outerBoundaryIs"), "LinearRing"), "coordinates", _kml_coords(msl_lla(ring)))
    ET.indent(root)
    return ET.tostring(root, encoding="utf-8", xml_declaration=True)


def write_targets_kml(path: str | PathLike, results, failures=()) -> None:
    """targets.kml: see `targets_kml`."""
    atomic_write_bytes(path, targets_kml(results, failures))
