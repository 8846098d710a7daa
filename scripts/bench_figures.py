#!/usr/bin/env python
"""CPU cost of the per-group figures (pipeline/report/figures.py), this code and another side by side.

    python scripts/bench_figures.py OUT [--groups group3 three_targets fmv] [--repeat 5] [--against DIR]
                                        [--save DIR]

OUT is a finished `ridgeloc run` output folder (e.g. `python -m pipeline run -q -o OUT`); each group's result is
read back (pipeline.report.outputs.load_finished_group) and split per target (pipeline.results.per_target). Each
figure (map, view3d, residuals) of each (group, target) is built and encoded as PNG (`figure_png`), `--repeat`
times after one warm-up render, in a child process per code (this worktree's, and with --against DIR that
checkout's, e.g. main's, read-only), the children alternating, each code's figures made as its
render_group_figures makes them (reused figures where the code has them); printed: the median process CPU time
per figure and per (group, target) (the three figures), and the ratio of this code to the other. --save DIR writes this
code's PNGs (and the other's under DIR/against) to look at them.
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
FIGURES = ("map", "view3d", "residuals")


def child(out: str, groups: list[str], repeat: int, save: str | None) -> None:
    """Time every figure of every (group, target) in this process (its code is the first on sys.path)."""
    import functools
    import inspect
    import time

    from pipeline.report import figures as F
    from pipeline.report.outputs import load_finished_group
    from pipeline.results import per_target

    makers = {"map": F.map_figure, "view3d": F.view3d_figure, "residuals": F.residuals_figure}
    if "reuse" in inspect.signature(F.map_figure).parameters:  # as render_group_figures makes them
        makers = {k: functools.partial(f, reuse=True) for k, f in makers.items()}
    rows = {}
    for g in groups:
        r = load_finished_group(out, g)
        if r is None:
            raise SystemExit(f"{out}/{g}: not a finished group folder")
        for t in per_target([r]):
            label = g if t.target is None else f"{g}/{t.target}"
            F.figure_png(makers["map"](t))  # warm-up: font cache, first-use imports
            rows[label] = {}
            for name, make in makers.items():
                cpu = []
                for _ in range(repeat):
                    c0 = time.process_time()
                    png = F.figure_png(make(t))
                    cpu.append(time.process_time() - c0)
                rows[label][name] = cpu
                if save:
                    p = Path(save) / label / f"{name}.png"
                    p.parent.mkdir(parents=True, exist_ok=True)
                    p.write_bytes(png)
    print(json.dumps(rows))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("out", help="a finished ridgeloc run output folder")
    ap.add_argument("--groups", nargs="+", default=["group3", "three_targets", "fmv"])
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--rounds", type=int, default=2, help="alternating child processes per code")
    ap.add_argument("--against", default=None, metavar="DIR", help="another checkout (e.g. /work/main)")
    ap.add_argument("--save", default=None, metavar="DIR", help="write the PNGs there")
    ap.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.child:
        child(args.out, args.groups, args.repeat, args.save)
        return 0
    trees = [("this code", ROOT, args.save)]
    if args.against:
        trees.append((f"against {args.against}", Path(args.against).resolve(),
                      str(Path(args.save) / "against") if args.save else None))
    runs: dict[str, dict[str, dict[str, list[float]]]] = {label: {} for label, _, _ in trees}
    out = str(Path(args.out).resolve())
    for _ in range(max(1, args.rounds)):
        for label, root, save in trees:
            cmd = [sys.executable, str(ROOT / "scripts" / "bench_figures.py"), out, "--child", "--repeat",
                   str(args.repeat), "--groups", *args.groups] + (["--save", str(Path(save).resolve())] if save else [])
            res = subprocess.run(cmd, cwd=root, capture_output=True, text=True, check=True,
                                 env={**__import__("os").environ, "PYTHONPATH": str(root)})
            for g, figs in json.loads(res.stdout.strip().splitlines()[-1]).items():
                for name, cpu in figs.items():
                    runs[label].setdefault(g, {}).setdefault(name, []).extend(cpu)
    med = {label: {g: {k: statistics.median(v) for k, v in figs.items()} for g, figs in rs.items()}
           for label, rs in runs.items()}
    print(f"median process CPU s per figure (build + PNG), {args.rounds} x {args.repeat} renders each")
    print(f"{'group/target':<28} {'code':<22} " + " ".join(f"{f:>9}" for f in FIGURES) + f" {'total':>9}")
    for g in med[trees[0][0]]:
        for label, _, _ in trees:
            m = med[label][g]
            print(f"{g:<28} {label[:22]:<22} " + " ".join(f"{m[f]:>9.3f}" for f in FIGURES)
                  + f" {sum(m.values()):>9.3f}")
    if args.against:
        a, b = (med[label] for label, _, _ in trees)
        per_fig = {f: statistics.median(b[g][f] / a[g][f] for g in a) for f in FIGURES}
        tot = [sum(b[g].values()) / sum(a[g].values()) for g in a]
        print("speed-up (other / this code), median over the groups: "
              + ", ".join(f"{f} {v:.2f}x" for f, v in per_fig.items())
              + f", per group {statistics.median(tot):.2f}x (range {min(tot):.2f}x to {max(tot):.2f}x)")
        per_group = [statistics.median(sum(v.values()) for v in m.values()) for m in (a, b)]
        print(f"CPU per group and target, median: this code {per_group[0]:.3f} s, other {per_group[1]:.3f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
