"""Check a run folder's TAK outputs against what they were made from (docs/outputs.md, "For TAK users"):

    python scripts/check_tak_outputs.py OUT [OUT2]

For every event of OUT/cot/: its point against targets.csv (lat/lon to 1e-7 deg, hae to 1 cm) and against the
answer's ENU position in OUT/<flight>/result.json converted with pymap3d; its ce and le against CE90 integrated
from the answer's covariance and 1.6449 sigma of its height (within 0.1 % + 1 cm); one event per located row of
targets.csv; OUT/targets.zip read as ATAK imports a data package (every event listed). With OUT2 (another run of
the same flights), the uids of both. Prints a line per event and a verdict; exit status 1 on any mismatch.
The comparisons are test support (tests/support/tak.py), shared with tests/test_tak_outputs.py.
"""

from __future__ import annotations

import csv
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT), str(ROOT / "tests")]  # this checkout's pipeline; test support (support.tak)

from support.tak import atak_import, compare_run_events  # noqa: E402


def main(argv: list[str]) -> int:
    out = Path(argv[0])
    report = compare_run_events(out)
    located = [r for r in csv.DictReader((out / "targets.csv").open()) if r["status"] == "located"]
    bad = []
    print(f"{'target':26s} {'dlat csv':>9s} {'dlon csv':>9s} {'dhae csv':>8s} {'dlat ans':>9s} {'dhae ans':>8s} "
          f"{'ce':>7s} {'CE90':>8s} {'le':>7s} {'LE90':>8s}")
    for r in report:
        ok = (max(r["d_lat_csv_deg"], r["d_lon_csv_deg"], r["d_lat_answer_deg"], r["d_lon_answer_deg"]) <= 1e-7
              and max(r["d_hae_csv_m"], r["d_hae_answer_m"]) <= 0.01
              and abs(r["ce"] - r["ce90_m"]) <= 1e-3 * r["ce90_m"] + 0.01
              and abs(r["le"] - r["le90_m"]) <= 1e-3 * r["le90_m"] + 0.01)
        print(f"{r['name']:26s} {r['d_lat_csv_deg']:9.1e} {r['d_lon_csv_deg']:9.1e} {r['d_hae_csv_m']:8.4f} "
              f"{max(r['d_lat_answer_deg'], r['d_lon_answer_deg']):9.1e} {r['d_hae_answer_m']:8.4f} "
              f"{r['ce']:7.2f} {r['ce90_m']:8.3f} {r['le']:7.2f} {r['le90_m']:8.3f}" + ("" if ok else "  MISMATCH"))
        if not ok:
            bad.append(r["name"])
    if sorted(r["name"] for r in report) != sorted(r["name"] for r in located):
        bad.append("events != located rows of targets.csv")
    imported = atak_import((out / "targets.zip").read_bytes())
    if set(imported["events"]) != {r["uid"] for r in report}:
        bad.append("targets.zip does not list every event")
    print(f"{len(report)} events for {len(located)} located targets; targets.zip: {len(imported['events'])} events "
          f"listed, package uid {imported['uid']}")
    if len(argv) > 1:
        other = {r["name"]: r["uid"] for r in compare_run_events(Path(argv[1]))}
        same = {r["name"]: r["uid"] for r in report} == other
        print(f"uids of {argv[0]} and {argv[1]}: {'the same' if same else 'DIFFERENT'}")
        if not same:
            bad.append("uids differ")
    print("OK" if not bad else "FAILED: " + "; ".join(bad))
    return 1 if bad else 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
