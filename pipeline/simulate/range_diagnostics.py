"""Where the laser-only estimator's answers lie, for the claims about it in docs/simulation.md.

    python -m pipeline.simulate.range_diagnostics [CONFIG] [--angles 10 20] [--trials N]

For each angle it solves the config's trials with `range` twice, from the default start (the vision result) and
from the true target, and prints: the share flagged DEGENERATE, the median error of the answered trials, the share
of answered trials whose point is more than 1 km above the ground (z > 1000 m; the target is at z = 0), and how far
the answers from the two starts are apart (trials answered by both).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from pipeline.errors import RidgelocError
from pipeline.simulate.config import SimulationConfig
from pipeline.simulate.experiment import solver_options
from pipeline.simulate.scenario import generate
from pipeline.simulate.statistics import answered_mask
from pipeline.solve.estimate import Status


def range_diagnostics(cfg: SimulationConfig, angle_deg: float) -> dict[str, float]:
    """Statistics of `range` at one angle (see the module docstring); shares in %, distances in m."""
    from pipeline.solve import solve_batch

    trials = generate(cfg, angle_deg)
    truth = trials.batch.truth_m
    opts = solver_options(cfg, "range")
    est = solve_batch("range", trials.batch, **opts)
    est_truth = solve_batch("range", trials.batch, **opts, initial_m=truth)
    ok, ok_truth = answered_mask(est), answered_mask(est_truth)
    B = ok.size
    both = ok & ok_truth
    apart = np.linalg.norm(est.position_m[both] - est_truth.position_m[both], axis=1)
    err = est.errors_m(truth)[ok]
    return {
        "degenerate_pct": 100.0 * np.count_nonzero(np.asarray(est.status) == Status.DEGENERATE) / B,
        "median_m": float(np.median(err)) if err.size else float("nan"),
        "above_1km_pct_of_answered": 100.0 * np.count_nonzero(est.position_m[ok, 2] > 1000.0) / max(ok.sum(), 1),
        "answered_from_truth_pct": 100.0 * ok_truth.sum() / B,
        "starts_agree_within_1m_pct": 100.0 * np.count_nonzero(apart < 1.0) / max(both.sum(), 1),
        "max_apart_m": float(apart.max()) if apart.size else float("nan"),
    }


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("config", nargs="?", type=Path, default=None,
                        help="a simulation config (default: the built-in defaults, = configs/simulation_table2.yaml)")
    parser.add_argument("--angles", type=float, nargs="+", default=[10.0, 20.0])
    parser.add_argument("--trials", type=int)
    args = parser.parse_args(argv)
    try:
        cfg = SimulationConfig() if args.config is None else SimulationConfig.load(args.config)
        if args.trials is not None:
            cfg = cfg.replace(trials=args.trials)
        for angle in args.angles:
            d = range_diagnostics(cfg, angle)
            print(f"{cfg.name} {angle:g} deg, range ({cfg.trials} trials): "
                  + ", ".join(f"{k} {v:.4g}" for k, v in d.items()))
    except RidgelocError as exc:
        print(f"range_diagnostics: error: {exc}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
