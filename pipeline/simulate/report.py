"""The experiment's outputs: table2.csv, table2.md, fig4.png, fig5.png and summary.json under one folder.

Everything is rendered in memory first and each file is written through a temporary name and renamed, so an
error never leaves a half-written output behind.
"""

from __future__ import annotations

import csv
import io
import json
import math
import os
from pathlib import Path

from pipeline.errors import InputError
from pipeline.simulate.experiment import SimulationResult
from pipeline.simulate.figures import LABELS, fig4_png, fig5_png
from pipeline.simulate.paper import PAPER_TABLE2_MEDIAN_M, paper_median_m
from pipeline.simulate.scenario import camera_matrix
from pipeline.simulate.statistics import STATISTICS

CSV_STATISTICS = tuple(STATISTICS)


def angle_label(angle_deg: float) -> str:
    return f"{angle_deg:g}"


def _csv_number(v: float | None) -> str:
    if v is None or (isinstance(v, float) and math.isnan(v)):
        return ""
    return f"{v:.6g}"


def table_csv(result: SimulationResult) -> str:
    """Columns method,statistic,<angle>...; our rows, then the paper's Table 2 medians as paper:<method>."""
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(["method", "statistic", *(angle_label(a) for a in result.angles_deg)])
    for row, table in result.rows.items():
        for stat in CSV_STATISTICS:
            w.writerow([row, stat, *(_csv_number(v) for v in table[stat])])
    for method in PAPER_TABLE2_MEDIAN_M:
        w.writerow([f"paper:{method}", "median_m",
                    *(_csv_number(paper_median_m(method, a)) for a in result.angles_deg)])
    return buf.getvalue()


def _fmt(v: float | None, stat: str) -> str:
    if v is None or math.isnan(v):
        return "–"
    if math.isinf(v):
        return "∞"
    if stat.endswith("_pct"):
        return f"{v:.1f}"
    if stat == "median_iterations":
        return f"{v:g}"
    if stat == "median_condition":
        return f"{v:.3g}"
    return f"{v:.2f}" if abs(v) < 1e5 else f"{v:.3g}"


def markdown_table(result: SimulationResult, stat: str, with_paper: bool) -> list[str]:
    head = "| method | " + " | ".join(f"{angle_label(a)}°" for a in result.angles_deg) + " |"
    lines = [head, "|---|" + "---:|" * len(result.angles_deg)]
    for row, table in result.rows.items():
        values = table[stat]
        if all(math.isnan(v) for v in values):
            continue
        lines.append(f"| {row} | " + " | ".join(_fmt(v, stat) for v in values) + " |")
        if with_paper and row in PAPER_TABLE2_MEDIAN_M:
            lines.append(f"| *paper:{row}* | " + " | ".join(
                f"*{_fmt(paper_median_m(row, a), stat)}*" for a in result.angles_deg) + " |")
    return lines


def mle_ratio_lines(result: SimulationResult) -> list[str]:
    """The weighted MLE's median error over the paper's ridge-fusion figure, per angle (issue 3 asks <= 0.45)."""
    if "mle" not in result.rows:
        return []
    cells = []
    for a, v in zip(result.angles_deg, result.rows["mle"]["median_m"], strict=True):
        paper = paper_median_m("ridge", a)
        cells.append("–" if paper is None or math.isnan(v) else f"{v / paper:.3f}")
    return ["", "Weighted MLE median ÷ the paper's ridge-fusion median: "
            + ", ".join(f"{angle_label(a)}° {c}" for a, c in zip(result.angles_deg, cells, strict=True)) + "."]


def setup_lines(result: SimulationResult) -> list[str]:
    cfg = result.config
    g, c, nz, s = cfg.geometry, cfg.camera, cfg.noise, cfg.solver
    K = camera_matrix(c)
    measured = ", ".join(f"{a:.4f}" for a in result.measured_angles_deg)
    return [
        f"- geometry: {g.path} path, {g.n_observations} observations, height {g.height_m:g} m, slant distance "
        f"{g.slant_distance_m:g} m (observation angle {result.observation_angle_deg:.2f}°); target at the origin",
        f"- camera: {c.image_width_px}x{c.image_height_px} px, f = {c.focal_length_px:g} px, principal point "
        f"({K[0, 2]:g}, {K[1, 2]:g}), pointing jitter {c.pointing_jitter_deg:g}°",
        f"- noise (1 sigma): platform position {nz.platform_position_m:g} m per axis, laser range {nz.range_m:g} m, "
        f"attitude {nz.attitude_deg:g}° per axis ({nz.attitude_model}), pixel {nz.pixel_px:g} px",
        f"- solver: tol {s.tol_m:g} m, at most {s.max_iterations} iterations, ridge HKB '{s.ridge_hkb}', "
        f"MLE sigma {s.mle_sigma}, MLE loss {s.mle_robust}",
        f"- {cfg.trials} trials per angle, seed {cfg.seed}; measured intersection angles (deg): {measured}",
    ]


