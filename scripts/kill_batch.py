"""Kill `ridgeloc run` with SIGKILL at random moments and check that nothing half-written is trusted.

    nice -n 10 python scripts/kill_batch.py --kills 20

A batch of --flights copies of sample flight group6 is run once cleanly (the reference). Then, --kills times:
a fresh output folder, `ridgeloc run` started and its whole process group SIGKILLed at a random moment within
the reference run's duration; the folder is checked (every group folder under its final name is finished and
loads; no run-level file is partial), then `ridgeloc run` is run again to the end and must exit 0 with a
targets.csv byte-identical to the reference's. Prints one line per kill and "N of K" at the end.
"""

from __future__ import annotations

import argparse
import csv
import io
import json
import os
import random
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import yaml

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from pipeline.atomic import TMP_PREFIX, is_done  # noqa: E402


def make_batch(folder: Path, n: int) -> Path:
    """A manifest of n copies of configs/flights/group6.yaml with absolute paths."""
    src = ROOT / "configs" / "flights" / "group6.yaml"
    base = src.parent
    paths = []
    for i in range(n):
        doc = yaml.safe_load(src.read_text())
        doc["files"] = {k: [str((base / p).resolve()) for p in v] if isinstance(v, list)
                        else str((base / v).resolve()) for k, v in doc["files"].items()}
        doc["truth_file"] = str((base / doc["truth_file"]).resolve())
        doc["name"] = f"flight{i:02d}"
        p = folder / "flights" / f"flight{i:02d}.yaml"
        p.parent.mkdir(parents=True, exist_ok=True)
        p.write_text(yaml.safe_dump(doc, sort_keys=False))
        paths.append(str(p))
    manifest = folder / "manifest.yaml"
    manifest.write_text(yaml.safe_dump(paths))
    return manifest


def command(manifest: Path, out: Path, args) -> list[str]:
    cmd = [sys.executable, "-m", "pipeline", "run", str(manifest), "-o", str(out), "-q", "--workers", str(args.workers)]
    return cmd + ([] if args.figures else ["--no-figures"])


def untrusted_leftovers(out: Path) -> list[str]:
    """What a re-run might trust although it is incomplete: group folders without their finished marker, or a
    run-level file that does not parse."""
    problems = []
    if not out.exists():
        return problems
    for p in out.iterdir():
        if p.name.startswith(TMP_PREFIX):
            continue  # hidden temporaries: removed by the next run, never read
        if p.is_dir() and not is_done(p):
            problems.append(f"{p.name}/ has no finished marker")
        elif p.is_dir() and not (p / "estimates.json").is_file():
            problems.append(f"{p.name}/ is marked finished without estimates.json")
        elif p.name == "targets.csv":
            rows = list(csv.reader(io.StringIO(p.read_text())))
            if not rows or any(len(r) != len(rows[0]) for r in rows):
                problems.append("targets.csv is partial")
        elif p.suffix in (".json", ".geojson"):
            try:
                json.loads(p.read_text())
            except ValueError:
                problems.append(f"{p.name} is partial")
    return problems


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--kills", type=int, default=20)
    ap.add_argument("--flights", type=int, default=4)
    ap.add_argument("--workers", type=int, default=1)
    ap.add_argument("--figures", action="store_true", help="also render figures (slower, more files per group)")
    ap.add_argument("--seed", type=int, default=None)
    ap.add_argument("--keep", type=Path, default=None, help="work in this folder and keep it")
    args = ap.parse_args(argv)
    seed = args.seed if args.seed is not None else int(time.time())
    rng = random.Random(seed)
    work = args.keep or Path(tempfile.mkdtemp(prefix="kill-batch-"))
    work.mkdir(parents=True, exist_ok=True)
    manifest = make_batch(work, args.flights)

    ref = work / "reference"
    t0 = time.monotonic()
    subprocess.run(command(manifest, ref, args), check=True, capture_output=True, cwd=ROOT)
    duration = time.monotonic() - t0
    reference = (ref / "targets.csv").read_bytes()
    print(f"seed {seed}; reference run of {args.flights} flights: {duration:.1f} s", flush=True)

    ok = 0
    for k in range(args.kills):
        out = work / f"run{k:02d}"
        delay = rng.uniform(0.02, 0.98) * duration
        for _attempt in range(4):  # the machine's load varies: a run that ends before its kill is run again
            shutil.rmtree(out, ignore_errors=True)
            proc = subprocess.Popen(command(manifest, out, args), cwd=ROOT, stdout=subprocess.DEVNULL,
                                    stderr=subprocess.DEVNULL, start_new_session=True)
            time.sleep(delay)
            finished_before_kill = proc.poll() is not None
            if not finished_before_kill:
                os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
            if not finished_before_kill:
                break
            delay *= 0.5
        done_before = sorted(p.name for p in out.glob("flight*") if is_done(p)) if out.exists() else []
        problems = untrusted_leftovers(out)
        rerun = subprocess.run(command(manifest, out, args), capture_output=True, text=True, cwd=ROOT)
        same = (out / "targets.csv").is_file() and (out / "targets.csv").read_bytes() == reference
        good = not problems and rerun.returncode == 0 and same and not finished_before_kill
        ok += good
        state = "run had finished before the kill" if finished_before_kill else f"killed at {delay:.1f} s"
        print(f"kill {k + 1:2d}: {state}, {len(done_before)} of {args.flights} flights finished before; "
              f"leftovers trusted: {problems or 'none'}; re-run exit {rerun.returncode}, targets.csv "
              f"{'identical' if same else 'DIFFERENT'}" + ("" if good else "  <-- FAIL"), flush=True)
        if rerun.returncode != 0:
            print("    " + rerun.stderr.strip().replace("\n", "\n    "), flush=True)
        shutil.rmtree(out, ignore_errors=True)
    print(f"{ok} of {args.kills} killed batches complete on re-run with identical targets.csv")
    if args.keep is None:
        shutil.rmtree(work, ignore_errors=True)
    return 0 if ok == args.kills else 1


if __name__ == "__main__":
    raise SystemExit(main())
