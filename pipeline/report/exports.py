"""GIS exports of a run: `targets.csv`, `targets.geojson` (RFC 7946) and `targets.kml` (KML 2.2).

Every position is converted from the group's local ENU frame to WGS84 with pymap3d; heights are above the
WGS84 ellipsoid (EPSG:4979), which is what RFC 7946 prescribes for GeoJSON. Columns and properties are
documented in docs/outputs.md. All files are written atomically.
"""

from __future__ import annotations

import csv
import io
import json
import xml.etree.ElementTree as ET
from collections.abc import Iterable
from os import PathLike

import numpy as np

from pipeline.atomic import atomic_write_bytes, atomic_write_text
from pipeline.report.geometry import (
    ALT_DATUM,
    ELLIPSE_CONFIDENCE,
    best_reference_m,
    ellipse_points_en_m,
    geodetic_from_enu,
    lines_of_sight_m,
    uncertainty,
)
from pipeline.report.labels import METHOD_COLORS, method_label, ordered_methods
from pipeline.results import GroupResult

# The documented columns of targets.csv, in order (docs/outputs.md describes each).
TARGETS_CSV_COLUMNS = (
    "group", "method", "method_label",
    "lat_deg", "lon_deg", "alt_m", "alt_datum",
    "e_m", "n_m", "u_m", "origin_lat_deg", "origin_lon_deg", "origin_alt_m",
    "error_m", "error_horizontal_m", "error_up_m",
    "cep50_m", "cep90_m", "sigma_up_m",
    "ellipse95_semi_major_m", "ellipse95_semi_minor_m", "ellipse95_azimuth_deg",
    "converged", "status", "iterations", "n_observations", "intersection_angle_deg",
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


def target_rows(results: Iterable[GroupResult]) -> list[dict]:
    """One dict per group and method with the keys of TARGETS_CSV_COLUMNS (None where undefined)."""
    rows = []
    for r in results:
        lat0, lon0, alt0 = r.origin_lla
        for method in ordered_methods(r.estimates):
            e = r.estimates[method]
            pos = np.asarray(e.position_m, dtype=np.float64)
            finite = bool(np.isfinite(pos).all())
            lla = geodetic_from_enu(pos, r.origin_lla) if finite else np.full(3, np.nan)
            err = e.error_m(r.truth_m)
            d = None if (err is None or r.truth_m is None) else pos - r.truth_m
            u = uncertainty(e)
            rows.append({
                "group": r.name, "method": method, "method_label": method_label(method),
                "lat_deg": _num(lla[0], DEG_DECIMALS), "lon_deg": _num(lla[1], DEG_DECIMALS),
                "alt_m": _num(lla[2]), "alt_datum": ALT_DATUM,
                "e_m": _num(pos[0]), "n_m": _num(pos[1]), "u_m": _num(pos[2]),
                "origin_lat_deg": _num(lat0, DEG_DECIMALS), "origin_lon_deg": _num(lon0, DEG_DECIMALS),
                "origin_alt_m": _num(alt0),
                "error_m": _num(err),
                "error_horizontal_m": None if d is None else _num(np.hypot(d[0], d[1])),
                "error_up_m": None if d is None else _num(d[2]),
                "cep50_m": _num(u["cep50_m"]), "cep90_m": _num(u["cep90_m"]), "sigma_up_m": _num(u["sigma_up_m"]),
                "ellipse95_semi_major_m": _num(u["ellipse95_semi_major_m"]),
                "ellipse95_semi_minor_m": _num(u["ellipse95_semi_minor_m"]),
                "ellipse95_azimuth_deg": _num(u["ellipse95_azimuth_deg"], 2),
                "converged": bool(e.converged), "status": e.status.name.lower(), "iterations": int(e.iterations),
                "n_observations": int(r.n_observations), "intersection_angle_deg": _num(r.intersection_angle_deg, 2),
            })
    return rows


# ---- CSV -------------------------------------------------------------------------------------------------------

def targets_csv_text(results: Iterable[GroupResult]) -> str:
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=TARGETS_CSV_COLUMNS, lineterminator="\n")
    w.writeheader()
    for row in target_rows(results):
        w.writerow({k: ("" if v is None else ("true" if v is True else "false" if v is False else v))
                    for k, v in row.items()})
    return buf.getvalue()


