#!/usr/bin/env python
"""Two runs of the zoo side by side, flight by flight: the before / after figures of docs/validation.md.

    OPENBLAS_NUM_THREADS=1 PYTHONPATH=. python scripts/zoo.py --seed 0,2,4,6 --json A0.json    # at the old commit
    OPENBLAS_NUM_THREADS=1 PYTHONPATH=. python scripts/zoo.py --seed 0,2,4,6 --json B0.json    # at the new one
    python scripts/zoo_compare.py A0.json A1.json --after B0.json B1.json [--blocks 8] [--moved 2.0]

Each file is the `--json` output of `scripts/zoo.py` or `scripts/zoo_unseen.py` (several files per side are
pooled; flights are matched by name). Printed: per block of --blocks seeds and over all, catastrophes (before /
after), median mle error, 95 % ellipsoid coverage (e^T C^-1 e <= chi2_3(0.95)) and the flights whose mle error moved
by more than 1 cm (how many came closer, the sum of the changes); the same per family; the catastrophes that went
and came; mle's wall time per flight (median and sum); every flight that moved by more than --moved metres.
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys

from pipeline.solve.uncertainty import CHI2_3_95


def _load(paths: list[str]) -> dict[str, dict]:
    rows: dict[str, dict] = {}
    for p in paths:
        for r in json.load(open(p))["flights"]:
            rows[r["name"]] = r
    return rows


def _seed(name: str) -> int:
    """The seed of a flight name ("s12/z034"; seed 0's flights may have no prefix)."""
    return int(name.split("/")[0][1:]) if "/" in name and name.startswith("s") else 0


def _mle(r: dict) -> float | None:
    return r["errors_m"].get("mle")


def _line(label: str, names: list[str], a: dict, b: dict) -> str:
    def stats(d: dict) -> tuple:
        rs = [d[k] for k in names]
        errors = [e for e in map(_mle, rs) if e is not None]
        inside = sum(r["mle_nees"] is not None and r["mle_nees"] <= CHI2_3_95 for r in rs) / len(rs)
        return sum(bool(r["catastrophe"]) for r in rs), statistics.median(errors) if errors else float("nan"), inside
    (ca, ma, va), (cb, mb, vb) = stats(a), stats(b)
    moved = [_mle(b[k]) - _mle(a[k]) for k in names if _mle(a[k]) is not None and _mle(b[k]) is not None
             and abs(_mle(b[k]) - _mle(a[k])) > 0.01]
    return (f"| {label} | {len(names):,} | {ca} / {cb} | {ma:.2f} / {mb:.2f} m | {100 * va:.1f} % / {100 * vb:.1f} % "
            f"| {len(moved)}, {sum(m < 0 for m in moved)} closer, sum {sum(moved):+.0f} m |")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("before", nargs="+", help="zoo --json files of the run before")
    ap.add_argument("--after", nargs="+", required=True, help="zoo --json files of the run after")
    ap.add_argument("--blocks", type=int, default=8, help="seeds per row of the first table")
    ap.add_argument("--moved", type=float, default=2.0, help="list the flights that moved by more (m)")
    args = ap.parse_args(argv)
    a, b = _load(args.before), _load(args.after)
    names = sorted(set(a) & set(b))
    if not names:
        print("zoo_compare: the two runs share no flight", file=sys.stderr)
        return 1
    header = "| {} | flights | catastrophes | median mle | coverage | moved by > 1 cm |\n|---|---|---|---|---|---|"
    print(header.format("seeds"))
    seeds = sorted({_seed(k) for k in names})
    for lo in range(seeds[0] - seeds[0] % args.blocks, seeds[-1] + 1, args.blocks):
        block = [k for k in names if lo <= _seed(k) < lo + args.blocks]
        if block:
            print(_line(f"{lo}-{lo + args.blocks - 1}", block, a, b))
    print(_line("all", names, a, b))
    print("\n" + header.format("family"))
    for fam in sorted({a[k]["family"] for k in names}):
        print(_line(fam, [k for k in names if a[k]["family"] == fam], a, b))
    gone = [k for k in names if a[k]["catastrophe"] and not b[k]["catastrophe"]]
    new = [k for k in names if b[k]["catastrophe"] and not a[k]["catastrophe"]]
    print(f"\ncatastrophes gone: {' '.join(gone) or '-'}\ncatastrophes new: {' '.join(new) or '-'}")
    walls = [[d[k]["mle_wall_s"] for k in names if d[k].get("mle_wall_s") is not None] for d in (a, b)]
    if all(walls):  # the machine's load moves these: compare runs made alike (processes per core)
        print(f"mle wall time per flight: median {statistics.median(walls[0]):.3f} -> "
              f"{statistics.median(walls[1]):.3f} s, sum {sum(walls[0]):,.0f} -> {sum(walls[1]):,.0f} s")
    moved = sorted((_mle(b[k]) - _mle(a[k]), k) for k in names if _mle(a[k]) is not None and _mle(b[k]) is not None
                   and abs(_mle(b[k]) - _mle(a[k])) > args.moved)
    for d, k in moved:
        print(f"{d:+8.2f} m  {k:10s} {a[k]['family']:16s} {_mle(a[k]):7.2f} -> {_mle(b[k]):7.2f} m, bound "
              f"{a[k]['bound_m']:.1f} m, e^T C^-1 e {a[k]['mle_nees'] or float('nan'):.1f} -> "
              f"{b[k]['mle_nees'] or float('nan'):.1f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
