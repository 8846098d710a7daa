"""The run report: one self-contained HTML page (figures as base64 PNG data URIs, inline CSS; the only scripts are
Leaflet, inline, and each group's interactive map: nothing is loaded from the network but the basemap's tiles).

Sections: a Table-4-like summary (error per method and group, the best per group highlighted, with the
intersection angle and observation count of Table 3), the failures, one section per group (figures,
estimates table, stage timings, settings) and the run's settings and software versions.
"""

from __future__ import annotations

import base64
import datetime as _dt
import json
import os
from collections.abc import Mapping, Sequence
from html import escape
from os import PathLike
from urllib.parse import quote

import numpy as np

from pipeline.atomic import atomic_write_text
from pipeline.report.answers import answer_of, answer_rows
from pipeline.report.exports import ALT_MSL_DATUM, estimate_rows, failure_status_reason
from pipeline.report.geometry import ALT_DATUM
from pipeline.report.labels import METHOD_COLORS, count, method_label, ordered_methods
from pipeline.report.versions import software_versions
from pipeline.results import FlightResult, GroupFailure, GroupResult, per_target, target_failures

_CSS = """
body { font-family: -apple-system, "Segoe UI", Roboto, "Helvetica Neue", Arial, sans-serif; margin: 0;
       color: #1d1d1f; background: #fafafa; line-height: 1.45; }
main { max-width: 1340px; margin: 0 auto; padding: 24px 28px 60px; }
h1 { font-size: 26px; margin: 8px 0 4px; }
h2 { font-size: 21px; margin: 34px 0 10px; padding-top: 10px; border-top: 2px solid #ddd; }
h3 { font-size: 16px; margin: 20px 0 8px; }
.meta { color: #555; font-size: 14px; }
.pill { display: inline-block; padding: 2px 10px; border-radius: 12px; font-size: 13px; margin-right: 6px; }
.ok { background: #e3f4ea; color: #1e6b3a; } .bad { background: #fde8e8; color: #9b1c1c; }
table { border-collapse: collapse; margin: 8px 0 14px; font-size: 14px; background: white; }
th, td { border: 1px solid #d9d9d9; padding: 4px 8px; text-align: right; white-space: nowrap; }
.scroll { overflow-x: auto; max-width: 100%; }
th { background: #f0f0f3; font-weight: 600; }
td.l, th.l { text-align: left; }
td.best { background: #d9f2e1; font-weight: 700; }
td.na { color: #999; }
td.wrap, th.wrap { white-space: normal; min-width: 220px; max-width: 420px; text-align: left; font-size: 12px; }
table.answers { font-size: 13px; }
table.compare { font-size: 12px; } table.compare td, table.compare th { padding: 3px 5px; }
.paper { color: #8a8a8a; font-size: 11px; font-weight: 400; }
.swatch { display: inline-block; width: 11px; height: 11px; border-radius: 2px; margin-right: 6px;
          vertical-align: -1px; border: 1px solid #0003; }
figure img { max-width: 100%; height: auto; background: white; border: 1px solid #e2e2e2; border-radius: 4px; }
.webmap { border: 1px solid #d0d0d0; border-radius: 4px; overflow: hidden; margin: 4px 0 6px; }
.row { display: flex; gap: 14px; flex-wrap: wrap; align-items: flex-start; }
.row > figure { flex: 1 1 480px; margin: 0; }
figure { margin: 0 0 12px; }
figcaption { font-size: 13px; color: #555; margin-top: 2px; }
pre { background: #f4f4f6; padding: 10px; overflow-x: auto; font-size: 12px; border-radius: 4px; }
.fail td { color: #9b1c1c; }
.note { font-size: 13px; color: #555; }
details summary { cursor: pointer; color: #0b57d0; margin: 6px 0; }
"""


def _fmt(x, decimals: int = 2) -> str:
    if x is None or (isinstance(x, float) and not np.isfinite(x)):
        return "—"
    if isinstance(x, float):
        return f"{x:,.{decimals}f}"
    return escape(str(x))


def _img(png: bytes, alt: str) -> str:
    data = base64.b64encode(png).decode("ascii")
    return f'<img src="data:image/png;base64,{data}" alt="{escape(alt)}">'


def _paper(group: str, table: dict, key: str, decimals: int = 2) -> str:
    """The paper's value for a group of the same name (group1..group6), as a grey second line."""
    from pipeline.report.table4 import PAPER_GROUPS

    if group not in PAPER_GROUPS or key not in table:
        return ""
    v = table[key][PAPER_GROUPS.index(group)]
    return f'<div class="paper">paper {_fmt(float(v), decimals) if decimals else v}</div>'


