"""targets.csv and estimates.csv against their documented columns, targets.kml as KML 2.2, and the uncertainty
numbers in them."""

from __future__ import annotations

import csv
import dataclasses
import math
import re
import shutil
import subprocess
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest
from test_export_geojson import ORIGIN, hand_group, rotated_cov

from pipeline.geometry.geoid import geoid_undulation_m
from pipeline.report.answers import ANSWER_COLUMNS
from pipeline.report.exports import (
    ESTIMATES_CSV_COLUMNS,
    KML_SCHEMAS,
    kml_field_type,
    write_estimates_csv,
    write_targets_csv,
    write_targets_geojson,
    write_targets_kml,
)
from pipeline.report.store import load_group_result, save_group_result
from pipeline.solve.estimate import Estimate
from pipeline.solve.uncertainty import cep_m, ellipse_axes_m

DOCS = Path(__file__).resolve().parent.parent / "docs" / "outputs.md"
KML = "{http://www.opengis.net/kml/2.2}"


def documented_csv_columns(name: str = "targets.csv") -> list[str]:
    """The first column of the table under '## `<name>`' in docs/outputs.md."""
    text = DOCS.read_text()
    section = text.split(f"## `{name}`", 1)[1].split("\n## ", 1)[0]
    return re.findall(r"^\| `([a-z0-9_]+)` \|", section, flags=re.M)


@pytest.fixture(scope="module")
def groups():
    return [hand_group("g1"), hand_group("g2", truth=False, seed=4)]


def test_csv_columns_are_the_documented_ones(tmp_path, groups):
    write_targets_csv(tmp_path / "targets.csv", groups)
    write_estimates_csv(tmp_path / "estimates.csv", groups)
    for name, columns, n in (("targets.csv", ANSWER_COLUMNS, 2), ("estimates.csv", ESTIMATES_CSV_COLUMNS, 8)):
        with (tmp_path / name).open(newline="") as f:
            rows = list(csv.DictReader(f))
        documented = documented_csv_columns(name)
        assert len(documented) > 20
        assert list(rows[0].keys()) == documented == list(columns)
        assert len(rows) == n  # one per target; 2 groups x 4 methods, the diverged one included
        assert {r["alt_datum"] for r in rows} == {"WGS84 ellipsoidal height (EPSG:4979)"}


def test_csv_values(tmp_path, groups):
    path = tmp_path / "estimates.csv"
    write_estimates_csv(path, groups)
    with path.open(newline="") as f:
        rows = {(r["group"], r["method"]): r for r in csv.DictReader(f)}
    g1 = groups[0]
    # Table-4 order within a group
    assert [m for (g, m) in rows if g == "g1"] == ["vision", "range", "ridge", "mle"]
    for m in ("vision", "ridge", "mle"):
        r = rows[("g1", m)]
        pos = g1.estimates[m].position_m
        d = pos - g1.truth_m
        assert float(r["error_m"]) == pytest.approx(math.sqrt(d @ d), abs=1e-3)
        assert float(r["error_horizontal_m"]) == pytest.approx(math.hypot(d[0], d[1]), abs=1e-3)
        assert float(r["error_up_m"]) == pytest.approx(d[2], abs=1e-3)
        assert [float(r[k]) for k in ("e_m", "n_m", "u_m")] == pytest.approx(pos, abs=1e-3)
        assert 28.0 < float(r["lat_deg"]) < 29.0 or abs(float(r["lat_deg"]) - ORIGIN[0]) < 0.1
        assert r["converged"] == "true"
    mle = rows[("g1", "mle")]
    assert float(mle["sigma_up_m"]) == pytest.approx(3.0)
    assert float(mle["ellipse95_azimuth_deg"]) == pytest.approx(30.0, abs=0.01)
    assert float(mle["cep50_m"]) < float(mle["cep90_m"])
    # vision states no covariance: the one propagated through it under the stated errors, said so
    assert rows[("g1", "vision")]["covariance_source"] == "propagated" and float(rows[("g1", "vision")]["cep50_m"]) > 0
    assert mle["covariance_source"] == "estimator" and mle["answer"] == "true" and mle["determined"] == "true"
    rng = rows[("g1", "range")]
    assert rng["lat_deg"] == "" and rng["error_m"] == "" and rng["status"] == "diverged"
    assert rng["converged"] == "false"
    assert rows[("g2", "mle")]["error_m"] == ""  # no truth known


