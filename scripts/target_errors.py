#!/usr/bin/env python
"""Per target of a `ridgeloc run` output folder: each method's error against the truth and whether the truth lies
inside the estimate's 95 % error ellipsoid (squared Mahalanobis distance of the error under its covariance vs
the chi-square 3-dof 95 % quantile, 7.815).

    python scripts/target_errors.py OUT [GROUP ...]      # e.g. OUT three_targets
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
from scipy.stats import chi2

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from pipeline.report.store import load_group_result
from pipeline.results import per_target


def main(argv=None) -> int:
    argv = list(argv if argv is not None else sys.argv[1:])
    out, groups = Path(argv[0]), argv[1:]
    folders = [out / g for g in groups] if groups else sorted(p.parent for p in out.glob("*/result.json"))
    q95 = chi2.ppf(0.95, 3)
    print(f"{'group:target':<28} {'method':<10} {'error m':>8} {'mahal^2':>8} inside 95 %")
    for folder in folders:
        for r in per_target([load_group_result(folder / "result.json")]):
            for m, e in r.estimates.items():
                err = e.error_m(r.truth_m)
                if err is None:
                    continue
                d2 = float("nan")
                if e.covariance_m2 is not None:
                    d = np.asarray(e.position_m) - r.truth_m
                    d2 = float(d @ np.linalg.solve(np.asarray(e.covariance_m2), d))
                inside = "" if not np.isfinite(d2) else ("yes" if d2 <= q95 else "NO")
                print(f"{r.label:<28} {m:<10} {err:>8.2f} {d2:>8.2f} {inside}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
