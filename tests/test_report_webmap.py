"""report.html's interactive maps: self-contained (Leaflet inline, nothing from a CDN), and rendered by a real
browser (headless Chromium, Debian's `chromium` package) with every layer drawn and each method toggled."""

from __future__ import annotations

import re
import shutil
import subprocess
import tempfile
from pathlib import Path

import numpy as np
import pytest

from pipeline.report.answers import determined_estimates, shown_covariance
from pipeline.report.html import report_html
from pipeline.report.labels import METHOD_COLORS, method_label, ordered_methods
from pipeline.report.webmap import ASSETS, MAX_LINES_OF_SIGHT, leaflet_head, map_fragment
from support.synthetic import synthetic_group

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
needs_chromium = pytest.mark.skipif(
    CHROMIUM is None, reason="headless Chromium not installed (Debian: apt-get install chromium; .ci/run installs it)")
# The flags that work on this project's machines (no sandbox as root, no network chatter): see docs/outputs.md.
CHROMIUM_FLAGS = ("--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
                  "--disable-background-networking", "--disable-component-update", "--disable-sync",
                  "--hide-scrollbars", "--virtual-time-budget=8000")


@pytest.fixture(scope="module")
def groups():
    return [synthetic_group("g1", seed=11, intersection_angle_deg=50, n_frames=12),
            synthetic_group("g2", seed=12, intersection_angle_deg=25, n_frames=10, truth_known=False)]


def _layer_names(r) -> list[str]:
    names = ["Flight path", "Lines of sight"]
    names += [method_label(m) for m in ordered_methods(r.estimates) if np.isfinite(r.estimates[m].position_m).all()]
    return names + (["Truth"] if r.truth_m is not None else [])


def test_the_page_loads_nothing_from_the_network(groups):
    html = report_html(groups, [], {"config": "x"}, {g.name: {} for g in groups})
    assert "<link" not in html and not re.search(r"<script[^>]+src=", html)
    assert "cdn." not in html and "jquery" not in html.lower() and "bootstrap" not in html.lower()
    assert html.count("Leaflet 1.9.4") == 2  # the inline script's and stylesheet's banners, once per page
    assert (ASSETS / "LICENSE").read_text().startswith("BSD 2-Clause License")
    for g in groups:
        frag = map_fragment(g)
        for name in _layer_names(g):
            assert name in frag
        assert "L.control.layers" in frag and "GridLayer" in frag
    assert "tile.openstreetmap.org" in leaflet_head() or "tile.openstreetmap.org" in html  # the online basemap


def _chromium(args: list[str], cwd: str) -> subprocess.CompletedProcess:
    with tempfile.TemporaryDirectory() as profile:
        return subprocess.run([CHROMIUM, *CHROMIUM_FLAGS, f"--user-data-dir={profile}", *args], cwd=cwd,
                              capture_output=True, text=True, timeout=180)


# After load: count the drawn vector layers, untick "Weighted MLE" in the first map's layer control, count again.
_TOGGLE = """<script>
window.addEventListener('load', function () {
  setTimeout(function () {
    var map = document.querySelector('.webmap:not([data-group="answers"])');
    var count = function () { return map.querySelectorAll('path.leaflet-interactive').length; };
    var before = count();
    var labels = Array.prototype.slice.call(map.querySelectorAll('.leaflet-control-layers-overlays label'));
    var mle = labels.filter(function (l) { return l.textContent.indexOf('Weighted MLE') >= 0; })[0];
    mle.querySelector('input').click();
    document.body.setAttribute('data-toggle', before + ',' + count() + ',' + labels.length + ',' +
      map.querySelectorAll('canvas').length);
  }, 1500);
});
</script>"""


@needs_chromium
def test_chromium_draws_every_layer_and_toggles_a_method(groups, tmp_path):
    g = groups[0]
    html = report_html([g], [], {"config": "x"}, {g.name: {}}).replace("</body>", _TOGGLE + "</body>")
    (tmp_path / "report.html").write_text(html)
    out = _chromium(["--dump-dom", (tmp_path / "report.html").as_uri()], str(tmp_path))
    m = re.search(r'data-toggle="(\d+),(\d+),(\d+),(\d+)"', out.stdout)
    assert m, (out.stdout[-2000:], out.stderr[-2000:])
    before, after, n_labels, n_canvas = map(int, m.groups())
    shown = determined_estimates(g)  # the estimates the flight determines: a point each, and their ellipses
    n_methods = len(shown)
    n_ellipses = len([m for m in shown if shown_covariance(g, m) is not None])
    n_los = min(MAX_LINES_OF_SIGHT, g.observations.n)
    # path + start + lines of sight + a marker per method + ellipses + truth, each an SVG path
    assert before == 2 + n_los + n_methods + n_ellipses + 1, (before, n_los, n_methods, n_ellipses)
    assert n_labels == len(_layer_names(g))
    assert after == before - 1 - ("mle" in shown and shown_covariance(g, "mle") is not None)
    assert n_canvas > 0  # the offline grid's tiles


@needs_chromium
def test_screenshot_shows_the_layers_offline(groups, tmp_path):
    """The first map, screenshotted with no network: the grid, the flight path, the truth and the MLE marker are
    all there in their colours (the file viewer shows this PNG; docs/report_webmap.png is one)."""
    import cv2

    g = groups[0]
    page = ("<!DOCTYPE html><html><head><meta charset='utf-8'>" + leaflet_head()
            + "<style>body{margin:0}</style></head><body>" + map_fragment(g, height_px=600) + "</body></html>")
    (tmp_path / "map.html").write_text(page)
    shot = tmp_path / "map.png"
    out = _chromium(["--window-size=1000,600", f"--screenshot={shot}", (tmp_path / "map.html").as_uri()],
                    str(tmp_path))
    assert shot.is_file(), out.stderr[-2000:]
    img = cv2.imread(str(shot))[:, :, ::-1].astype(int)  # RGB

    def share(hex_rgb: str, tol: int = 12) -> float:
        rgb = np.array([int(hex_rgb[i:i + 2], 16) for i in (1, 3, 5)])
        return float(np.mean(np.abs(img - rgb).max(axis=2) <= tol))

    assert share("#F4F4F1", 2) > 0.3  # the plain grid under everything (tiles cannot load here)
    assert share("#1F4E79") > 1e-4  # flight path
    assert share("#FFD700") > 5e-5  # truth
    assert share(METHOD_COLORS["mle"], 20) > 1e-5  # the MLE's marker
    Path(shot).unlink()


def test_answers_on_top_of_each_other_share_one_label():
    """Ten answers within a few metres (the sample flights' one site) get one label, 'first and 9 more'; an
    answer 1.3 km away keeps its own; within 20 m is 'on top' at least, or a fortieth of the map's extent."""
    from types import SimpleNamespace

    from pipeline.report.webmap import shared_labels

    origin = (34.36, 108.76, 400.0)

    def target(label, e_m, n_m):
        return SimpleNamespace(label=label, origin_lla=origin, answer=SimpleNamespace(
            position_m=np.array([e_m, n_m, 0.0]), located=True))

    near = [target(f"g{i}", 3.0 * i, -2.0 * i) for i in range(10)]
    labels = shared_labels([*near, target("far", 0.0, 1300.0), target("close_but_apart", 60.0, 0.0)])
    assert labels == {"g0": "g0 and 9 more", "far": "far", "close_but_apart": "close_but_apart"}
