"""Fuzz every reader in tests/support/fuzz_targets.py for a while and report inputs tried and failures found.

    nice -n 10 python scripts/fuzz.py --minutes 2                 # every reader, 2 minutes each
    nice -n 10 python scripts/fuzz.py --minutes 5 --targets tlog,mcap --seed 7

A failure is an exception other than RidgelocError (a traceback for the user), an error message that is not one
line naming the file, a read over --timeout seconds, or running out of the --memory-gb address-space limit.
Each reader runs in its own process (so a hang or crash is caught and the run goes on); failing inputs are kept
in OUT/<reader>/ with what was done to the seed, and OUT/counts.json accumulates inputs tried across runs.
"""

from __future__ import annotations

import argparse
import json
import multiprocessing as mp
import os
import random
import resource
import signal
import sys
import tempfile
import time
import warnings
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tests"))  # test support: support.fuzz_targets

from support.fuzz_targets import BY_NAME, TARGETS, check, mutate  # noqa: E402


class _Timeout(Exception):
    pass


def _alarm(signum, frame):
    raise _Timeout


def _worker(name: str, seconds: float, seed: int, timeout_s: float, memory_gb: float, out: Path, status: Path):
    """Runs in a child process: mutate, write, read, record; writes status JSON about once a second."""
    resource.setrlimit(resource.RLIMIT_AS, (int(memory_gb * 2**30),) * 2)
    devnull = os.open(os.devnull, os.O_WRONLY)  # FFmpeg, OpenCV and SQLite chatter on fds 1 and 2 for every bad input
    os.dup2(devnull, 1)
    os.dup2(devnull, 2)
    warnings.simplefilter("ignore")
    signal.signal(signal.SIGALRM, _alarm)
    target = BY_NAME[name]
    work = Path(tempfile.mkdtemp(prefix=f"fuzz-{name}-"))
    path = target.make_seed(work)
    seed_bytes = path.read_bytes()
    rng = random.Random(seed)
    tried, failures, last = 0, {}, 0.0
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline:
        data, ops = mutate(target, seed_bytes, rng)
        path.write_bytes(data)
        (out / "current.bin").write_bytes(data)
        signal.setitimer(signal.ITIMER_REAL, timeout_s)
        try:
            problem = check(target, path)
        except _Timeout:
            problem = f"timeout: more than {timeout_s:g} s"
        except MemoryError:
            problem = f"MemoryError: more than {memory_gb:g} GB of address space"
        finally:
            signal.setitimer(signal.ITIMER_REAL, 0)
        tried += 1
        if problem is not None:
            key = problem.split(":")[0] + ":" + problem.split(" at ")[-1][:60] if " at " in problem else problem[:80]
            if key not in failures:
                failures[key] = {"problem": problem, "ops": ops, "count": 0, "file": f"fail-{len(failures)}.bin"}
                (out / failures[key]["file"]).write_bytes(data)
            failures[key]["count"] += 1
        now = time.monotonic()
        if now - last > 1.0 or now >= deadline:
            status.write_text(json.dumps({"tried": tried, "failures": failures}))
            last = now
    status.write_text(json.dumps({"tried": tried, "failures": failures, "done": True}))


def fuzz_target(name: str, seconds: float, seed: int, timeout_s: float, memory_gb: float, out: Path) -> dict:
    """Runs the worker, restarting it after a hang or crash, until `seconds` have passed."""
    out.mkdir(parents=True, exist_ok=True)
    total = {"tried": 0, "failures": {}}
    end = time.monotonic() + seconds
    restart = 0
    while (left := end - time.monotonic()) > 1.0:
        status = out / f"status-{restart}.json"
        proc = mp.get_context("fork").Process(target=_worker, args=(name, left, seed + restart, timeout_s, memory_gb,
                                                                     out, status), daemon=True)
        proc.start()
        while proc.is_alive():
            proc.join(1.0)
            beat = (out / "current.bin").stat().st_mtime if (out / "current.bin").exists() else time.time()
            if time.time() - beat > 3 * timeout_s:  # stuck in C code where the alarm cannot interrupt it
                proc.kill()
                proc.join()
                break
        st = json.loads(status.read_text()) if status.exists() else {"tried": 0, "failures": {}}
        status.unlink(missing_ok=True)
        total["tried"] += st["tried"]
        for k, f in st["failures"].items():
            if k in total["failures"]:
                total["failures"][k]["count"] += f["count"]
            else:
                total["failures"][k] = f
        if not st.get("done"):
            crash = f"hang or crash (exit {proc.exitcode})"
            kept = out / f"crash-{restart}.bin"
            if (out / "current.bin").exists():
                (out / "current.bin").replace(kept)
            total["failures"].setdefault(crash, {"problem": crash, "ops": [], "count": 0, "file": kept.name})
            total["failures"][crash]["count"] += 1
            total["tried"] += 1
        restart += 1
    (out / "current.bin").unlink(missing_ok=True)
    return total


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--minutes", type=float, default=1.0, help="per reader")
    ap.add_argument("--targets", default="all", help=f"comma-separated, from: {', '.join(BY_NAME)}")
    ap.add_argument("--seed", type=int, default=None, help="random seed (default: from the clock; printed)")
    ap.add_argument("--timeout", type=float, default=20.0, help="seconds one input may take")
    ap.add_argument("--memory-gb", type=float, default=4.0, help="address-space limit of the reading process")
    ap.add_argument("--out", type=Path, default=ROOT / "fuzz_out")
    args = ap.parse_args(argv)
    names = [t.name for t in TARGETS] if args.targets == "all" else args.targets.split(",")
    unknown = [n for n in names if n not in BY_NAME]
    if unknown:
        ap.error(f"unknown target(s): {', '.join(unknown)}")
    seed = args.seed if args.seed is not None else int(time.time())
    print(f"seed {seed}, {args.minutes:g} min per reader, timeout {args.timeout:g} s, memory {args.memory_gb:g} GB",
          flush=True)
    counts_path = args.out / "counts.json"
    args.out.mkdir(parents=True, exist_ok=True)
    counts = json.loads(counts_path.read_text()) if counts_path.exists() else {}
    bad = 0
    print(f"{'reader':<15}{'tried':>8}{'all runs':>10}{'failures':>10}", flush=True)
    for i, name in enumerate(names):
        res = fuzz_target(name, args.minutes * 60, seed + 1000 * i, args.timeout, args.memory_gb, args.out / name)
        counts[name] = counts.get(name, 0) + res["tried"]
        counts_path.write_text(json.dumps(counts, indent=1, sort_keys=True))
        n_fail = sum(f["count"] for f in res["failures"].values())
        bad += n_fail
        print(f"{name:<15}{res['tried']:>8}{counts[name]:>10}{n_fail:>10}", flush=True)
        for f in res["failures"].values():
            print(f"    {f['count']} x {f['problem']}  [{args.out / name / f['file']}; {'; '.join(f['ops'])}]",
                  flush=True)
    print(f"total failures: {bad}")
    return 1 if bad else 0


if __name__ == "__main__":
    raise SystemExit(main())
