"""The interactive map of a group in report.html: Leaflet through folium, with every asset embedded.

    group_map(r) -> folium.Map       flight path, lines of sight, a video flight's camera footprints and frame-centre
                                     tracks (ridgeloc's, the payload's KLV), truth, each method's estimate and 95 %


    answers_map(targets) -> folium.Map  the targets' answers with their 95 % ellipses and names (the report's top)
    answer_sites(results)            located targets grouped by site (a map each)
    group_map(r) -> folium.Map       flight path, lines of sight, truth, each determined method's estimate and 95 %
                                     ellipse, one layer per method (toggled in the layer control)
    map_fragment(r) -> str           the map's <div> and <script> for a page that already loads Leaflet
    leaflet_head() -> str            Leaflet's CSS and JS inline (once per page)

folium links Leaflet, jQuery and Bootstrap from CDNs by default; here those links are dropped and Leaflet 1.9.4 (the
npm package `leaflet`, vendored under pipeline/report/assets/leaflet with its BSD-2 licence) is inlined, and only
core Leaflet layers are used (circle markers, polylines, polygons), so the page works offline. The base layer is
OpenStreetMap's tiles when the browser can reach them; beneath it a plain grid drawn in the browser (a Leaflet
GridLayer of canvas tiles, no network) shows where the tiles cannot load.
"""

from __future__ import annotations

import functools
import re
from collections.abc import Sequence
from html import escape
from pathlib import Path

import numpy as np

from pipeline.geometry.geodesic import pairwise_geodesic_m
from pipeline.report.answers import answer_of, answer_row, determined_estimates, shown_covariance
from pipeline.report.geometry import (
    best_reference_m,
    geodetic_from_enu,
    lines_of_sight_m,
)
from pipeline.report.labels import METHOD_COLORS, method_label, one_decimal, ordered_methods
from pipeline.results import GroupResult
from pipeline.solve.uncertainty import ELLIPSE_CONFIDENCE, ellipse_points_en_m

ASSETS = Path(__file__).resolve().parent / "assets" / "leaflet"
OSM_TILES = "https://tile.openstreetmap.org/{z}/{x}/{y}.png"
OSM_ATTRIBUTION = '&copy; <a href="https://www.openstreetmap.org/copyright">OpenStreetMap</a> contributors'
MAX_LINES_OF_SIGHT = 60

# A grid of canvas tiles under the basemap: visible where the tiles do not load (offline).
_GRID_JS = """
(function (map) {
  var Grid = L.GridLayer.extend({
    createTile: function (coords) {
      var tile = document.createElement('canvas');
      var size = this.getTileSize();
      tile.width = size.x; tile.height = size.y;
      var ctx = tile.getContext('2d');
      ctx.fillStyle = '#f4f4f1'; ctx.fillRect(0, 0, size.x, size.y);
      ctx.strokeStyle = '#c9c9c4'; ctx.lineWidth = 1;
      ctx.beginPath();
      for (var i = 0; i <= 4; i++) {
        var p = i * size.x / 4 + 0.5;
        ctx.moveTo(p, 0); ctx.lineTo(p, size.y); ctx.moveTo(0, p); ctx.lineTo(size.x, p);
      }
      ctx.stroke();
      return tile;
    }
  });
  new Grid({zIndex: 0, maxZoom: 24, className: 'ridgeloc-grid'}).addTo(map);
})(%s);
"""


@functools.cache
def leaflet_head() -> str:
    """Leaflet's stylesheet and script, inline, for a page's <head> (no network needed)."""
    # its url()s (icons images/*.png of the default marker and the collapsed layer control, old IE's VML) are
    # unused here: dropped, so the page asks for no file at all
    css = re.sub(r"url\([^)]*\)", "none", (ASSETS / "leaflet.css").read_text())
    js = (ASSETS / "leaflet.js").read_text()
    return (f"<style>/* Leaflet 1.9.4, BSD-2-Clause, see pipeline/report/assets/leaflet/LICENSE */\n{css}</style>\n"
            f"<script>{js}</script>\n")


def _latlon(lla: np.ndarray) -> list[list[float]]:
    return [[round(float(a), 8), round(float(b), 8)] for a, b in np.atleast_2d(lla)[:, :2]]


