"""Is the `mle` covariance honest on a run's flights? The normalized squared error e^T C^-1 e per group (e the
error against the truth, C the reported covariance: chi-square with 3 degrees of freedom when C is right, mean
3, below 7.81 in 95 % of cases), for the MLE as the run solves it (the flight's sigma; without correlation times
it estimates a boresight bias and checks its fit) and, for comparison, the independent-error model with the
Huber loss and no bias (the default before issue 12; its fit checks still inflate the covariance).

    python scripts/consistency.py OUTDIR    (OUTDIR from `ridgeloc run -o OUTDIR`)
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # this checkout's pipeline

from pipeline.observation_file import load
from pipeline.solve import solve
from pipeline.solve.observations import Observations
from pipeline.solve.uncertainty import CHI2_3_95


def normalized_errors(obs: Observations, **options) -> tuple[float, float, np.ndarray, dict]:
    """(e^T C^-1 e, |e| m, 1-sigma per axis (3,) m, the estimate's extras) of `mle` with the given options."""
    est = solve("mle", obs, **options)
    e = est.position_m - obs.truth_m
    return float(e @ np.linalg.solve(est.covariance_m2, e)), float(np.linalg.norm(e)), \
        np.sqrt(np.diag(est.covariance_m2)), est.extras


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("outdir", type=Path)
    args = ap.parse_args(argv)
    print(f"chi-square with 3 degrees of freedom when the covariance is right: mean 3, 95 % below {CHI2_3_95:.2f}\n")
    print("| group | mle error m | 1-sigma E, N, U m | e^T C^-1 e | fits | independent, no bias: error m | "
          "1-sigma E, N, U m | e^T C^-1 e |")
    print("| --- | --- | --- | --- | --- | --- | --- | --- |")
    rows = []
    for path in sorted(args.outdir.glob("*/observations.json")):
        obs = load(path)
        if obs.truth_m is None:
            continue
        d_m, err_m, sd_m, ex = normalized_errors(obs)
        d_w, err_w, sd_w, _ = normalized_errors(obs, robust="huber", bias_prior_deg=0.0)
        rows.append((d_m, d_w, err_m, err_w))
        fmt = ", ".join
        fit = ex.get("fit", {})
        fits = "-" if not fit else ("yes" if fit["consistent"] else f"no (x{fit['covariance_inflation']:.1f})")
        print(f"| {path.parent.name} | {err_m:.2f} | {fmt(f'{v:.2f}' for v in sd_m)} | {d_m:.1f} | {fits} | "
              f"{err_w:.2f} | {fmt(f'{v:.2f}' for v in sd_w)} | {d_w:.1f} |")
    if rows:
        d = np.array(rows)
        print(f"| mean | {d[:, 2].mean():.2f} | | {d[:, 0].mean():.1f} | | {d[:, 3].mean():.2f} | | "
              f"{d[:, 1].mean():.1f} |")
        print(f"| within the 95 % ellipsoid | | | {(d[:, 0] <= CHI2_3_95).sum()}/{len(d)} | | | | "
              f"{(d[:, 1] <= CHI2_3_95).sum()}/{len(d)} |")
        if obs.sigma.correlated:
            print("(the observations carry correlation times: the mle column is the configured GLS model)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
