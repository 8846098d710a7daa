#!/usr/bin/env python
"""Compare table4.csv and targets.csv of two `ridgeloc run` output folders, ignoring what issue 21 adds: the
`target` column and the rows / columns of flights with named targets (those in NEW only).

    python scripts/compare_outputs.py BASELINE_OUT NEW_OUT      # exit 0 when the rest is identical
"""

from __future__ import annotations

import argparse
import csv
import sys
from pathlib import Path


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("baseline", type=Path, help="the baseline run's output folder")
    ap.add_argument("new", type=Path, help="the new run's output folder")
    args = ap.parse_args(argv)
    base, new = args.baseline, args.new
    ok = True
    b_rows = list(csv.reader((base / "table4.csv").open()))
    n_rows = list(csv.reader((new / "table4.csv").open()))
    keep = [i for i, h in enumerate(n_rows[0]) if h in b_rows[0]]
    n_cut = [[r[i] for i in keep] for r in n_rows]
    n_cut = [r for r in n_cut if any(c for c in r[1:]) or r[0] in {x[0] for x in b_rows}]
    same = n_cut == b_rows
    ok &= same
    print(f"table4.csv: {'identical' if same else 'DIFFERENT'} on the baseline's {len(b_rows[0]) - 1} group(s)")
    b = [{k: v for k, v in r.items() if k != "target"} for r in csv.DictReader((base / "targets.csv").open())]
    groups = {r["group"] for r in b}
    n = [{k: v for k, v in r.items() if k != "target"} for r in csv.DictReader((new / "targets.csv").open())
         if r["group"] in groups]
    same = n == b and (not n or list(n[0]) == list(b[0]))
    ok &= same
    print(f"targets.csv: {'identical' if same else 'DIFFERENT'} on the baseline's {len(b)} row(s)")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