def write_targets_csv(path: str | PathLike, results: Iterable[GroupResult]) -> None:
    """targets.csv: one row per group and method, columns TARGETS_CSV_COLUMNS; empty cell = undefined."""
    atomic_write_text(path, targets_csv_text(results))


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
    rows = {row["method"]: row for row in target_rows([r])}
    for method in ordered_methods(r.estimates):
        e = r.estimates[method]
        if not np.isfinite(e.position_m).all():
            continue  # no position to draw; targets.csv still lists it with its status
        lla = geodetic_from_enu(e.position_m, r.origin_lla)
        props = {"kind": "estimate", **{k: v for k, v in rows[method].items()
                                        if k not in ("lat_deg", "lon_deg", "origin_lat_deg", "origin_lon_deg",
                                                     "origin_alt_m")}}
        feats.append(_feature({"type": "Point", "coordinates": _positions(lla)[0]}, props))
        row = rows[method]
        if row["ellipse95_semi_major_m"] is not None and row["ellipse95_semi_major_m"] >= MIN_ELLIPSE_M:
            ring_en = ellipse_points_en_m(np.asarray(e.covariance_m2)[:2, :2], ELLIPSE_CONFIDENCE)
            ring_enu = np.column_stack([ring_en + e.position_m[:2], np.full(len(ring_en), e.position_m[2])])
            ring = _positions(geodetic_from_enu(ring_enu, r.origin_lla))
            ring[-1] = ring[0]  # closed exactly, whatever the rounding
            feats.append(_feature({"type": "Polygon", "coordinates": [ring]}, {
                "kind": "error_ellipse", "group": r.name, "method": method, "method_label": method_label(method),
                "confidence": ELLIPSE_CONFIDENCE, "semi_major_m": row["ellipse95_semi_major_m"],
                "semi_minor_m": row["ellipse95_semi_minor_m"], "azimuth_deg": row["ellipse95_azimuth_deg"],
                "alt_datum": ALT_DATUM}))
    if r.truth_m is not None:
        lla = geodetic_from_enu(r.truth_m, r.origin_lla)
        feats.append(_feature({"type": "Point", "coordinates": _positions(lla)[0]}, {
            "kind": "truth", "group": r.name, "alt_m": _num(lla[2]), "alt_datum": ALT_DATUM,
            "e_m": _num(r.truth_m[0]), "n_m": _num(r.truth_m[1]), "u_m": _num(r.truth_m[2])}))
    obs = r.observations
    if obs.n >= 2:
        path = _positions(geodetic_from_enu(obs.platform_m, r.origin_lla))
        feats.append(_feature({"type": "LineString", "coordinates": path}, {
            "kind": "flight_path", "group": r.name, "n_positions": obs.n, "alt_datum": ALT_DATUM,
            "t_start_ns": int(obs.t_ns[0]), "t_end_ns": int(obs.t_ns[-1])}))
    seg, idx = lines_of_sight_m(obs, best_reference_m(r), max_lines_of_sight)
    for s, i in zip(seg, idx, strict=True):
        feats.append(_feature({"type": "LineString", "coordinates": _positions(geodetic_from_enu(s, r.origin_lla))},
                              {"kind": "line_of_sight", "group": r.name, "frame": int(i), "t_ns": int(obs.t_ns[i]),
                               "has_pixel": bool(obs.has_pixel[i]),
                               "range_m": _num(obs.range_m[i]) if obs.has_range[i] else None}))
    return feats


def targets_geojson(results: Iterable[GroupResult], max_lines_of_sight: int | None = 200) -> dict:
    """A GeoJSON FeatureCollection (RFC 7946: WGS84 lon/lat, ellipsoidal height, no `crs` member)."""
    feats = []
    for r in results:
        feats.extend(group_features(r, max_lines_of_sight))
    return {"type": "FeatureCollection", "features": feats}


def write_targets_geojson(path: str | PathLike, results: Iterable[GroupResult],
                          max_lines_of_sight: int | None = 200) -> None:
    """targets.geojson: see `targets_geojson`."""
    doc = targets_geojson(results, max_lines_of_sight)
    atomic_write_text(path, json.dumps(doc, allow_nan=False, separators=(",", ":")) + "\n")


# ---- KML 2.2 --------------------------------------------------------------------------------------------------

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


def _extended_data(pm: ET.Element, props: dict) -> None:
    ext = _sub(pm, "ExtendedData")
    for k, v in props.items():
        if v is None:
            continue
        data = _sub(ext, "Data", name=k)
        _sub(data, "value", str(v).lower() if isinstance(v, bool) else str(v))


def _placemark(folder: ET.Element, name: str, style: str, props: dict | None = None) -> ET.Element:
    pm = _sub(folder, "Placemark")
    _sub(pm, "name", name)
    _sub(pm, "styleUrl", f"#{style}")
    if props:
        _extended_data(pm, props)
    return pm