def _answers_table(rows: list[dict], results: Sequence[GroupResult]) -> str:
    """The answers: one row per target (targets.csv's), the reason wrapped in the last column."""
    truth = any(r.truth_m is not None for r in results)
    cols = [("Target", "name", "l"), ("Latitude /°", "lat_deg", ""), ("Longitude /°", "lon_deg", ""),
            ("Height MSL /m", "alt_msl_m", ""), ("MGRS", "mgrs", "l"), ("CE90 /m", "ce90_m", ""),
            ("LE90 /m", "le90_m", ""), ("Category", "tle_category", "l"), ("Method", "method", "l"),
            ("Obs.", "n_observations", ""), *((("Error /m", "error_m", ""),) if truth else ()),
            ("Why", "reason", "l wrap")]
    head = "".join(f'<th class="{c}">{escape(t)}</th>' for t, _, c in cols)
    body = []
    for row in rows:
        if row["status"] != "located":
            body.append(f'<tr class="fail"><td class="l">{escape(row["name"])}</td><td class="l" '
                        f'colspan="{len(cols) - 2}">not located</td><td class="l wrap">'
                        f'{escape(str(row["reason"]))}</td></tr>')
            continue
        cells = []
        for _, key, c in cols:
            v = row[key]
            cells.append(f'<td class="{c}">{_fmt(v, 7) if key in ("lat_deg", "lon_deg") else _fmt(v, 1)}</td>')
        body.append("<tr>" + "".join(cells) + "</tr>")
    return f'<table class="answers"><tr>{head}</tr>{"".join(body)}</table>'


def _answers_section(results: Sequence[GroupResult], rows: list[dict], interactive: bool) -> str:
    """The report's top: the answers on a map (a map per site) and in a table."""
    parts = ["<h2 id=\"answers\">Answers: one per target</h2>"]
    if interactive:
        from pipeline.report.webmap import answer_sites, answers_fragment

        sites = answer_sites(results)
        for site in sites:
            where = "" if len(sites) == 1 else f"<h3>{escape(', '.join(t.label for t in site))}</h3>"
            parts.append(where + answers_fragment(site))
    parts.append(_answers_table(rows, results))
    parts.append('<p class="note">Each answer is chosen by one rule from what the flight shows (docs/outputs.md, '
                 '"The answer"): the weighted MLE when the flight determines it and its fit checks pass, else the '
                 "most precise simpler method the flight determines; a target no method locates is not located, and "
                 "why. "
                 "CE90: the circle around the answer holding 90 % of the horizontal error; LE90: 90 % of the "
                 "height's; category: target location error category (JP 3-09.3) of CE90. Heights above mean sea "
                 "level (EGM2008); targets.csv also gives WGS84 ellipsoidal heights. The shaded ellipse on the map "
                 "holds the answer with 95 % probability.</p>")
    return "\n".join(parts)


