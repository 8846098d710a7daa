"""End-to-end zoo flights (issue 19, docs/zoo.md): synthesise continuous-video flights with long focal lengths
(configs/synth/e2e_*.yaml: fx 8,000-12,000 px), run each through `ridgeloc run` (video, tracking, telemetry,
sync, every estimator) as a user would, with the flight config `ridgeloc synth` writes (what an operator knows),
and print every method's error, mle's normalized error e^T C^-1 e and the no-catastrophe rule (mle <= 2 x
median(the other methods' errors) + 5 m).

    python scripts/e2e_flights.py [--out /tmp/ridgeloc_e2e] [--reuse] [--only NAME,...] [--json OUT]

Each flight is synthesised into OUT/<group> (kept; --reuse skips flights already there) and run into
OUT/run/<group> (always redone, so that the figures are this checkout's).
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from pipeline.solve.uncertainty import CHI2_3_95  # noqa: E402
from pipeline.solve_options import METHODS  # noqa: E402


def _ridgeloc(*args: str) -> float:
    """Runs `python -m pipeline ARGS` from this checkout; wall seconds. Raises on failure with its stderr."""
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    t = time.perf_counter()
    p = subprocess.run([sys.executable, "-m", "pipeline", *args], cwd=REPO, env=env, capture_output=True, text=True)
    if p.returncode != 0:
        raise RuntimeError(f"ridgeloc {' '.join(args)} failed: {(p.stderr or p.stdout).strip()[-400:]}")
    return time.perf_counter() - t


def flight_row(group: str, run_dir: Path) -> dict:
    """Every method's error (m), mle's e^T C^-1 e and the rule, from a run's estimates.json and observations.json."""
    est = json.loads((run_dir / group / "estimates.json").read_text())
    obs = json.loads((run_dir / group / "observations.json").read_text())
    truth = np.array(obs["truth_m"]) if obs.get("truth_m") is not None else None
    errors = {m: e["error_m"] for m, e in est["estimates"].items() if e.get("error_m") is not None}
    row = {"group": group, "n": len(obs["observations"]),
           "pixels": sum(o.get("pixel") is not None for o in obs["observations"]),
           "ranges": sum(o.get("range_m") is not None for o in obs["observations"]),
           "errors_m": errors, "unsolved": {m: u.get("status") for m, u in est.get("unsolved", {}).items()}}
    mle = est["estimates"].get("mle")
    row["mle_nees"] = None
    if mle and truth is not None and mle.get("covariance_m2") is not None:
        e = np.array(mle["position_m"]) - truth
        row["mle_nees"] = float(e @ np.linalg.solve(np.array(mle["covariance_m2"]), e))
    others = [v for m, v in errors.items() if m != "mle"]
    row["bound_m"] = 2 * statistics.median(others) + 5.0 if others else None
    row["catastrophe"] = "mle" not in errors or (row["bound_m"] is not None and errors["mle"] > row["bound_m"])
    return row


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="/tmp/ridgeloc_e2e", help="synthesised flights and runs (default "
                    "/tmp/ridgeloc_e2e)")
    ap.add_argument("--reuse", action="store_true", help="do not synthesise flights already in OUT")
    ap.add_argument("--only", help="comma-separated groups (default: every configs/synth/e2e_*.yaml)")
    ap.add_argument("--json", metavar="OUT", help="write the rows as JSON")
    args = ap.parse_args(argv)
    out = Path(args.out)
    configs = sorted((REPO / "configs" / "synth").glob("e2e_*.yaml"))
    if args.only:
        wanted = set(args.only.split(","))
        configs = [c for c in configs if c.stem in wanted]
    rows = []
    for cfg in configs:
        group = cfg.stem
        flight = out / group
        try:
            synth_s = 0.0
            if not (args.reuse and (flight / "flight.yaml").exists()):
                synth_s = _ridgeloc("synth", str(cfg), "-o", str(flight), "--overwrite")
            run_s = _ridgeloc("run", str(flight / "flight.yaml"), "-o", str(out / "run"), "--force", "--no-figures",
                              "--quiet")
            row = flight_row(group, out / "run")
        except (RuntimeError, OSError, KeyError, ValueError) as exc:  # a batch goes on past one bad flight
            print(f"{group}: {exc}", flush=True)
            rows.append({"group": group, "failed": str(exc)})
            continue
        row.update({"synth_s": round(synth_s, 1), "run_s": round(run_s, 1)})
        rows.append(row)
        errs = "  ".join(f"{m} {row['errors_m'][m]:.1f}" for m in METHODS if m in row["errors_m"])
        unsolved = ", ".join(f"{m} ({s})" for m, s in row["unsolved"].items())
        nees = "-" if row["mle_nees"] is None else f"{row['mle_nees']:.2f}"
        inside = row["mle_nees"] is not None and row["mle_nees"] <= CHI2_3_95
        print(f"{group}: n {row['n']} ({row['pixels']} pixels, {row['ranges']} ranges); errors m: {errs}"
              + (f"; unsolved: {unsolved}" if unsolved else "")
              + f"; mle e^T C^-1 e {nees} ({'inside' if inside else 'OUTSIDE'} the 95 % ellipsoid)"
              + ("; no other method solved: no bound" if row["bound_m"] is None else
                 f"; bound {row['bound_m']:.1f} m: {'CATASTROPHE' if row['catastrophe'] else 'ok'}")
              + f"; synth {synth_s:.0f} s, run {run_s:.0f} s", flush=True)
    if args.json:
        Path(args.json).write_text(json.dumps(rows, indent=1))
    return 0 if rows and not any("failed" in r for r in rows) else 1


if __name__ == "__main__":
    raise SystemExit(main())
