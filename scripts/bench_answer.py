"""What an answer costs on large or odd observation files: every method and the answer rule (issue 38, point 7).

    PYTHONPATH=. python scripts/bench_answer.py [--rows 5000] [--repeat 10]

Builds, from configs/example_observations.json, a file of ROWS observations whose times repeat REPEAT frames'
(each row a copy of one of the first REPEAT frames, its pixel moved by 0.5 px of noise: the shape of a log
exported twice over), and one of ROWS distinct frames (the same rows, one time each); then times, on each, every
method (`solve_problems`, one batch per method) and `choose_answer` (the verdicts, the propagation through the
methods without a covariance of their own). Wall seconds, median of 3.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import statistics
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
METHODS = ["dlt", "vision", "range", "los", "fusion-raw", "fusion", "ridge", "mle"]


def _timed(fn, runs: int = 3) -> tuple[float, object]:
    times, out = [], None
    for _ in range(runs):
        t = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t)
    return statistics.median(times), out


def main(argv: list[str]) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--rows", type=int, default=5000)
    parser.add_argument("--repeat", type=int, default=10)
    args = parser.parse_args(argv)
    from pipeline.answer import choose_answer
    from pipeline.observation_file import from_dict
    from pipeline.solve.methods import solve_problems

    doc = json.loads((ROOT / "configs" / "example_observations.json").read_text())
    base = doc["observations"]
    rng = np.random.default_rng(0)
    rows = []
    for i in range(args.rows):
        o = json.loads(json.dumps(base[i % args.repeat]))
        if o.get("pixel"):
            o["pixel"] = [v + rng.normal(0, 0.5) for v in o["pixel"]]
        rows.append(o)
    repeated = from_dict({**doc, "observations": rows})
    distinct = dataclasses.replace(repeated, t_ns=repeated.t_ns[0] + np.arange(repeated.n, dtype=np.int64) * 10**8)
    print(f"{'file':34s}{'methods s':>11s}{'answer s':>10s}  answer")
    for name, obs in ((f"{args.rows} rows, {args.repeat} frames' times", repeated),
                      (f"{args.rows} rows, distinct times", distinct)):
        t_solve, got = _timed(lambda obs=obs: solve_problems([obs], METHODS, {})[0])
        est = {m: a for m, a in got.items() if not isinstance(a, Exception)}
        uns = {m: str(a) for m, a in got.items() if isinstance(a, Exception)}
        t_answer, a = _timed(lambda obs=obs, est=est, uns=uns: choose_answer(obs, est, uns, None))
        print(f"{name:34s}{t_solve:11.2f}{t_answer:10.2f}  {a.method or a.status}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