def test_geometry_warnings_reach_every_estimates_reason(tmp_path, groups):
    """A group's geometry warnings (`ridgeloc run`'s checks: settings["geometry_warnings"]) are in the reason of
    each of its finite estimates, after the solver's own reason (the mle's fit message); one without a finite
    position (range, diverged) does not get them, nor do the other groups' estimates."""
    warned = hand_group("g1")
    warned.settings["geometry_warnings"] = ["the lines of sight are nearly parallel"]
    warned.estimates["mle"].extras["fit"] = {"message": "mle: the error model does not fit this flight"}
    path = tmp_path / "estimates.csv"
    write_estimates_csv(path, [warned, groups[1]])
    with path.open(newline="") as f:
        rows = {(r["group"], r["method"]): r for r in csv.DictReader(f)}
    parallel = "the lines of sight are nearly parallel"
    assert rows[("g1", "vision")]["reason"] == rows[("g1", "ridge")]["reason"] == parallel
    assert rows[("g1", "mle")]["reason"] == ("mle: the error model does not fit this flight; the lines of sight are "
                                             "nearly parallel")
    assert "nearly parallel" not in rows[("g1", "range")]["reason"]
    assert all(r["reason"] == "" for (g, m), r in rows.items() if g == "g2" and m != "range")


def test_kml_is_kml22_and_agrees_with_geojson_and_csv(tmp_path, groups):
    import json

    write_targets_kml(tmp_path / "t.kml", groups)
    write_targets_geojson(tmp_path / "t.geojson", groups)
    write_targets_csv(tmp_path / "t.csv", groups)
    root = ET.parse(tmp_path / "t.kml").getroot()
    assert root.tag == f"{KML}kml"
    placemarks = root.findall(f"{KML}Document/{KML}Placemark")
    # one placemark per located target and one for its ellipse
    assert [pm.findtext(f"{KML}name") for pm in placemarks] == ["g1", "g1: 95 % error ellipse", "g2",
                                                                "g2: 95 % error ellipse"]
    gj = {f["properties"]["name"]: f for f in json.loads((tmp_path / "t.geojson").read_text())["features"]
          if f["properties"]["kind"] == "target"}
    with (tmp_path / "t.csv").open(newline="") as f:
        rows = {r["name"]: r for r in csv.DictReader(f)}
    styles = {s.get("id") for s in root.iter(f"{KML}Style")}
    for pm in placemarks:
        assert pm.findtext(f"{KML}styleUrl").lstrip("#") in styles
        ring = pm.findtext(f".//{KML}LinearRing/{KML}coordinates")
        if ring is not None:
            coords = [tuple(map(float, p.split(","))) for p in ring.split()]
            assert coords[0] == coords[-1] and len(coords) >= 4
            continue
        name = pm.findtext(f"{KML}name")
        c = [float(v) for v in pm.findtext(f"{KML}Point/{KML}coordinates").split(",")]
        assert pm.findtext(f"{KML}Point/{KML}altitudeMode") == "absolute"
        lon, lat, h = gj[name]["geometry"]["coordinates"]
        assert c[:2] == pytest.approx([lon, lat], abs=1e-7)
        assert [float(rows[name]["lon_deg"]), float(rows[name]["lat_deg"])] == pytest.approx([lon, lat], abs=1e-7)
        # KML height = GeoJSON (ellipsoidal) height - the geoid undulation at the point
        n_m = float(geoid_undulation_m(lat, lon))
        assert abs(n_m) > 1.0  # Zurich: ~47-48 m; a KML still in ellipsoidal heights would fail here
        assert c[2] == pytest.approx(h - n_m, abs=0.011) and float(rows[name]["alt_msl_m"]) == pytest.approx(
            h - n_m, abs=0.011)
        assert rows[name]["mgrs"] in pm.findtext(f"{KML}description")
        # the balloon's CE90 and LE90 as the CoT remarks give them: one decimal each (LE90 had targets.csv's three)
        ce, le = (float(rows[name][k]) for k in ("ce90_m", "le90_m"))
        assert f"CE90 {ce:.1f} m, LE90 {le:.1f} m (" in pm.findtext(f"{KML}description")


