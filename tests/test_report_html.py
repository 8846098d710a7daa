"""The run output folder: report.html is self-contained and says what happened; group folders are reusable."""

from __future__ import annotations

import base64
import json
import re
import struct

import numpy as np
import pytest

from pipeline.atomic import is_done
from pipeline.report import load_finished_group, write_group_outputs, write_run_outputs
from pipeline.results import GroupFailure
from support.synthetic import synthetic_group


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    out = tmp_path_factory.mktemp("run")
    results = [synthetic_group("group1", seed=11, intersection_angle_deg=50, n_frames=14),
               synthetic_group("group2", seed=12, intersection_angle_deg=25, n_frames=10, truth_known=False)]
    failures = [GroupFailure("group3", "/data/g3/flight.yaml",
                             "/data/g3/cam.mp4: cannot decode frame 12 <corrupt & truncated>")]
    settings = {"config": "configs/sample.yaml", "workers": 2, "methods": ["all"]}
    paths = write_run_outputs(out, results, failures, settings)
    return out, results, paths


def png_size(png: bytes) -> tuple[int, int]:
    assert png[:8] == b"\x89PNG\r\n\x1a\n"
    return struct.unpack(">II", png[16:24])


def test_run_folder_has_every_output(run):
    out, results, paths = run
    assert sorted(p.name for p in paths.values()) == ["estimates.csv", "estimates.geojson", "report.html", "run.json",
                                                      "targets.csv", "targets.geojson", "targets.kml"]
    for p in paths.values():
        assert p.parent == out and p.is_file() and p.stat().st_size > 0
    for r in results:
        folder = out / r.name
        assert is_done(folder)
        for f in ("result.json", "map.png", "view3d.png", "residuals.png", "estimates.geojson"):
            assert (folder / f).is_file()
        w, h = png_size((folder / "map.png").read_bytes())
        assert w >= 1000 and h >= 500
    assert not list(out.glob(".tmp-*"))
    doc = json.loads((out / "run.json").read_text())
    assert [a["name"] for a in doc["answers"]] == ["group1", "group2", "group3"]  # the answers first
    assert [a["status"] for a in doc["answers"]] == ["located", "located", "not_located"]
    assert doc["groups"] == ["group1", "group2"]
    assert doc["failures"][0]["name"] == "group3"
    assert doc["software"]["numpy"] == np.__version__


def test_report_is_self_contained_and_complete(run):
    out, results, _ = run
    html = (out / "report.html").read_text()
    # nothing fetched from elsewhere: no linked scripts or stylesheets, no remote images (the scripts are inline:
    # Leaflet and the interactive maps; only their basemap's tiles come from the network, when there is one)
    assert not re.search(r"<script[^>]+src=|<link|src=\"(?!data:)", html)
    assert not any("url(" in css for css in re.findall(r"<style>(.*?)</style>", html, flags=re.S))
    imgs = re.findall(r'<img src="data:image/png;base64,([A-Za-z0-9+/=]+)"', html)
    assert len(imgs) == 3 * len(results)
    for b64 in imgs:
        png_size(base64.b64decode(b64))
    # the failure is listed, its message escaped
    assert "Failed groups (1)" in html
    assert "cannot decode frame 12 &lt;corrupt &amp; truncated&gt;" in html
    assert "<corrupt" not in html
    # settings and software versions
    assert "configs/sample.yaml" in html and f"<td class=\"l\">{np.__version__}</td>" in html
    for r in results:
        assert f'id="group-{r.name}"' in html


def test_summary_highlights_the_smallest_error(run):
    out, results, _ = run
    html = (out / "report.html").read_text()
    table = html.split("(the paper's Table 4)", 1)[1].split("</table>", 1)[0]
    g1 = results[0]
    errors = {m: float(np.linalg.norm(e.position_m - g1.truth_m)) for m, e in g1.estimates.items()}
    best = min(errors, key=errors.get)
    cells = re.findall(r'<td class="best">([0-9.,]+)', table)
    assert cells == [f"{errors[best]:,.2f}"]  # one group with a truth, one highlighted cell
    assert table.count("no truth") == len(results[1].estimates)
    assert "Angle /°" in table and "<td>14<" in table  # Table 3's columns
    # beside ours, the paper's values for a group of the same name (group1: Table 3 and the ridge row of Table 4)
    assert '<div class="paper">paper 16</div>' in table and '<div class="paper">paper 8.68</div>' in table


def test_finished_group_is_reused_only_for_the_same_config(tmp_path):
    r = synthetic_group("g", seed=3, n_frames=6)
    write_group_outputs(tmp_path, r, config_digest="abc", figures=False)
    back = load_finished_group(tmp_path, "g", "abc")
    assert back is not None
    np.testing.assert_array_equal(back.estimates["mle"].position_m, r.estimates["mle"].position_m)
    assert load_finished_group(tmp_path, "g", "other-config") is None
    assert load_finished_group(tmp_path, "missing", "abc") is None
    (tmp_path / "g" / ".done").unlink()  # an unfinished folder is never reused
    assert load_finished_group(tmp_path, "g", "abc") is None
    # rewriting replaces the folder as a whole: no file of the old one survives
    (tmp_path / "g" / "stale.txt").write_text("old")
    write_group_outputs(tmp_path, r, config_digest="def", figures=False)
    assert not (tmp_path / "g" / "stale.txt").exists()
    assert load_finished_group(tmp_path, "g", "def") is not None


def test_flight_settings_show_paths_relative_to_the_config(tmp_path):
    """report.html must not show the folders of the machine that ran it: paths are relative to the config."""
    from pipeline.report.html import relative_paths, report_html

    g = synthetic_group("g1", seed=3, intersection_angle_deg=40, n_frames=8)
    g.settings.update({"path": "/home/someone/survey/configs/flights/g1.yaml",
                       "files": {"telemetry": ["/home/someone/survey/data/g1/flight.tlog"],
                                 "video": "/home/someone/survey/data/g1/video.mp4", "frames_csv": None},
                       "truth_file": "/home/someone/survey/configs/flights/truth.json", "name": "g1"})
    rel = relative_paths(g.settings)
    assert rel["path"] == "g1.yaml" and rel["truth_file"] == "truth.json"
    assert rel["files"]["telemetry"] == ["../../data/g1/flight.tlog"]
    assert rel["files"]["video"] == "../../data/g1/video.mp4" and rel["files"]["frames_csv"] is None
    assert g.settings["files"]["video"].startswith("/home/someone")  # the result itself keeps them
    html = report_html([g], [], {"config": "configs/sample.yaml"}, {"g1": {}})
    assert "/home/someone" not in html and "../../data/g1/flight.tlog" in html
