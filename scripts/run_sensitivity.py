"""Run the simulation's sensitivity configs and collect their key tables into one markdown file.

    python scripts/run_sensitivity.py [CONFIG ...] [--out out/simulation] [--trials N]

Without CONFIG it runs every configs/simulation_*.yaml, the default simulation_table2.yaml first (as the
reference row of the overview). Each run's full outputs go to OUT/<name>/ (as `ridgeloc simulate CONFIG --out
OUT/<name>` would write them); OUT/sensitivity.md holds, per run, the median error, the non-converged and
degenerate shares, and the wall time. docs/simulation.md quotes these tables.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from pipeline.errors import RidgelocError
from pipeline.simulate import SimulationConfig, run_simulation, write_outputs
from pipeline.simulate.report import markdown_table, setup_lines

ROOT = Path(__file__).resolve().parent.parent
OVERVIEW_METHODS = ("vision", "range", "fusion", "ridge", "mle")
OVERVIEW_ANGLES = (10.0, 40.0, 80.0)


def _overview_row(result) -> str:
    def cell(method: str, stat: str, angle: float) -> str:
        if method not in result.rows or angle not in result.angles_deg:
            return "–"
        v = result.value(method, stat, angle)
        return "–" if v != v else (f"{v:.1f}" if v < 1e5 else f"{v:.2g}")
    cells = [cell(m, "median_m", a) for m in OVERVIEW_METHODS for a in OVERVIEW_ANGLES]
    cells += [cell("ridge", "nonconverged_pct", a) for a in (10.0, 80.0)]
    return f"| `{result.config.name}` | " + " | ".join(cells) + " |"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("configs", nargs="*", type=Path)
    parser.add_argument("--out", type=Path, default=Path("out/simulation"))
    parser.add_argument("--trials", type=int, help="override every config's trials per angle")
    args = parser.parse_args(argv)
    default = ROOT / "configs" / "simulation_table2.yaml"
    paths = args.configs or [default, *sorted(p for p in (ROOT / "configs").glob("simulation_*.yaml")
                                              if p.name != default.name)]
    sections = ["# Simulation sensitivity runs", "",
                "Produced by `python scripts/run_sensitivity.py" + (f" --trials {args.trials}" if args.trials else "")
                + "`; each section's full outputs are in the folder named after it.", ""]
    overview = ["## Overview: median 3D error (m) at 10°, 40° and 80°, and ridge non-converged (%)", "",
                "| run | " + " | ".join(f"{m} {a:g}°" for m in OVERVIEW_METHODS for a in OVERVIEW_ANGLES)
                + " | ridge n.c. 10° | ridge n.c. 80° |",
                "|---|" + "---:|" * (len(OVERVIEW_METHODS) * len(OVERVIEW_ANGLES) + 2)]
    t_all = time.perf_counter()
    for path in paths:
        try:
            cfg = SimulationConfig.load(path)
            if args.trials is not None:
                cfg = cfg.replace(trials=args.trials)
            t0 = time.perf_counter()
            result = run_simulation(cfg)
            write_outputs(result, args.out / cfg.name)
        except RidgelocError as exc:
            print(f"run_sensitivity: error: {exc}", file=sys.stderr)
            return 1
        wall = time.perf_counter() - t0
        print(f"{cfg.name}: {wall:.1f} s")
        rel = path.resolve().relative_to(ROOT) if path.resolve().is_relative_to(ROOT) else path
        sections += [f"## `{cfg.name}` ({rel})", "", cfg.description.strip(), "", *setup_lines(result), ""]
        for stat, title, paper in (("median_m", "Median 3D error (m)", True),
                                   ("rms_m", "RMS 3D error (m)", False),
                                   ("nonconverged_pct", "Not converged (%)", False),
                                   ("degenerate_pct", "Flagged degenerate (%)", False)):
            sections += [f"**{title}**", "", *markdown_table(result, stat, paper), ""]
        sections += [f"Wall time {wall:.1f} s.", ""]
        overview.append(_overview_row(result))
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "sensitivity.md").write_text("\n".join([*sections[:4], *overview, "", *sections[4:]]))
    print(f"wrote {args.out / 'sensitivity.md'} ({time.perf_counter() - t_all:.1f} s)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