def test_kml_attributes_are_typed_by_a_schema(tmp_path, groups):
    """Every SimpleData is declared in the Schema its SchemaData names, with a KML type its text parses as;
    numeric columns are double/int, not string (GDAL reads them as Real/Integer; see the ogrinfo test)."""
    write_targets_kml(tmp_path / "t.kml", groups)
    root = ET.parse(tmp_path / "t.kml").getroot()
    schemas = {s.get("id"): {f.get("name"): f.get("type") for f in s.findall(f"{KML}SimpleField")}
               for s in root.iter(f"{KML}Schema")}
    assert set(schemas) == set(KML_SCHEMAS)
    assert schemas["target"]["error_m"] == "double" and schemas["target"]["n_observations"] == "int"
    assert schemas["target"]["mgrs"] == "string" and schemas["target"]["method"] == "string"
    assert schemas["target"]["alt_msl_m"] == "double" and schemas["target"]["ce90_m"] == "double"
    parse = {"double": float, "int": int, "string": str}
    n = 0
    for sd in root.iter(f"{KML}SchemaData"):
        fields = schemas[sd.get("schemaUrl").lstrip("#")]
        for d in sd.findall(f"{KML}SimpleData"):
            parse[fields[d.get("name")]](d.text)
            n += 1
    assert n > 30
    assert not list(root.iter(f"{KML}Data"))  # no untyped attributes left
    assert kml_field_type("reason") == "string" and kml_field_type("cep50_m") == "double"


def test_ogrinfo_reads_typed_kml_fields(tmp_path, groups):
    """GDAL's own reading (skipped where gdal-bin is not installed; the schema test above checks without it)."""
    if shutil.which("ogrinfo") is None:
        pytest.skip("ogrinfo (GDAL, Debian package gdal-bin) is not installed")
    write_targets_kml(tmp_path / "t.kml", groups)
    out = subprocess.run(["ogrinfo", "-al", "-so", str(tmp_path / "t.kml")], capture_output=True, text=True,
                         check=True).stdout
    for field, kind in (("error_m", "Real"), ("alt_msl_m", "Real"), ("ce90_m", "Real"), ("n_observations", "Integer"),
                        ("mgrs", "String")):
        assert re.search(rf"^{field}: {kind}", out, flags=re.M), (field, kind, out[:2000])


def test_ogrinfo_reads_targets_csv_as_points(tmp_path, groups):
    """targets.csvt and targets.prj beside targets.csv: GDAL opens it as WGS84 points at (lon_deg, lat_deg), with
    numbers as numbers (without them every column was a String and no geometry)."""
    if shutil.which("ogrinfo") is None:
        pytest.skip("ogrinfo (GDAL, Debian package gdal-bin) is not installed")
    write_targets_csv(tmp_path / "targets.csv", groups)
    rows = list(csv.DictReader((tmp_path / "targets.csv").open()))
    located = [r for r in rows if r["lat_deg"]]
    assert located
    out = subprocess.run(["ogrinfo", "-ro", "-al", str(tmp_path / "targets.csv")], capture_output=True, text=True,
                         check=True).stdout
    assert "Geometry: Point" in out and f"Feature Count: {len(rows)}" in out and "WGS 84" in out
    for field, kind in (("ce90_m", "Real"), ("alt_msl_m", "Real"), ("n_observations", "Integer"),
                        ("mgrs", "String"), ("lat_deg", "Real")):
        assert re.search(rf"^{field}: {kind}", out, flags=re.M), (field, kind)
    points = [tuple(map(float, m)) for m in re.findall(r"POINT \(([-\d.]+) ([-\d.]+)\)", out)]
    assert points == [(float(r["lon_deg"]), float(r["lat_deg"])) for r in located]


