"""Is the `mle` covariance honest on a run's flights? The normalized squared error e^T C^-1 e per group (e the
error against the truth, C the reported covariance: chi-square with 3 degrees of freedom when C is right, mean
3, below 7.81 in 95 % of cases), with the flight's sigma as written and with its correlation times removed.

    python -m pipeline.solve.consistency OUTDIR    (OUTDIR from `ridgeloc run -o OUTDIR`)
"""

from __future__ import annotations

import argparse
import dataclasses
from pathlib import Path

import numpy as np

from pipeline.solve import solve
from pipeline.solve.mle import CHI2_3_95
from pipeline.solve.observations import Observations


def normalized_errors(obs: Observations, sigma) -> tuple[float, float, np.ndarray]:
    """(e^T C^-1 e, |e| m, 1-sigma per axis (3,) m) of `mle` with the given sigma."""
    est = solve("mle", obs, sigma=sigma)
    e = est.position_m - obs.truth_m
    return float(e @ np.linalg.solve(est.covariance_m2, e)), float(np.linalg.norm(e)), \
        np.sqrt(np.diag(est.covariance_m2))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("outdir", type=Path)
    args = ap.parse_args(argv)
    print(f"chi-square with 3 degrees of freedom when the covariance is right: mean 3, 95 % below {CHI2_3_95:.2f}\n")
    print("| group | independent: error m | 1-sigma E, N, U m | e^T C^-1 e | correlated: error m | 1-sigma E, N, U m | "
          "e^T C^-1 e |")
    print("| --- | --- | --- | --- | --- | --- | --- |")
    rows = []
    for path in sorted(args.outdir.glob("*/observations.json")):
        obs = Observations.load(path)
        if obs.truth_m is None:
            continue
        white = dataclasses.replace(obs.sigma, attitude_tau_s=None, position_tau_s=None)
        d_w, err_w, sd_w = normalized_errors(obs, white)
        d_c, err_c, sd_c = normalized_errors(obs, obs.sigma)
        rows.append((d_w, d_c))
        fmt = ", ".join
        print(f"| {path.parent.name} | {err_w:.2f} | {fmt(f'{v:.2f}' for v in sd_w)} | {d_w:.1f} | {err_c:.2f} | "
              f"{fmt(f'{v:.2f}' for v in sd_c)} | {d_c:.1f} |")
    if rows:
        d = np.array(rows)
        print(f"| mean | | | {d[:, 0].mean():.1f} | | | {d[:, 1].mean():.1f} |")
        print(f"| within the 95 % ellipsoid | | | {(d[:, 0] <= CHI2_3_95).sum()}/{len(d)} | | | "
              f"{(d[:, 1] <= CHI2_3_95).sum()}/{len(d)} |")
        if not obs.sigma.correlated:
            print("(the observations carry no correlation times: both columns are the independent model)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