def group_map(r: GroupResult | Sequence[GroupResult], tiles: bool = True):
    """A folium.Map of one group (see the module docstring); its CDN links are removed. A list of GroupResults
    (the named targets of one flight) gives one map of them all: the flight path and lines of sight of the first,
    each target's truth, a layer per method holding every target's estimate and ellipse, and a permanent label
    per target (at its mle, else its first estimate)."""
    import folium

    targets = [r] if isinstance(r, GroupResult) else list(r)
    r = targets[0]
    obs = r.observations
    path = geodetic_from_enu(obs.platform_m, r.origin_lla)
    m = folium.Map(location=[float(r.origin_lla[0]), float(r.origin_lla[1])], zoom_start=14, tiles=None,
                   control_scale=True, max_zoom=22, prefer_canvas=False)
    m.default_js, m.default_css = [], []  # Leaflet comes inline with the page (leaflet_head); nothing from a CDN
    if tiles:
        folium.TileLayer(OSM_TILES, attr=OSM_ATTRIBUTION, name="OpenStreetMap", max_zoom=22, max_native_zoom=19,
                         control=False).add_to(m)
    bounds = _latlon(path)

    layer = folium.FeatureGroup(name="Flight path", show=True)
    if obs.n >= 2:
        folium.PolyLine(_latlon(path), color="#1F4E79", weight=3, tooltip="flight path").add_to(layer)
    if obs.n:
        folium.CircleMarker(_latlon(path[0])[0], radius=5, color="#1F4E79", fill=True, fill_opacity=1.0,
                            tooltip="path start").add_to(layer)
    layer.add_to(m)

    seg, _ = lines_of_sight_m(obs, best_reference_m(r), MAX_LINES_OF_SIGHT)
    if len(seg):
        layer = folium.FeatureGroup(name="Lines of sight", show=True)
        for s in geodetic_from_enu(seg, r.origin_lla):
            folium.PolyLine(_latlon(s), color="#7F7F7F", weight=1, opacity=0.7).add_to(layer)
        layer.add_to(m)

    _footprint_layers(m, r)

    truths = [t for t in targets if t.truth_m is not None]
    if truths:  # under the estimates, which are drawn after it
        layer = folium.FeatureGroup(name="Truth", show=True)
        for t in truths:
            lla = geodetic_from_enu(t.truth_m, t.origin_lla)
            who = "" if t.target is None else f"{escape(t.target)} "
            folium.CircleMarker(_latlon(lla)[0], radius=9, color="#000000", weight=2, fill=True,
                                fill_color="#FFD700", fill_opacity=1.0,
                                tooltip=f"{who}truth: {lla[0]:.7f}°, {lla[1]:.7f}°").add_to(layer)
            bounds += _latlon(lla)
        layer.add_to(m)

    shown = {id(t): determined_estimates(t) for t in targets}  # an undetermined estimate is no point
    for method in ordered_methods(dict.fromkeys(k for t in targets for k in shown[id(t)])):
        color = METHOD_COLORS.get(method, "#000000")
        swatch = (f'<span style="display:inline-block;width:10px;height:10px;border-radius:50%;background:{color};'
                  'border:1px solid #000;margin-right:4px"></span>')
        layer = folium.FeatureGroup(name=f"{swatch}{escape(method_label(method))}", show=True)
        drawn = False
        for t in targets:
            e = shown[id(t)].get(method)
            if e is None:
                continue
            lla = geodetic_from_enu(e.position_m, t.origin_lla)
            err = e.error_m(t.truth_m)
            who = "" if t.target is None else f"{escape(t.target)}: "
            answer = " (the answer)" if answer_of(t).method == method else ""
            tip = (f"{who}{escape(method_label(method))} ({method}){answer}: {lla[0]:.7f}°, {lla[1]:.7f}°"
                   + ("" if err is None else f", error {err:.2f} m") + f", {e.status.name.lower()}")
            folium.CircleMarker(_latlon(lla)[0], radius=8 if method == "mle" else 6, color="#000000", weight=1,
                                fill=True, fill_color=color, fill_opacity=0.95, tooltip=tip).add_to(layer)
            cov = shown_covariance(t, method)
            if cov is not None and np.isfinite(cov).all():
                ring_en = ellipse_points_en_m(np.asarray(cov)[:2, :2], ELLIPSE_CONFIDENCE) + e.position_m[:2]
                ring = geodetic_from_enu(np.column_stack([ring_en, np.full(len(ring_en), e.position_m[2])]),
                                         t.origin_lla)
                folium.Polygon(_latlon(ring), color=color, weight=2, dash_array="6 4", fill=True,
                               fill_opacity=0.08,
                               tooltip=f"{who}{escape(method_label(method))}: 95 % error ellipse").add_to(layer)
            bounds += _latlon(lla)
            drawn = True
        if drawn:
            layer.add_to(m)

    named = [t for t in targets if t.target is not None]
    if named:  # a label per target, always shown, at its answer (else its first estimate shown)
        layer = folium.FeatureGroup(name="Target names", show=True)
        for t in named:
            a = answer_of(t)
            finite = [a.position_m] if a.located else [e.position_m for e in shown[id(t)].values()]
            if not finite:
                continue
            lla = geodetic_from_enu(finite[0], t.origin_lla)
            folium.CircleMarker(_latlon(lla)[0], radius=1, opacity=0, fill=False,
                                tooltip=folium.Tooltip(escape(t.target), permanent=True, direction="right",
                                                       class_name="ridgeloc-target-label")).add_to(layer)
        layer.add_to(m)

    folium.LayerControl(collapsed=False, position="topleft").add_to(m)
    b = np.array(bounds)
    # the layer control (top left, ~280 px wide) must not hide the target: leave it room
    m.fit_bounds([b.min(axis=0).tolist(), b.max(axis=0).tolist()], padding_top_left=(300, 20),
                 padding_bottom_right=(30, 30))
    return m