def _summary_table(results: Sequence[GroupResult]) -> str:
    """The paper's Table 4, a row per target and a column per method (so it fits a page whatever the number of
    targets): the 3D error of each method's estimate, with the paper's value for a group of the same name."""
    from pipeline.report.table4 import PAPER_TABLE3, PAPER_TABLE4_M

    methods = ordered_methods(dict.fromkeys(m for r in results
                                            for m in (*r.estimates, *(r.settings.get("solve_failures") or {}))))
    head = "".join(f'<th><span class="swatch" style="background:{METHOD_COLORS.get(m, "#000")}"></span>'
                   f'{escape(m)}</th>' for m in methods)
    rows = [f'<tr><th class="l">Target</th><th>Angle /°</th><th>Obs.</th>{head}</tr>']
    for r in results:
        errors = r.errors_m()
        verdicts = answer_of(r).verdicts
        finite = {m: e for m, e in errors.items() if e is not None and np.isfinite(e)}
        best = min(finite, key=finite.get) if finite else None
        failures = r.settings.get("solve_failures") or {}
        cells = [f'<td class="l"><a href="#group-{escape(r.label)}">{escape(r.label)}</a></td>',
                 f"<td>{_fmt(float(r.intersection_angle_deg))}{_paper(r.name, PAPER_TABLE3, 'intersection_angle_deg')}"
                 "</td>",
                 f"<td>{r.n_observations}{_paper(r.name, PAPER_TABLE3, 'observations', 0)}</td>"]
        for m in methods:
            if m not in r.estimates:
                if m not in failures:  # a method this flight does not have (dem without a DEM, dji on video)
                    cells.append('<td class="na" title="does not apply to this flight">n/a</td>')
                    continue
                status, why = failure_status_reason(failures[m])
                cells.append(f'<td class="na" title="{escape(why)}">{escape(status.replace("_", " "))}</td>')
                continue
            e = errors[m]
            if r.truth_m is None:
                cells.append('<td class="na">no truth</td>')
            elif e is None:
                cells.append(f'<td class="na">{escape(r.estimates[m].status.name.lower())}</td>')
            else:
                flag = "" if r.estimates[m].converged else " †"
                misfit = _misfit(r.estimates[m])
                if misfit:
                    flag += " ‡"
                v = verdicts.get(m)
                title = misfit or ""
                if v is not None and not v.determined:
                    flag += " §"
                    title = f"not determined: {v.reason}"
                cls = ' class="best"' if best == m else ""
                title = f' title="{escape(title)}"' if title else ""
                cells.append(f"<td{cls}{title}>{_fmt(e)}{flag}{_paper(r.name, PAPER_TABLE4_M, m)}</td>")
        rows.append("<tr>" + "".join(cells) + "</tr>")
    legend = " ".join(f"<b>{escape(m)}</b>: {escape(method_label(m))}." for m in methods)
    return ('<table class="compare">' + "".join(rows) + "</table>"
            '<p class="note">3D localization error against the known target position (m); the lowest per target '
            "is highlighted. † the estimator stopped without converging (iteration limit or divergence). ‡ its error "
            "model does not fit the flight (the group's notes say how): its covariance was inflated and its ellipse "
            "is less reliable. § the flight does not determine this estimate (hover for why): it is no answer and no "
            "exported point. n/a: the method does not apply to the flight (dem needs a terrain model, dji a DJI "
            "photo's own laser target). In grey, the paper's value for the group of the same name (its Tables 3 "
            f"and 4), where there is one. {legend}</p>")


def _misfit(e) -> str | None:
    """The mle's fit message when its error model does not fit the flight, else None."""
    fit = e.extras.get("fit") if isinstance(e.extras, dict) else None
    return fit.get("message") if isinstance(fit, dict) and not fit.get("consistent", True) else None


def _estimates_table(r: GroupResult) -> str:
    """Every method's estimate of one target (estimates.csv's rows): the answer marked, an undetermined one without
    coordinates, the status, and why in the last column."""
    cols = (("Method", "method_label", "l"), ("Latitude /°", "lat_deg", ""), ("Longitude /°", "lon_deg", ""),
            ("Height /m", "alt_m", ""), ("Height MSL /m", "alt_msl_m", ""), ("Error /m", "error_m", ""),
            ("CE90 /m", "cep90_m", ""), ("σ up /m", "sigma_up_m", ""), ("Status", "status", "l"),
            ("Why", "reason", "l wrap"))
    head = "".join(f'<th class="{c}">{escape(t)}</th>' for t, _, c in cols)
    body = []
    for row in estimate_rows([r]):
        cells = []
        for _, key, c in cols:
            v = row[key]
            text = _fmt(v, 7) if key in ("lat_deg", "lon_deg") else _fmt(v)
            if key == "method_label" and row["answer"]:
                text = f"<b>{text}</b> (the answer)"
            if key == "status" and row["method"] in r.estimates and _misfit(r.estimates[row["method"]]):
                text += " ‡"
            cells.append(f'<td class="{c}">{text}</td>')
        body.append("<tr>" + "".join(cells) + "</tr>")
    return (f"<table style=\"font-size: 13px\"><tr>{head}</tr>{''.join(body)}</table>"
            f'<p class="note">Height: {escape(ALT_DATUM)}; height MSL: {escape(ALT_MSL_DATUM)}. CE90 and σ up from '
            "each method's covariance: the MLE's own, the others' propagated through the method under the flight's "
            "stated errors (estimates.csv's covariance_source). ‡ the MLE's error model does not fit the flight. "
            "E, N, U in the local frame at "
            f"{_fmt(r.origin_lla[0], 7)}°, {_fmt(r.origin_lla[1], 7)}°, {_fmt(r.origin_lla[2])} m: estimates.csv."
            "</p>")


