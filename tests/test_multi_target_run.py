"""Many targets in one pass (issue 21): the sample flight three_targets, plus a target that cannot be located.

Logs are read and each frame decoded once for all targets; a target that cannot be located keeps its rows with
status and reason and leaves the others exactly as they are alone; every output has one feature per (target,
method), and opens in GDAL (ogrinfo) and shapely."""

from __future__ import annotations

import csv
import dataclasses
import json
import shutil
import subprocess
from collections import Counter
from pathlib import Path

import numpy as np
import pytest

from pipeline import run as run_module
from pipeline.flight.frames import TimedDecoder
from pipeline.flight_config import load_flight_config
from pipeline.results import FlightResult
from pipeline.targets import TargetEntry

ROOT = Path(__file__).resolve().parents[1]
CONFIG = ROOT / "configs" / "flights" / "three_targets.yaml"
TRUTH = json.loads((ROOT / "sample_data" / "three_targets" / "truth.json").read_text())


def _with(cfg, *entries):
    return dataclasses.replace(cfg, targets=tuple(entries))


@pytest.fixture(scope="module")
def runs():
    """(the flight with its three targets and an unlocatable `edge` one, reads, decoded frame numbers; the flight
    with small_grey alone)."""
    cfg = load_flight_config(CONFIG)
    edge = TargetEntry("edge", frame_index=4, pixel=(3.0, 3.0))  # inside the image, but no patch around it
    reads, decoded = [], []
    import pipeline.ingest as ingest

    real_read, real_call = ingest.read_flight, TimedDecoder.__call__

    def read_flight(*a, **k):
        reads.append(a[0])
        return real_read(*a, **k)

    def call(self, indices):
        decoded.extend(int(i) for i in indices)
        return real_call(self, indices)

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(ingest, "read_flight", read_flight)
        mp.setattr(TimedDecoder, "__call__", call)
        flight = run_module.process_group(_with(cfg, *cfg.targets[:2], edge, cfg.targets[2]))
    alone = run_module.process_group(_with(cfg, cfg.targets[1]))
    return flight, reads, decoded, alone


def test_logs_read_and_frames_decoded_once_for_every_target(runs):
    flight, reads, decoded, _ = runs
    assert len(reads) == 1
    assert decoded and max(Counter(decoded).values()) == 1  # no frame decoded twice, whatever the targets
    assert all(r.settings["frames_decoded"] == len(decoded) for r in flight.targets)


def test_every_target_is_located_near_its_truth_and_the_bad_one_says_why(runs):
    flight, *_ = runs
    assert isinstance(flight, FlightResult)
    assert [r.target for r in flight.targets] == ["panel", "small_grey", "far_north"]
    (failed,) = flight.failed
    assert failed.target == "edge" and "is not inside frame 4" in failed.message
    truth = {t["name"]: t for t in TRUTH["targets"]}
    for r in flight.targets:
        assert r.truth_m is not None and r.label == f"three_targets:{r.target}"
        err = r.errors_m()["mle"]
        assert err is not None and err < 100.0, (r.target, err)  # ~5 km away, 0.2 deg attitude noise: tens of m
        lost = [i for i, lost in enumerate(r.tracking["lost"]) if lost]
        visible = set(truth[r.target]["visible_observations"])
        assert not set(lost) & visible - {max(visible)}, (r.target, lost)  # lost only where not visible (edge px)
        assert set(range(TRUTH["n_observations"])) - visible <= set(lost)  # and never "found" where hidden
    # the laser aims at the panel: the others keep no range (more than 50 px from the image centre)
    assert flight.targets[0].observations.has_range.any()
    assert not any(r.observations.has_range.any() for r in flight.targets[1:])


def test_a_target_is_unaffected_by_the_others(runs):
    flight, _, _, alone = runs
    assert isinstance(alone, FlightResult) and alone.targets[0].target == "small_grey"
    a, b = flight.targets[1], alone.targets[0]
    assert a.tracking["pixel_px"] == b.tracking["pixel_px"]
    for m, e in b.estimates.items():  # solved with the others or alone: the same answer (to rounding: the
        # targets are solved as one batch, whose BLAS calls may sum in another order on another CPU)
        np.testing.assert_allclose(a.estimates[m].position_m, e.position_m, rtol=1e-12, atol=1e-9)