def targets_kml(results: Iterable[GroupResult], max_lines_of_sight: int | None = 200) -> bytes:
    """A KML 2.2 document: one Folder per group with the estimates, truth, 95 % ellipses, flight path and lines of
    sight. Geometry is clamped to the ground (KML's absolute altitude is above the geoid, not the ellipsoid);
    the ellipsoidal height of every point is in its ExtendedData (`alt_m`)."""
    results = list(results)
    ET.register_namespace("", KML_NS)
    root = ET.Element(f"{{{KML_NS}}}kml")
    doc = _sub(root, "Document")
    _sub(doc, "name", "ridgeloc targets")
    _sub(doc, "description", f"Target estimates per flight group and method. Heights: {ALT_DATUM}.")
    for method, color in METHOD_COLORS.items():
        st = _sub(doc, "Style", id=f"est-{method}")
        icon = _sub(st, "IconStyle")
        _sub(icon, "color", _kml_color(color))
        _sub(_sub(icon, "Icon"), "href", "http://maps.google.com/mapfiles/kml/shapes/placemark_circle.png")
        ls = _sub(st, "LineStyle")
        _sub(ls, "color", _kml_color(color))
        _sub(ls, "width", "2")
        _sub(_sub(st, "PolyStyle"), "color", _kml_color(color, 0x40))
    for sid, color, width in (("truth", "#000000", "2"), ("path", "#1F77B4", "3"), ("los", "#7F7F7F", "1")):
        st = _sub(doc, "Style", id=sid)
        icon = _sub(st, "IconStyle")
        _sub(icon, "color", _kml_color(color))
        _sub(_sub(icon, "Icon"), "href", "http://maps.google.com/mapfiles/kml/shapes/star.png")
        ls = _sub(st, "LineStyle")
        _sub(ls, "color", _kml_color(color, 0xC0 if sid == "los" else 0xFF))
        _sub(ls, "width", width)
    for r in results:
        folder = _sub(doc, "Folder")
        _sub(folder, "name", r.name)
        rows = {row["method"]: row for row in target_rows([r])}
        for method in ordered_methods(r.estimates):
            e = r.estimates[method]
            if not np.isfinite(e.position_m).all():
                continue
            row = rows[method]
            style = f"est-{method}" if method in METHOD_COLORS else "truth"
            pm = _placemark(folder, f"{r.name}: {method_label(method)}", style, row)
            _sub(_sub(pm, "Point"), "coordinates", _kml_coords(geodetic_from_enu(e.position_m, r.origin_lla)))
            if row["ellipse95_semi_major_m"] is not None and row["ellipse95_semi_major_m"] >= MIN_ELLIPSE_M:
                ring_en = ellipse_points_en_m(np.asarray(e.covariance_m2)[:2, :2], ELLIPSE_CONFIDENCE)
                ring_enu = np.column_stack([ring_en + e.position_m[:2], np.full(len(ring_en), e.position_m[2])])
                pm = _placemark(folder, f"{r.name}: {method_label(method)} 95 % error ellipse", style)
                poly = _sub(pm, "Polygon")
                ring = _sub(_sub(poly, "outerBoundaryIs"), "LinearRing")
                _sub(ring, "coordinates", _kml_coords(geodetic_from_enu(ring_enu, r.origin_lla)))
        if r.truth_m is not None:
            lla = geodetic_from_enu(r.truth_m, r.origin_lla)
            pm = _placemark(folder, f"{r.name}: truth", "truth", {"alt_m": _num(lla[2]), "alt_datum": ALT_DATUM})
            _sub(_sub(pm, "Point"), "coordinates", _kml_coords(lla))
        obs = r.observations
        if obs.n >= 2:
            pm = _placemark(folder, f"{r.name}: flight path", "path")
            _sub(_sub(pm, "LineString"), "coordinates", _kml_coords(geodetic_from_enu(obs.platform_m, r.origin_lla)))
        seg, _ = lines_of_sight_m(obs, best_reference_m(r), max_lines_of_sight)
        if len(seg):
            pm = _placemark(folder, f"{r.name}: lines of sight", "los")
            multi = _sub(pm, "MultiGeometry")
            for s in seg:
                _sub(_sub(multi, "LineString"), "coordinates", _kml_coords(geodetic_from_enu(s, r.origin_lla)))
    ET.indent(root)
    return ET.tostring(root, encoding="utf-8", xml_declaration=True)


def write_targets_kml(path: str | PathLike, results: Iterable[GroupResult],
                      max_lines_of_sight: int | None = 200) -> None:
    """targets.kml: see `targets_kml`."""
    atomic_write_bytes(path, targets_kml(results, max_lines_of_sight))