def _kv_table(d: Mapping, decimals: int = 2) -> str:
    rows = "".join(f'<tr><td class="l">{escape(str(k))}</td><td class="l">{_fmt(v, decimals)}</td></tr>'
                   for k, v in d.items())
    return f"<table>{rows}</table>"


def relative_paths(settings: Mapping) -> dict:
    """A flight's settings with every absolute path shown relative to its config file's folder (and the config
    as its file name), so a report does not show the folders of the machine that ran it."""
    config = settings.get("path")
    base = os.path.dirname(config) if isinstance(config, str) and os.path.isabs(config) else None

    def rel(v):
        if isinstance(v, dict):
            return {k: rel(x) for k, x in v.items()}
        if isinstance(v, list):
            return [rel(x) for x in v]
        if isinstance(v, str) and base is not None and os.path.isabs(v):
            try:
                return os.path.relpath(v, base)
            except ValueError:  # another drive (Windows)
                return os.path.basename(v)
        return v

    out = rel(dict(settings))
    if base is not None:
        out["path"] = os.path.basename(config)
    return out


def _group_section(r: GroupResult, figures: Mapping[str, bytes], interactive: bool = True,
                   flight_map: list[GroupResult] | None = None) -> str:
    """A group's section, or a named target's (`flight_map`: its flight's targets, for the one map of them all
    shown in the flight's first target's section; [] for the others)."""
    parts = [f'<h2 id="group-{escape(r.label)}">{escape(r.label)}</h2>']
    angle = _fmt(float(r.intersection_angle_deg))
    parts.append(f'<p class="meta">{count(r.n_observations, "observation")}, intersection angle {angle}°'
                 + ("" if r.truth_m is not None else ", target truth unknown") + "</p>")
    if interactive and flight_map != []:
        from pipeline.report.webmap import map_fragment

        which = "" if not flight_map else f" (every target of {escape(r.name)})"
        parts.append(f"<h3>Interactive map{which}</h3>" + map_fragment(flight_map or r)
                     + '<p class="note">Zoom and pan; tick a layer to show or hide a method. Basemap: OpenStreetMap '
                     "when online, a plain grid when not (everything else is in this file).</p>")
    overlay = r.settings.get("overlay")
    if isinstance(overlay, dict) and overlay.get("file") and flight_map != []:  # once per flight
        src = f"{quote(r.name)}/{quote(overlay['file'])}"
        parts.append(f"<h3>What was tracked{' (every target)' if flight_map else ''}</h3>"
                     f'<video class="overlay" controls preload="metadata" src="{escape(src)}" '
                     f'width="{int(overlay.get("width", 960))}" style="max-width:100%"></video>'
                     f'<p class="note">{escape(src)}: the {int(overlay.get("frames", 0))} observation frames, '
                     "each held 0.5 s: the tracked pixel in a reticle (a red cross where the target was lost), the "
                     "answer projected back with its 95 % ellipse (orange), the laser's spot (red dot) and a "
                     "caption with the time and range.</p>")
    if "map" in figures:
        parts.append(f"<figure>{_img(figures['map'], f'{r.name} map view')}<figcaption>Plan view: flight path, "
                     "lines of sight, each method's estimate and the truth; right, a close-up around the target "
                     "with the 95 % horizontal error ellipse.</figcaption></figure>")
    pair = [(k, cap) for k, cap in (("view3d", "3D view (East, North, Up)."),
                                    ("residuals", "Residuals per frame of the main estimates.")) if k in figures]
    if pair:
        parts.append('<div class="row">' + "".join(
            f"<figure>{_img(figures[k], f'{r.name} {k}')}<figcaption>{cap}</figcaption></figure>" for k, cap in pair)
            + "</div>")
    parts.append("<h3>Estimates</h3>" + _estimates_table(r))
    failed = r.settings.get("solve_failures") or {}
    if isinstance(failed, dict) and failed:
        parts.append('<p class="note">Estimators that gave no answer: ' + "; ".join(
            "<b>{}</b> ({}): {}".format(escape(method_label(m)), *map(escape, failure_status_reason(msg)))
            for m, msg in failed.items()) + "</p>")
    notes = r.settings.get("notes") or []
    if isinstance(notes, list) and notes:
        parts.append("<h3>Notes</h3><ul class=\"note\">" + "".join(f"<li>{escape(str(n))}</li>" for n in notes)
                     + "</ul>")
    if r.timings_s:
        parts.append("<h3>Stage timings</h3>" + _kv_table({f"{k} /s": float(v) for k, v in r.timings_s.items()}, 3))
    if r.settings:
        parts.append("<details><summary>Flight settings</summary><pre>"
                     + escape(json.dumps(relative_paths(r.settings), indent=2, default=str)) + "</pre></details>")
    return "\n".join(parts)


