"""Where does the `mle` 95 % ellipsoid's width come from? The default's coverage per error family of
scripts/calibration.py with each term of its covariance removed or scaled (docs/validation.md, "Calibration: the
width per term").

The terms (`pipeline.solve.mle`, the bias-size-unknown path of `solve_batch`):

    offset      the GNSS offset shared by the segment, position_m^2 I added to the covariance (times the
                misfit factor); "offset x s" carries s position_m^2 instead
    bias        the bias mixture over the bias's prior scale phi (`bias_mixture.PHI_GRID`); "-bias" keeps only
                phi = 0 (no bias: the estimate changes too)
    inflation   the fit checks' inflation (lag-1 autocorrelation and batch-means factors, chi-square variance
                factor)

Per family and variant: coverage of the 95 % ellipsoid (e^T C^-1 e <= 7.81), median e^T C^-1 e (2.37 for a
right covariance) and median error (m), on the problems of scripts/calibration.py (same generator, seed and
order). The variants patch the solver's internals for the duration of one solve (this revision's
`mle._Iteration.finish`, `bias_mixture.PHI_GRID`, `fit_checks`); they are measurements, not options.

    PYTHONPATH=. python scripts/calibration_split.py [--trials 100] [--seed 0] [--families a,b]
"""

from __future__ import annotations

import argparse
import contextlib
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import calibration as cal

from pipeline.solve import bias_mixture, fit_checks, solve_batch
from pipeline.solve import mle as _mle

VARIANTS = {
    "default": {},
    "offset x 0.5": {"offset": 0.5},
    "offset x 0.25": {"offset": 0.25},
    "-offset": {"offset": 0.0},
    "-bias": {"bias": False},
    "-inflation": {"inflation": False},
    "-offset -bias": {"offset": 0.0, "bias": False},
    "-offset -bias -inflation": {"offset": 0.0, "bias": False, "inflation": False},
}


@contextlib.contextmanager
def variant(offset: float = 1.0, bias: bool = True, inflation: bool = True):
    saved = (_mle.White.adjust, bias_mixture.PHI_GRID, fit_checks.acf_significant, fit_checks.chi_square_p,
             fit_checks.batch_means_significant)
    if offset != 1.0:
        finish = saved[0]

        def scaled(self, *args):
            self.position_m = self.position_m * np.sqrt(offset)
            return finish(self, *args)

        _mle.White.adjust = scaled
    if not bias:
        bias_mixture.PHI_GRID = np.array([0.0])
    if not inflation:
        fit_checks.acf_significant = lambda rho, pairs: np.zeros(np.shape(rho), dtype=bool)
        fit_checks.chi_square_p = lambda chi2, dof: np.ones(np.shape(chi2))
        fit_checks.batch_means_significant = lambda ratio, blocks: np.zeros(np.shape(ratio), dtype=bool)
    try:
        yield
    finally:
        (_mle.White.adjust, bias_mixture.PHI_GRID, fit_checks.acf_significant, fit_checks.chi_square_p,
         fit_checks.batch_means_significant) = saved


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--trials", type=int, default=100, help="problems per family, geometry and n (default 100)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--families", default=",".join(cal.FAMILIES))
    args = ap.parse_args(argv)
    t0 = time.perf_counter()
    print(f"{args.trials} problems per family x geometry x n; per variant: coverage / median e^T C^-1 e / "
          "median error m\n")
    print("| family | " + " | ".join(VARIANTS) + " |")
    print("|---|" + "---|" * len(VARIANTS))
    for family in args.families.split(","):
        rng = np.random.default_rng(args.seed)  # the same problems as calibration.py for a single family
        batches = [cal.make_family(rng, family, args.trials, n, g)[0] for g in cal.GEOMETRIES for n in cal.NS]
        cells = []
        for kw in VARIANTS.values():
            d2, err = [], []
            for batch in batches:
                with variant(**kw):
                    est = solve_batch("mle", batch)
                d2.append(cal.nees(est.position_m, est.covariance_m2, batch.truth_m))
                err.append(est.errors_m(batch.truth_m))
            d2, err = np.concatenate(d2), np.concatenate(err)
            cells.append(f"{np.mean(d2 <= cal.CHI2_3_95):.1%} / {np.median(d2):.2f} / {np.nanmedian(err):.2f}")
        print(f"| {family} | " + " | ".join(cells) + " |", flush=True)
    print(f"\n{time.perf_counter() - t0:.0f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
