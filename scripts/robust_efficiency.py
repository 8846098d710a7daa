"""What does the robust loss cost on clean data? Median error of the MLE with the default loss (redescending,
after a Huber start) and with Huber, over the squared loss's (robust=None), on Gaussian noise as in the paper's
simulation (section 3.1 sigmas, errors independent and the model told so: bias_prior_deg=0), for intersection
angles 10-80 deg, n = 5, 10, 20, 50 observations and slant ranges 2, 5 and 10 km.

    python scripts/robust_efficiency.py [--trials 400] [--seed 0]      (about a minute)
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT), str(ROOT / "tests")]  # this checkout's pipeline; test support (support.scenes)

from pipeline.solve import solve_batch  # noqa: E402
from support.scenes import paper_batch  # noqa: E402

ANGLES = (10, 20, 30, 40, 50, 60, 70, 80)
NS = (5, 10, 20, 50)
SLANTS = (2000.0, 5000.0, 10000.0)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--trials", type=int, default=400)
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args(argv)
    t0 = time.perf_counter()
    ratios = {"redescending": [], "huber": []}
    rejected = 0
    rows = 0
    print("| n | slant km | default / squared (min, median, max over angles) | huber / squared |")
    print("|---:|---:|---|---|")
    for n in NS:
        for slant in SLANTS:
            per = {"redescending": [], "huber": []}
            for k, angle in enumerate(ANGLES):
                batch = paper_batch(args.trials, n=n, gamma_deg=angle, seed=args.seed + 1000 * n + k,
                                    slant_m=slant, height_m=0.4 * slant)
                base = np.nanmedian(solve_batch("mle", batch, robust=None, bias_prior_deg=0.0).errors_m(batch.truth_m))
                for loss in per:
                    est = solve_batch("mle", batch, robust=loss, bias_prior_deg=0.0)
                    per[loss].append(np.nanmedian(est.errors_m(batch.truth_m)) / base)
                    if loss == "redescending":
                        rejected += int(est.extras["rejected"].sum())
                        rows += int(est.extras["rejected"].size)
            for loss in per:
                ratios[loss] += per[loss]
            r, h = np.array(per["redescending"]), np.array(per["huber"])
            print(f"| {n} | {slant / 1000:g} | {r.min():.3f}, {np.median(r):.3f}, {r.max():.3f} | "
                  f"{h.min():.3f}, {np.median(h):.3f}, {h.max():.3f} |", flush=True)
    r, h = np.array(ratios["redescending"]), np.array(ratios["huber"])
    print(f"\nall {len(r)} configurations: default / squared median {np.median(r):.3f}, max {r.max():.3f}; "
          f"huber / squared median {np.median(h):.3f}, max {h.max():.3f}; the default rejected {rejected} of "
          f"{rows} rows ({rejected / rows:.2e}) of Gaussian data; {time.perf_counter() - t0:.0f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
