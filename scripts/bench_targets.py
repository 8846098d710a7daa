#!/usr/bin/env python
"""Cost of many targets in one pass (issue 21): the sample flight three_targets with 1 target and with 10,
side by side in one run.

    python scripts/bench_targets.py [--repeat N] [--config configs/flights/three_targets.yaml] [--against DIR]
                                    [--command]

Each case is `pipeline.run.process_group` (what `ridgeloc run` does before writing outputs) in a fresh child
process, the cases alternating, N times each; per case the median wall time, the median stage times (ingest,
decode, track, sync, solve; a stage summed over the targets), the median process CPU time of the run (all
threads; less disturbed than wall time when other work shares the cores) and the median peak resident memory of
the child (ru_maxrss, which includes the interpreter and libraries). The 10 targets are the flight's three and
seven more points marked on a grid of frame 4; 1 target is the first of them. Prints the ratios 10 / 1. With
--against DIR (another checkout, e.g. main's, used read-only) its children run the same cases in turn with this
code's, and the ratios of this code's medians to its are printed too; the 1-minute load average is printed.

With --command, also what a user waits for: the whole command `python -m pipeline run -q -o OUT FLIGHT.yaml` (a
fresh interpreter: imports, the flight, every output written, figures included; and again with --no-figures) on
a flight config with the 1 and with the 10 targets (written to a temporary folder, its files as absolute paths),
each run's wall time, CPU time (user + system) and peak resident memory (of that child, os.wait4), the medians
and the ratios 10 / 1, alternating with --against's code the same way.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
STAGES = ("ingest", "decode", "track", "sync", "solve")
GRID_PX = [(100.0, 100.0), (200.0, 300.0), (500.0, 120.0), (450.0, 330.0), (150.0, 220.0), (380.0, 60.0),
           (240.0, 150.0)]


def child(config: str, n: int) -> None:
    """Run process_group with the first n of the 10 targets and print a JSON line."""
    import dataclasses
    import time

    sys.path.insert(0, str(ROOT))
    from pipeline.flight_config import load_flight_config
    from pipeline.run import process_group
    from pipeline.targets import TargetEntry

    cfg = load_flight_config(config)
    entries = list(cfg.targets) + [TargetEntry(f"grid{i}", frame_index=cfg.targets[0].frame_index, pixel=px)
                                   for i, px in enumerate(GRID_PX)]
    cfg = dataclasses.replace(cfg, targets=tuple(entries[:n]))
    t0, c0 = time.perf_counter(), time.process_time()
    r = process_group(cfg)
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    located = [t.target for t in r.targets]
    print(json.dumps({"n": n, "wall_s": wall, "cpu_s": cpu, "timings_s": r.timings_s, "located": located,
                      "failed": [f.target for f in r.failed],
                      "frames_decoded": r.targets[0].settings["frames_decoded"],
                      "maxrss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024}))


def _targets(config: str) -> list[dict]:
    """The 10 targets as flight-config entries: the flight's and the grid points of `child`."""
    import yaml

    cfg = yaml.safe_load(Path(config).read_text())
    first = cfg["targets"][0]
    return list(cfg["targets"]) + [{"name": f"grid{i}", "frame_index": first["frame_index"], "pixel": list(px)}
                                   for i, px in enumerate(GRID_PX)]


def command_configs(config: str, folder: Path) -> dict[int, Path]:
    """Flight configs with the first 1 and all 10 targets in `folder` ({n: path}), the config's files (and
    truth_file) as absolute paths so that they open from there."""
    import yaml

    src = Path(config).resolve()
    cfg = yaml.safe_load(src.read_text())

    def absolute(p):
        return [absolute(x) for x in p] if isinstance(p, list) else str((src.parent / p).resolve())

    cfg["files"] = {k: absolute(v) for k, v in cfg["files"].items()}
    if cfg.get("truth_file"):
        cfg["truth_file"] = absolute(cfg["truth_file"])
    ten = _targets(config)
    out = {}
    for n in (1, 10):
        out[n] = folder / f"{src.stem}_{n}_targets.yaml"
        out[n].write_text(yaml.safe_dump({**cfg, "name": src.stem, "targets": ten[:n]}, sort_keys=False))
    return out


