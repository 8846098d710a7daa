"""Batch throughput: flights per minute with the local executor (1 and 2 worker processes) and on a Dask
LocalCluster of 2 worker processes, for the same jobs.

    python scripts/bench_batch.py                       # stand-in jobs (below), 20 flights
    python scripts/bench_batch.py --flights configs/sample.yaml --jobs 20   # real flights via pipeline.run

A stand-in job is what `ridgeloc run` does after tracking: read one flight's observations file (generated here,
8-16 frames like the paper's groups), run every estimator, write the group's output folder (result.json, three
figures, GeoJSON) atomically. With --flights a job is the real thing, `pipeline.run.process_group` on a flight
config (ingest, track, sync, solve) plus the same group folder; the configs are repeated to make --jobs jobs.
Dask cluster start-up is timed apart from the jobs.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT), str(ROOT / "tests")]  # this checkout's pipeline; test support (support.synthetic)

from pipeline import observation_file  # noqa: E402
from pipeline.batch import Job, discover_flights, run_jobs  # noqa: E402
from pipeline.geometry.rays import intersection_angle_deg  # noqa: E402
from pipeline.report.outputs import write_group_outputs  # noqa: E402
from pipeline.results import GroupResult  # noqa: E402
from support.synthetic import DEFAULT_ORIGIN_LLA, solve_all, synthetic_observations  # noqa: E402


def standin_job(payload: dict) -> str:
    obs = observation_file.load(payload["observations"])
    estimates, t = solve_all(obs)
    r = GroupResult(name=payload["name"], origin_lla=DEFAULT_ORIGIN_LLA, observations=obs, estimates=estimates,
                    truth_m=obs.truth_m, intersection_angle_deg=intersection_angle_deg(obs.platform_m, obs.truth_m),
                    timings_s={"solve": t})
    write_group_outputs(payload["outdir"], r)
    return r.name


def real_job(payload: dict) -> str:
    from pipeline.flight_config import load_flight_config
    from pipeline.results import group_files
    from pipeline.run import process_group

    r = process_group(load_flight_config(payload["config"]))
    r = dataclasses.replace(r, name=payload["name"])
    write_group_outputs(payload["outdir"], r, extra_files=group_files(r))
    return r.name


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--jobs", type=int, default=20)
    ap.add_argument("--flights", help="folder or manifest of flight configs (real jobs); default: stand-in jobs")
    ap.add_argument("--skip-dask", action="store_true")
    args = ap.parse_args()

    work = Path(tempfile.mkdtemp(prefix="bench_batch-"))
    if args.flights:
        configs = discover_flights(args.flights)
        fn, kind = real_job, f"real flights ({len(configs)} config(s) repeated)"
        payloads = [{"name": f"flight{i:02d}", "config": str(configs[i % len(configs)])} for i in range(args.jobs)]
    else:
        fn, kind = standin_job, "stand-in flights (observations file -> 8 estimators -> group folder with figures)"
        payloads = []
        for i in range(args.jobs):
            obs, _ = synthetic_observations(seed=i, intersection_angle_deg=20 + 2 * i, n_frames=8 + i % 9)
            p = work / "flights" / f"flight{i:02d}.json"
            p.parent.mkdir(parents=True, exist_ok=True)
            p.write_text(json.dumps(observation_file.to_dict(obs)))
            payloads.append({"name": f"flight{i:02d}", "observations": str(p)})

    def jobs(tag):
        return [Job(p["name"], p.get("config", p.get("observations")), {**p, "outdir": str(work / tag)})
                for p in payloads]

    rows = []

    def timed(label, **kw):
        t0 = time.perf_counter()
        results, failures = run_jobs(jobs(label.replace(" ", "_")), fn, progress=False, **kw)
        dt = time.perf_counter() - t0
        if failures:
            print(f"{label}: {len(failures)} failed, first: {failures[0].message}", file=sys.stderr)
        rows.append((label, len(results), dt, 60.0 * len(results) / dt))
        print(f"{label:<34} {len(results):>3} flights  {dt:7.2f} s  {rows[-1][3]:7.1f} flights/min", flush=True)
        return results

    print(f"{args.jobs} jobs: {kind}; {os.cpu_count()} CPU(s), Python {sys.version.split()[0]}")
    timed("local, 1 worker (in process)", workers=1)
    timed("local, 2 worker processes", workers=2)
    if not args.skip_dask:
        from distributed import Client, LocalCluster

        t0 = time.perf_counter()
        cluster = LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None)
        client = Client(cluster)
        startup = time.perf_counter() - t0
        try:
            timed("dask LocalCluster, 2 processes", executor="dask", scheduler=client)
        finally:
            client.close()
            cluster.close()
        print(f"(dask cluster start-up {startup:.1f} s, not included)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