def table_markdown(result: SimulationResult) -> str:
    cfg = result.config
    out = [f"# Simulation `{cfg.name}`", ""]
    if cfg.description:
        out += [cfg.description.strip(), ""]
    out += setup_lines(result)
    sections = [
        ("median_m", "Median 3D error (m), the paper's Table 2 beside ours (*italic*)", True),
        ("rms_m", "RMS 3D error (m) (cf. paper Fig. 5; the paper gives no numbers)", False),
        ("p90_m", "90th percentile of the 3D error (m)", False),
        ("nonconverged_pct", "Trials not converged (%): iteration limit, diverged or degenerate", False),
        ("degenerate_pct", "Trials flagged degenerate (%): the geometry does not determine the target", False),
        ("failed_pct", "Trials without an answer (%): degenerate, diverged or non-finite; left out of the errors",
         False),
        ("median_iterations", "Median iteration count", False),
        ("median_condition", "Median condition number of the final design matrix", False),
    ]
    for stat, title, paper in sections:
        out += ["", f"## {title}", "", *markdown_table(result, stat, paper)]
        if stat == "median_m":
            out += mle_ratio_lines(result)
    out += ["", "## Run time", "", "| method | total s | ms per batch of one angle | µs per problem |",
            "|---|---:|---:|---:|"]
    for m, sec in result.method_seconds.items():
        per_batch_ms = 1e3 * sec / len(result.angles_deg)
        out.append(f"| {m} | {sec:.3f} | {per_batch_ms:.1f} | {1e6 * sec / result.solves():.1f} |")
    out += ["", f"Trial generation {result.generation_seconds:.3f} s; whole experiment {result.wall_seconds:.2f} s "
            "wall time.", "", "Row names: " + "; ".join(f"`{k}` {v}" for k, v in LABELS.items() if k in result.rows)
            + ". Statistics: " + "; ".join(f"`{k}` {v}" for k, v in STATISTICS.items()) + "."]
    return "\n".join(out) + "\n"


def _json_number(v: float):
    return None if math.isnan(v) or math.isinf(v) else v


def summary_json(result: SimulationResult) -> str:
    doc = {
        "config": result.config.to_dict(),
        "observation_angle_deg": result.observation_angle_deg,
        "angles_deg": list(result.angles_deg),
        "measured_angles_deg": result.measured_angles_deg,
        "rows": {r: {s: [_json_number(v) for v in vals] for s, vals in t.items()} for r, t in result.rows.items()},
        "method_seconds": result.method_seconds,
        "generation_seconds": result.generation_seconds,
        "wall_seconds": result.wall_seconds,
    }
    return json.dumps(doc, indent=1)


def write_outputs(result: SimulationResult, out_dir: str | os.PathLike) -> list[Path]:
    """Write every output file into out_dir (created if needed); returns the paths written."""
    out = Path(out_dir)
    files: dict[str, bytes] = {
        "table2.csv": table_csv(result).encode(),
        "table2.md": table_markdown(result).encode(),
        "fig4.png": fig4_png(result),
        "fig5.png": fig5_png(result),
        "summary.json": summary_json(result).encode(),
    }
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise InputError(f"cannot create the output folder: {exc.strerror}", out) from None
    written = []
    for name, data in files.items():
        path = out / name
        tmp = out / f".{name}.tmp"
        try:
            tmp.write_bytes(data)
            os.replace(tmp, path)
        except OSError as exc:
            tmp.unlink(missing_ok=True)
            raise InputError(f"cannot write {name}: {exc.strerror}", out) from None
        written.append(path)
    return written