@pytest.mark.parametrize("sigma", [0.5, 2.0, 10.0])
def test_cep_closed_forms_circular(sigma):
    cov = np.diag([sigma ** 2, sigma ** 2])
    assert cep_m(cov, 0.5) == pytest.approx(sigma * math.sqrt(2 * math.log(2)), rel=1e-6)
    assert cep_m(cov, 0.9) == pytest.approx(sigma * math.sqrt(2 * math.log(10)), rel=1e-6)


def test_cep_degenerate_and_correlated():
    # one axis vanishing: the 1D half-normal quantiles (0.674490, 1.644854 sigma)
    assert cep_m(np.diag([9.0, 1e-10]), 0.5) == pytest.approx(3 * 0.6744897501960817, rel=1e-4)
    assert cep_m(np.diag([9.0, 1e-10]), 0.9) == pytest.approx(3 * 1.6448536269514722, rel=1e-4)
    # correlated: the fraction of Gaussian samples inside the CEP circles
    cov = rotated_cov(5.0, 1.5, 70.0)[:2, :2]
    x = np.random.default_rng(0).multivariate_normal([0, 0], cov, 200_000)
    r = np.hypot(x[:, 0], x[:, 1])
    assert np.mean(r <= cep_m(cov, 0.5)) == pytest.approx(0.5, abs=0.004)
    assert np.mean(r <= cep_m(cov, 0.9)) == pytest.approx(0.9, abs=0.003)
    a, b, az = ellipse_axes_m(cov)
    inside = (x @ np.array([math.sin(math.radians(az)), math.cos(math.radians(az))])) ** 2 / a ** 2 + (
        x @ np.array([math.cos(math.radians(az)), -math.sin(math.radians(az))])) ** 2 / b ** 2 <= 1
    assert np.mean(inside) == pytest.approx(0.95, abs=0.003)


def test_group_result_round_trip(tmp_path, groups):
    g = groups[0]
    g.timings_s["solve"] = 0.25
    save_group_result(tmp_path / "result.json", g)
    back = load_group_result(tmp_path / "result.json")
    assert back.name == g.name and back.origin_lla == g.origin_lla
    np.testing.assert_array_equal(back.truth_m, g.truth_m)
    np.testing.assert_array_equal(back.observations.P, g.observations.P)
    np.testing.assert_array_equal(back.observations.pixel, g.observations.pixel)
    assert back.intersection_angle_deg == g.intersection_angle_deg
    assert back.timings_s == {"solve": 0.25}
    for m, e in g.estimates.items():
        b = back.estimates[m]
        np.testing.assert_array_equal(b.position_m, e.position_m)  # NaN stays NaN
        assert (b.status, b.iterations, b.method) == (e.status, e.iterations, e.method)
        if e.covariance_m2 is None:
            assert b.covariance_m2 is None
        else:
            np.testing.assert_array_equal(b.covariance_m2, e.covariance_m2)


def test_group_result_with_nan_in_extras_is_strict_json(tmp_path, groups):
    """An MLE from one observation has no degrees of freedom: its sigma0_sq is NaN (a 60 kB cut of
    aphill_klv_10s.ts failed with 'internal error (ValueError): Out of range float values are not JSON compliant')."""
    mle = groups[0].estimates["mle"]
    nan_mle = Estimate(mle.method, mle.position_m, mle.iterations, mle.status, covariance_m2=mle.covariance_m2,
                       extras={"sigma0_sq": float("nan"), "variance_factors": {"pixel": float("inf")},
                               "starts": [[1.0, float("nan")]]})
    g = dataclasses.replace(groups[0], estimates={**groups[0].estimates, "mle": nan_mle})
    save_group_result(tmp_path / "result.json", g)
    back = load_group_result(tmp_path / "result.json")
    assert back.estimates["mle"].extras == {"sigma0_sq": None, "variance_factors": {"pixel": None},
                                            "starts": [[1.0, None]]}
