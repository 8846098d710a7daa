"""Profile the batched mle on the paper's problems (issue 19's throughput): problems/s of CPU and a cProfile of
solve_batch("mle") on 8000 paper problems (10 frames, 30 deg).

    OPENBLAS_NUM_THREADS=1 PYTHONPATH=. python scripts/prof_batch_mle.py [--batch 8000] [--top 35]
"""

from __future__ import annotations

import argparse
import cProfile
import pstats
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT), str(ROOT / "tests")]  # this checkout's pipeline; test support (support.scenes)

from pipeline.solve import solve_batch  # noqa: E402
from support.scenes import paper_batch  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--batch", type=int, default=8000)
    ap.add_argument("--top", type=int, default=35)
    args = ap.parse_args()
    b = paper_batch(args.batch, 10, 30.0, seed=1)
    solve_batch("mle", b)  # warm-up
    times = []
    for _ in range(3):
        t = time.process_time()
        solve_batch("mle", b)
        times.append(time.process_time() - t)
    print(f"{args.batch / min(times):.0f} problems/s CPU (best of 3)")
    prof = cProfile.Profile()
    prof.runcall(solve_batch, "mle", b)
    pstats.Stats(prof).sort_stats("cumulative").print_stats(args.top)


if __name__ == "__main__":
    main()