def time_command(root: Path, flight: Path, figures: bool) -> dict:
    """`python -m pipeline run -q -o OUT flight` with root's code (its folder as the working directory): the
    wall time from launch to exit, CPU seconds (user + system) and peak RSS (MB) of that process."""
    import tempfile
    import time

    with tempfile.TemporaryDirectory() as out:
        cmd = [sys.executable, "-m", "pipeline", "run", "-q", "-o", out, str(flight)] + ([] if figures else
                                                                                        ["--no-figures"])
        t0 = time.perf_counter()
        p = subprocess.Popen(cmd, cwd=root, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        _, status, ru = os.wait4(p.pid, 0)
        wall = time.perf_counter() - t0
        p.returncode = os.waitstatus_to_exitcode(status)
        if p.returncode != 0:
            raise SystemExit(f"{' '.join(cmd)} (in {root}) exited with {p.returncode}")
    return {"wall_s": wall, "cpu_s": ru.ru_utime + ru.ru_stime, "maxrss_mb": ru.ru_maxrss / 1024}


def _command_table(label: str, runs: dict[tuple, list[dict]]) -> dict[tuple, dict]:
    """Print one code's whole-command medians and ratios 10 / 1; returns the medians per case."""
    med = {case: {k: statistics.median(r[k] for r in rs) for k in ("wall_s", "cpu_s", "maxrss_mb")}
           for case, rs in runs.items()}
    print(f"{label}: the whole command `python -m pipeline run -q -o OUT FLIGHT.yaml`")
    print(f"{'figures':>8} {'targets':>8} {'wall s':>8} {'cpu s':>8} {'peak MB':>8}")
    for (figures, n), m in med.items():
        print(f"{'yes' if figures else 'no':>8} {n:>8} {m['wall_s']:>8.2f} {m['cpu_s']:>8.2f} {m['maxrss_mb']:>8.1f}")
    for figures in (True, False):
        a, b = med[figures, 1], med[figures, 10]
        print(f"ratio 10/1 ({'with' if figures else 'without'} figures): wall {b['wall_s'] / a['wall_s']:.2f}x, "
              f"cpu {b['cpu_s'] / a['cpu_s']:.2f}x, peak memory {b['maxrss_mb'] / a['maxrss_mb']:.2f}x")
    return med


def _table(label: str, runs: dict[int, list[dict]]) -> dict[int, dict]:
    """Print one code's table and ratios 10 / 1; returns the medians per case."""
    med = {n: {"wall_s": statistics.median(r["wall_s"] for r in rs), "cpu_s": statistics.median(r["cpu_s"] for r in rs),
               "maxrss_mb": statistics.median(r["maxrss_mb"] for r in rs),
               **{s: statistics.median(r["timings_s"].get(s, 0.0) for r in rs) for s in STAGES}}
           for n, rs in runs.items()}
    print(label)
    print(f"{'targets':>8} {'located':>8} {'decoded':>8} {'wall s':>8} {'cpu s':>8} {'peak MB':>8} "
          + " ".join(f"{s + ' s':>9}" for s in STAGES))
    for n, rs in runs.items():
        m = med[n]
        print(f"{n:>8} {len(rs[0]['located']):>8} {rs[0]['frames_decoded']:>8} {m['wall_s']:>8.2f} "
              f"{m['cpu_s']:>8.2f} {m['maxrss_mb']:>8.1f} " + " ".join(f"{m[s]:>9.3f}" for s in STAGES))
    a, b = med[1], med[10]
    no_solve = [sum(m[s] for s in STAGES if s != "solve") for m in (a, b)]
    print(f"ratio 10/1: wall {b['wall_s'] / a['wall_s']:.2f}x, cpu {b['cpu_s'] / a['cpu_s']:.2f}x, "
          f"peak memory {b['maxrss_mb'] / a['maxrss_mb']:.2f}x, stages without solve {no_solve[1] / no_solve[0]:.2f}x, "
          f"solve {b['solve'] / max(a['solve'], 1e-9):.2f}x")
    if runs[10][0]["failed"]:
        print(f"not located among the 10: {', '.join(runs[10][0]['failed'])}")
    return med


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--config", default=str(ROOT / "configs" / "flights" / "three_targets.yaml"))
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--against", default=None, metavar="DIR",
                    help="another checkout of the project (e.g. main's): its children alternate with this one's")
    ap.add_argument("--command", action="store_true",
                    help="also time the whole `python -m pipeline run` command (outputs written) with 1 and 10 targets")
    ap.add_argument("--child", type=int, default=None, help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.child is not None:
        child(args.config, args.child)
        return 0
    trees = [("this code", ROOT)] + ([(f"against {args.against}", Path(args.against).resolve())] if args.against
                                     else [])
    runs: dict[str, dict[int, list[dict]]] = {label: {1: [], 10: []} for label, _ in trees}
    cases = [(figures, n) for figures in (True, False) for n in (1, 10)]
    commands: dict[str, dict[tuple, list[dict]]] = {label: {c: [] for c in cases} for label, _ in trees}
    load = [os.getloadavg()[0]]
    with tempfile.TemporaryDirectory() as folder:
        flights = command_configs(args.config, Path(folder)) if args.command else {}
        for _ in range(max(1, args.repeat)):
            for label, root in trees:
                for n in (1, 10):
                    out = subprocess.run([sys.executable, str(root / "scripts" / "bench_targets.py"), "--config",
                                          args.config, "--child", str(n)], cwd=root, capture_output=True, text=True,
                                         check=True)
                    runs[label][n].append(json.loads(out.stdout.strip().splitlines()[-1]))
                for figures, n in cases if args.command else []:
                    commands[label][figures, n].append(time_command(root, flights[n], figures))
            load.append(os.getloadavg()[0])
    print(f"{Path(args.config).name}, median of {args.repeat} run(s) each, alternating, one child process per run; "
          f"1-minute load average {min(load):.2f} to {max(load):.2f}")
    med = {label: _table(label, r) for label, r in runs.items()}
    if args.against:
        (_, a), (lb, b) = med.items()
        print(f"this code / {lb.split(' ', 1)[1]}: " + ", ".join(
            f"{n} target(s) wall {a[n]['wall_s'] / b[n]['wall_s']:.2f}x cpu {a[n]['cpu_s'] / b[n]['cpu_s']:.2f}x "
            f"solve {a[n]['solve'] / max(b[n]['solve'], 1e-9):.2f}x" for n in (1, 10)))
    if args.command:
        cmed = {label: _command_table(label, r) for label, r in commands.items()}
        if args.against:
            (_, a), (lb, b) = cmed.items()
            print(f"whole command, this code / {lb.split(' ', 1)[1]}: " + ", ".join(
                f"{n} target(s) {'with' if f else 'without'} figures wall {a[f, n]['wall_s'] / b[f, n]['wall_s']:.2f}x"
                for f, n in cases))
    return 0


if __name__ == "__main__":
    sys.exit(main())