def _footprint_layers(m, r: GroupResult) -> None:
    """A video flight's camera footprints at a few frames and its frame-centre tracks (`footprints.py`)."""
    import folium

    from pipeline.report.footprints import flight_footprints

    fp = flight_footprints(r)
    if fp is None:
        return
    layer = folium.FeatureGroup(name="Camera footprints", show=True)
    for k, outline in enumerate(fp.outline_lla):
        frame = fp.frame_index[k]
        t_s = (r.observations.t_ns[fp.frames[k]] - r.observations.t_ns[0]) / 1e9
        folium.Polygon(_latlon(outline), color="#8E44AD", weight=2, fill=True, fill_opacity=0.05,
                       tooltip=f"camera footprint, frame {frame} (+{t_s:.1f} s), on {escape(fp.ground)}").add_to(layer)
    layer.add_to(m)
    centre = fp.centre_lla[np.isfinite(fp.centre_lla).all(axis=1)]
    if len(centre):
        layer = folium.FeatureGroup(name="Frame centre: ridgeloc", show=True)
        folium.PolyLine(_latlon(centre), color="#8E44AD", weight=3,
                        tooltip=f"ridgeloc's frame centre (the image centre's ray on {escape(fp.ground)})"
                        ).add_to(layer)
        layer.add_to(m)
    if fp.payload_deg is not None and len(fp.payload_deg):
        layer = folium.FeatureGroup(name="Frame centre: payload (KLV)", show=True)
        folium.PolyLine(_latlon(fp.payload_deg), color="#E67E22", weight=3, dash_array="8 5",
                        tooltip="the payload's own frame centre (KLV)").add_to(layer)
        layer.add_to(m)


#: answers farther apart than this (km) get maps of their own: one map of targets on two continents shows neither
SITE_KM = 50.0
ANSWER_COLOR = "#D55E00"


def _answer_lat_lon(targets: Sequence[GroupResult]) -> tuple[np.ndarray, np.ndarray]:
    """(lat, lon) (n,) deg of the targets' answers."""
    lla = [geodetic_from_enu(answer_of(t).position_m, t.origin_lla) for t in targets]
    return np.array([float(p[0]) for p in lla]), np.array([float(p[1]) for p in lla])


def _grouped(d_m: np.ndarray, radius_m: float) -> list[list[int]]:
    """Indices grouped greedily in order: each joins the first group whose first member is within radius_m
    (`d_m` (n, n) distances)."""
    groups: list[list[int]] = []
    for i in range(d_m.shape[0]):
        near = next((g for g in groups if d_m[i, g[0]] < radius_m), None)
        if near is None:
            groups.append([i])
        else:
            near.append(i)
    return groups


def answer_sites(results: Sequence[GroupResult]) -> list[list[GroupResult]]:
    """The located targets grouped by site: each joins the first site whose first target is within SITE_KM."""
    located = [t for t in results if answer_of(t).located]
    if not located:
        return []
    d_m = pairwise_geodesic_m(*_answer_lat_lon(located))
    return [[located[i] for i in g] for g in _grouped(d_m, SITE_KM * 1000.0)]


#: answers closer than this (m), or a fortieth of the map's extent, share one label on the answers map
LABEL_MERGE_M = 20.0


def shared_labels(targets: Sequence[GroupResult]) -> dict[str, str]:
    """{target label: its permanent map label} for located answers: answers closer than a fortieth of the map's
    extent (at least LABEL_MERGE_M) to an earlier one share its label, "first and N more" (each marker's own
    tooltip still names it); the others are absent from the dict. Eleven sample answers within 10 m stacked eleven
    labels on one spot."""
    if not targets:
        return {}
    d_m = pairwise_geodesic_m(*_answer_lat_lon(targets))
    radius = max(LABEL_MERGE_M, float(d_m.max()) / 40.0)
    names = [t.label for t in targets]
    return {names[g[0]]: names[g[0]] + (f" and {len(g) - 1} more" if len(g) > 1 else "")
            for g in _grouped(d_m, radius)}


