"""What `ridgeloc check` and `ridgeloc run` say about each convention mistake of pipeline/synth/conventions.py:
writes the small flights (once, into --workdir), then prints the Markdown table of docs/check.md.

    python scripts/check_conventions.py [--workdir out/check_conventions] [--no-run]
"""

from __future__ import annotations

import argparse
from pathlib import Path


def main(argv=None) -> int:
    from pipeline.check.report import check_flight
    from pipeline.errors import RidgelocError
    from pipeline.flight_config import load_flight_config
    from pipeline.run import process_group
    from pipeline.synth.conventions import CASES, case_config, write_flights

    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--workdir", default="out/check_conventions")
    ap.add_argument("--no-run", action="store_true", help="only `check`, not `run`")
    args = ap.parse_args(argv)
    flights = write_flights(Path(args.workdir))
    print("| case | data written as | config mistake | `ridgeloc check` | cluster as configured -> with the fix | "
          "`ridgeloc run` |")
    print("|---|---|---|---|---|---|")
    for case in CASES:
        cfg = load_flight_config(case_config(flights[case.flight], case))
        res = check_flight(cfg, clock=False)
        c = res.geometry.cluster
        alt = res.geometry.alternatives
        spread = "-" if c is None else f"{c.spread_m:,.0f} m" + (f" -> {alt[0].cluster.spread_m:,.0f} m" if alt
                                                                 else "")
        said = "; ".join(res.problems) or "consistent"
        ran = ""
        if not args.no_run:
            try:
                r = process_group(cfg)
                ran = f"ok, mle error {r.errors_m().get('mle', float('nan')):.1f} m"
            except RidgelocError as exc:
                ran = "refused: " + str(exc).split(": ", 1)[1]
        print(f"| {case.name} | {case.flight} | {case.mistake or '(none)'} | {said} | {spread} | {ran} |".replace(
            "\n", " "), flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