def _traceback(f: GroupFailure) -> str:
    detail = getattr(f, "detail", "")
    if not detail:
        return ""
    return ("<details><summary>traceback (a bug in ridgeloc: please report it)</summary>"
            f"<pre>{escape(detail)}</pre></details>")


def report_html(results: Sequence[GroupResult], failures: Sequence[GroupFailure], settings: Mapping,
                figures: Mapping[str, Mapping[str, bytes]] | None = None, title: str = "ridgeloc run report",
                interactive: bool = True) -> str:
    """The report page as a string. `figures`: group name -> {"map"|"view3d"|"residuals": PNG bytes}; groups
    missing from it are rendered here. `interactive`: a Leaflet map per group (webmap.py; Leaflet inline)."""
    from pipeline.report.figures import render_group_figures  # matplotlib only when a page is made

    n_groups = len(results)
    all_results = list(results)
    not_located = target_failures(results)
    by_flight = {r.name: r.targets for r in results if isinstance(r, FlightResult)}
    results = per_target(results)  # a section and a column per target of a flight with named targets
    figures = dict(figures or {})
    for r in results:
        if r.label not in figures:
            figures[r.label] = render_group_figures(r)
    now = _dt.datetime.now(_dt.timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
    status = (f'<span class="pill ok">{n_groups} group(s) processed</span>'
              + (f'<span class="pill bad">{len(failures)} failed</span>' if failures else ""))
    out = [f"<!DOCTYPE html><html lang=\"en\"><head><meta charset=\"utf-8\"><title>{escape(title)}</title>"
           f"<meta name=\"viewport\" content=\"width=device-width, initial-scale=1\"><style>{_CSS}</style>"
           + (_leaflet_head() if interactive and results else "") + "</head>"
           f"<body><main><h1>{escape(title)}</h1><p class=\"meta\">Generated {now}. {status}</p>"]
    if results:
        out.append(_answers_section(results, answer_rows(all_results, failures), interactive))
    if failures:
        rows = "".join(f'<tr><td class="l">{escape(f.name)}</td><td class="l">{escape(f.source)}</td>'
                       f'<td class="l">{escape(f.message)}{_traceback(f)}</td></tr>' for f in failures)
        out.append(f"<h2>Failed groups ({len(failures)})</h2><p class=\"note\">These groups were skipped; the other "
                   'groups are complete.</p><table class="fail"><tr><th class="l">Group</th><th class="l">Source</th>'
                   f'<th class="l">Error</th></tr>{rows}</table>')
    if not_located:
        rows = "".join(f'<tr><td class="l">{escape(n)}</td><td class="l">{escape(f.target)}</td>'
                       f'<td class="l">{escape(f.message)}</td></tr>' for n, f in not_located)
        out.append(f"<h2>Targets not located ({len(not_located)})</h2><p class=\"note\">The other targets of "
                   'these flights are complete.</p><table class="fail"><tr><th class="l">Group</th>'
                   f'<th class="l">Target</th><th class="l">Reason</th></tr>{rows}</table>')
    if results:
        out.append("<h2 id=\"comparison\">Comparison of methods (the paper's Table 4)</h2>" + _summary_table(results))
        nav = " · ".join(f'<a href="#group-{escape(r.label)}">{escape(r.label)}</a>' for r in results)
        out.append(f'<p class="meta">Each flight in detail: {nav}</p>')
    for r in results:
        flight = by_flight.get(r.name)
        fm = None if flight is None else (flight if r is flight[0] else [])
        out.append(_group_section(r, figures[r.label], interactive, fm))
    out.append("<h2>Run settings</h2><pre>" + escape(json.dumps(dict(settings), indent=2, default=str)) + "</pre>")
    out.append("<h2>Software</h2>" + _kv_table(software_versions()))
    out.append("</main></body></html>\n")
    return "\n".join(out)


def _leaflet_head() -> str:
    from pipeline.report.webmap import leaflet_head

    return leaflet_head()


def write_report_html(path: str | PathLike, results: Sequence[GroupResult], failures: Sequence[GroupFailure],
                      settings: Mapping, figures: Mapping[str, Mapping[str, bytes]] | None = None) -> None:
    """Write the self-contained report page (atomically); see `report_html`."""
    atomic_write_text(path, report_html(results, failures, settings, figures))