def answers_map(targets: Sequence[GroupResult], tiles: bool = True):
    """A folium.Map of located targets' answers: each a marker with its name always shown, its 95 % ellipse, and
    the truth where a flight config gives it (a small black ring)."""
    import folium

    first = answer_of(targets[0])
    lat0, lon0, _ = geodetic_from_enu(first.position_m, targets[0].origin_lla)
    m = folium.Map(location=[float(lat0), float(lon0)], zoom_start=15, tiles=None, control_scale=True, max_zoom=22,
                   prefer_canvas=False)
    m.default_js, m.default_css = [], []
    if tiles:
        folium.TileLayer(OSM_TILES, attr=OSM_ATTRIBUTION, name="OpenStreetMap", max_zoom=22, max_native_zoom=19,
                         control=False).add_to(m)
    bounds = []
    labels = shared_labels(targets)
    for t in targets:
        a, row = answer_of(t), answer_row(t)
        lla = geodetic_from_enu(a.position_m, t.origin_lla)
        if a.covariance_m2 is not None and np.isfinite(a.covariance_m2).all():
            ring_en = ellipse_points_en_m(np.asarray(a.covariance_m2)[:2, :2], ELLIPSE_CONFIDENCE) + a.position_m[:2]
            ring = geodetic_from_enu(np.column_stack([ring_en, np.full(len(ring_en), a.position_m[2])]), t.origin_lla)
            folium.Polygon(_latlon(ring), color=ANSWER_COLOR, weight=2, fill=True, fill_opacity=0.12,
                           tooltip=f"{escape(t.label)}: 95 % error ellipse").add_to(m)
            bounds += _latlon(ring)
        if t.truth_m is not None:
            tl = geodetic_from_enu(t.truth_m, t.origin_lla)
            folium.CircleMarker(_latlon(tl)[0], radius=4, color="#000000", weight=2, fill=False,
                                tooltip=f"{escape(t.label)}: truth").add_to(m)
            bounds += _latlon(tl)
        ce90 = "" if row["ce90_m"] is None else f", CE90 {row['ce90_m']:.1f} m ({row['tle_category']})"
        folium.CircleMarker(_latlon(lla)[0], radius=7, color="#000000", weight=1, fill=True, fill_color=ANSWER_COLOR,
                            fill_opacity=1.0,
                            tooltip=f"<b>{escape(t.label)}</b><br>{lla[0]:.7f}°, {lla[1]:.7f}°<br>"
                                    f"{escape(row['mgrs'])}<br>{one_decimal(row['alt_msl_m'])} m MSL{ce90}<br>"
                                    f"method {escape(str(row['method']))}").add_to(m)
        label = labels.get(t.label)
        if label is not None:  # its name, always shown (one label for answers that lie on top of each other)
            folium.CircleMarker(_latlon(lla)[0], radius=1, opacity=0, fill=False,
                                tooltip=folium.Tooltip(escape(label), permanent=True, direction="right",
                                                       class_name="ridgeloc-target-label")).add_to(m)
        bounds += _latlon(lla)
    b = np.array(bounds)
    m.fit_bounds([b.min(axis=0).tolist(), b.max(axis=0).tolist()], padding_top_left=(30, 30),
                 padding_bottom_right=(120, 30), max_zoom=19)
    return m


def _fragment(m, label: str, height_px: int) -> str:
    root = m.get_root()
    root.render()
    name = m.get_name()
    return (f'<div class="webmap" data-group="{escape(label)}">'
            f"<style>#{name} {{ position: relative; width: 100%; height: {int(height_px)}px; }}</style>"
            f"{root.html.render()}</div>\n"
            f"<script>\n{root.script.render()}\n{_GRID_JS % name}</script>")


def answers_fragment(targets: Sequence[GroupResult], height_px: int = 460, tiles: bool = True) -> str:
    """The <div> and <script> of `answers_map(targets)` (see `map_fragment`)."""
    return _fragment(answers_map(targets, tiles=tiles), "answers", height_px)


def map_fragment(r: GroupResult | Sequence[GroupResult], height_px: int = 520, tiles: bool = True) -> str:
    """The <div> and <script> of `group_map(r)` for a page whose <head> has `leaflet_head()` (folium's page-wide
    header, which restyles html and body, is left out: only the map's own size is kept)."""
    m = group_map(r, tiles=tiles)
    r = r if isinstance(r, GroupResult) else r[0]
    return _fragment(m, r.name, height_px)
