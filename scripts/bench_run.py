"""Time `ridgeloc run`'s processing of the sample flights: whole run, per stage, per observation.

    python scripts/bench_run.py [CONFIG] [--repeat N] [--workers W]

Each group is processed by `pipeline.run.process_group` exactly as `ridgeloc run` does (outputs are not
written). Stage times are wall-clock seconds measured inside process_group (ingest, decode, track, sync,
solve); the run time is the wall clock of all groups, sequential (--workers 1) or in W worker processes.
Prints per group and pooled: seconds, seconds per 10 observations, and the share of each stage; also the
process CPU seconds of each stage (all threads), which a loaded machine does not inflate. The best of
--repeat runs is reported (the machine may be shared).
"""

from __future__ import annotations

import argparse
import sys
import time
from concurrent.futures import ProcessPoolExecutor

from pipeline.flight_config import load_run_config
from pipeline.run import process_group

STAGES = ("ingest", "decode", "track", "sync", "solve")


def _run(configs, workers: int):
    t0 = time.perf_counter()
    c0 = time.process_time()
    if workers > 1:
        with ProcessPoolExecutor(workers) as pool:
            results = list(pool.map(process_group, configs))
    else:
        results = [process_group(c) for c in configs]
    return results, time.perf_counter() - t0, time.process_time() - c0


def _flight_row(r):
    """A flight with named targets (issue 21) as one row: its stage times (targets summed), its targets'
    observations summed, its CPU seconds."""
    from types import SimpleNamespace

    from pipeline.results import FlightResult

    if not isinstance(r, FlightResult):
        return r
    cpu = {s: r.settings.get("cpu_s", {}).get(s, 0.0) if s in ("ingest",) else
           sum(t.settings.get("cpu_s", {}).get(s, 0.0) for t in r.targets) for s in STAGES}
    return SimpleNamespace(name=r.name, timings_s=r.timings_s, settings={"cpu_s": cpu},
                           n_observations=sum(t.n_observations for t in r.targets))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("config", nargs="?", default="configs/sample.yaml")
    ap.add_argument("--repeat", type=int, default=2)
    ap.add_argument("--workers", type=int, default=1)
    args = ap.parse_args(argv)
    configs = [e.config for e in load_run_config(args.config) if e.config is not None]
    best = None
    for _ in range(max(1, args.repeat)):
        results, wall, cpu = _run(configs, args.workers)
        if best is None or wall < best[1]:
            best = (results, wall, cpu)
    results, wall, cpu = best
    results = [_flight_row(r) for r in results]
    print(f"{'group':<14} {'obs':>4} " + " ".join(f"{s + ' s':>9}" for s in STAGES) + f" {'total s':>8} "
          f"{'s/10 obs':>8}")
    totals = dict.fromkeys(STAGES, 0.0)
    n_obs = 0
    for r in results:
        t = r.timings_s
        total = sum(t.get(s, 0.0) for s in STAGES)
        n_obs += r.n_observations
        for s in STAGES:
            totals[s] += t.get(s, 0.0)
        print(f"{r.name:<14} {r.n_observations:>4} " + " ".join(f"{t.get(s, 0.0):>9.3f}" for s in STAGES)
              + f" {total:>8.3f} {10 * total / r.n_observations:>8.3f}")
    stage_sum = sum(totals.values())
    print(f"{'all':<14} {n_obs:>4} " + " ".join(f"{totals[s]:>9.3f}" for s in STAGES)
          + f" {stage_sum:>8.3f} {10 * stage_sum / max(n_obs, 1):>8.3f}")
    stage_cpu = {s: sum(r.settings.get("cpu_s", {}).get(s, 0.0) for r in results) for s in STAGES}
    total_cpu = sum(stage_cpu.values())
    print(f"{'all (CPU s)':<14} {n_obs:>4} " + " ".join(f"{stage_cpu[s]:>9.3f}" for s in STAGES)
          + f" {total_cpu:>8.3f} {10 * total_cpu / max(n_obs, 1):>8.3f}")
    print("share of stage time: " + ", ".join(f"{s} {100 * totals[s] / stage_sum:.0f} %" for s in STAGES))
    print(f"whole run ({len(results)} groups, {n_obs} observations, {args.workers} worker(s)): {wall:.2f} s wall, "
          f"{10 * wall / max(n_obs, 1):.3f} s per 10 observations; parent CPU {cpu:.2f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