def test_outputs_one_feature_per_target_and_method(runs, tmp_path):
    from pipeline.report.outputs import write_run_outputs
    from pipeline.report.store import load_group_result, save_group_result
    from pipeline.report.table4 import table4_rows

    flight, *_ = runs
    save_group_result(tmp_path / "result.json", flight)
    again = load_group_result(tmp_path / "result.json")
    assert [t.target for t in again.targets] == ["panel", "small_grey", "far_north"]
    assert again.failed == flight.failed
    paths = write_run_outputs(tmp_path / "out", [flight], [], {"config": "x"}, figures=False)
    answers = list(csv.DictReader(paths["csv"].open()))  # targets.csv: one answer per target
    assert [(a["name"], a["status"]) for a in answers] == [
        ("three_targets:panel", "located"), ("three_targets:small_grey", "located"),
        ("three_targets:far_north", "located"), ("three_targets:edge", "not_located")]
    assert "is not inside frame 4" in answers[-1]["reason"]
    rows = list(csv.DictReader(paths["estimates_csv"].open()))
    assert list(rows[0])[:3] == ["group", "target", "method"]
    keys = [(r["group"], r["target"], r["method"]) for r in rows]
    assert len(keys) == len(set(keys))
    edge = [r for r in rows if r["target"] == "edge"]
    assert edge and all(r["status"] == "not_located" and "is not inside frame 4" in r["reason"] for r in edge)
    solved = {(r["target"], r["method"]) for r in rows if r["lat_deg"]}
    assert {t for t, _ in solved} == {"panel", "small_grey", "far_north"}
    doc = json.loads(paths["estimates_geojson"].read_text())
    est = [f for f in doc["features"] if f["properties"]["kind"] == "estimate"]
    assert sorted((f["properties"]["target"], f["properties"]["method"]) for f in est) == sorted(solved)
    assert all(f["properties"]["name"] == f"three_targets:{f['properties']['target']}" for f in est)
    shapely = pytest.importorskip("shapely.geometry")
    assert all(shapely.shape(f["geometry"]).is_valid for f in doc["features"])
    header = table4_rows([flight])[0]
    assert header == ["method", "three_targets:panel", "three_targets:small_grey", "three_targets:far_north",
                      "three_targets:edge"]
    run_json = json.loads(paths["run"].read_text())
    assert run_json["targets"]["three_targets"]["not_located"]["edge"].startswith("the target mark")
    html = paths["html"].read_text()
    assert html.count("ridgeloc-target-label") >= 3 and "Targets not located (1)" in html
    ogrinfo = shutil.which("ogrinfo")
    if ogrinfo is None:
        pytest.skip("GDAL's ogrinfo not installed")
    # GDAL reads the estimates (one per solved target and method) and the answers (a placemark per located target)
    out = subprocess.run([ogrinfo, "-ro", "-al", "-q", str(paths["estimates_geojson"]), "-where", "kind = 'estimate'"],
                         capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, out.stderr
    assert out.stdout.count("OGRFeature(") == len(solved)
    out = subprocess.run([ogrinfo, "-ro", "-al", "-q", str(paths["kml"])], capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, out.stderr
    placemarks = [ln.split("= ", 1)[1] for ln in out.stdout.splitlines() if ln.strip().startswith("Name (String) =")]
    assert [p for p in placemarks if "ellipse" not in p] == [a["name"] for a in answers[:3]]


CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")


@pytest.mark.skipif(CHROMIUM is None, reason="headless Chromium not installed (Debian: apt-get install chromium)")
def test_the_report_map_shows_every_target_with_a_label_and_a_layer_per_method(runs, tmp_path):
    import re
    import tempfile

    from pipeline.report.html import report_html

    flight, *_ = runs
    html = report_html([flight], [], {"config": "x"}, {r.label: {} for r in flight.targets})
    probe = """<script>window.addEventListener('load', function () { setTimeout(function () {
      var map = document.querySelector('.webmap:not([data-group="answers"])');
      var labels = Array.prototype.map.call(map.querySelectorAll('.leaflet-tooltip.ridgeloc-target-label'),
                                            function (t) { return t.textContent.trim(); });
      var layers = Array.prototype.map.call(map.querySelectorAll('.leaflet-control-layers-overlays label'),
                                            function (l) { return l.textContent.trim(); });
      document.body.setAttribute('data-probe', JSON.stringify({
        maps: document.querySelectorAll('.webmap:not([data-group="answers"])').length, labels: labels,
        layers: layers}));
    }, 1500); });</script>"""
    (tmp_path / "report.html").write_text(html.replace("</body>", probe + "</body>"))
    flags = ("--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
             "--disable-background-networking", "--disable-component-update", "--disable-sync",
             "--virtual-time-budget=8000")
    with tempfile.TemporaryDirectory() as profile:
        out = subprocess.run([CHROMIUM, *flags, f"--user-data-dir={profile}", "--dump-dom",
                              (tmp_path / "report.html").as_uri()], capture_output=True, text=True, timeout=180)
    m = re.search(r'data-probe="([^"]*)"', out.stdout)
    assert m, (out.stdout[-1500:], out.stderr[-1500:])
    from html import unescape

    probe = json.loads(unescape(m.group(1)))
    assert probe["maps"] == 1  # one map of the flight with all its targets
    assert sorted(probe["labels"]) == ["far_north", "panel", "small_grey"]
    from pipeline.report.labels import method_label

    methods = {m for r in flight.targets for m, e in r.estimates.items() if np.isfinite(e.position_m).all()}
    assert sorted(probe["layers"]) == sorted(["Flight path", "Lines of sight", "Truth", "Target names",
                                              "Camera footprints", "Frame centre: ridgeloc",
                                              *[method_label(m) for m in methods]])
