"""`ridgeloc run [CONFIG] [-o OUTDIR]`: process flight groups end to end into a Table-4-like report."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import cv2

from pipeline.errors import RidgelocError
from pipeline.flight_config import load_run_config
from pipeline.results import GroupFailure

HELP = "process flights (video, telemetry, ranges) into target positions and a Table-4-like report"
DEFAULT_CONFIG = Path("configs/sample.yaml")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("config", nargs="?", default=str(DEFAULT_CONFIG),
                        help="run config listing flight configs under `groups:`, or one flight config "
                             f"(default: {DEFAULT_CONFIG}, the bundled sample flights)")
    parser.add_argument("-o", "--outdir", default="out", help="output folder (default: out)")
    parser.add_argument("-q", "--quiet", action="store_true", help="print only errors")


def main(args) -> int:
    from pipeline.report.table4 import write_table4
    from pipeline.run import process_group, write_group_outputs

    config = Path(args.config)
    if args.config == str(DEFAULT_CONFIG) and not config.exists():
        # The bundled sample config of this checkout, when ridgeloc runs from another folder.
        bundled = Path(__file__).resolve().parents[2] / DEFAULT_CONFIG
        config = bundled if bundled.exists() else config
    entries = load_run_config(config)
    results, failures = [], []
    for entry in entries:
        name = entry.config.name if entry.config is not None else Path(entry.source).stem
        if entry.config is None:
            failures.append(GroupFailure(name, entry.source, entry.error))
            print(f"ridgeloc: {name}: skipped: {entry.error}", file=sys.stderr)
            continue
        try:
            result = process_group(entry.config)
            write_group_outputs(args.outdir, result)
        except (RidgelocError, OSError, cv2.error) as exc:  # one bad flight must not stop the others
            failures.append(GroupFailure(name, entry.source, str(exc)))
            print(f"ridgeloc: {name}: failed: {exc}", file=sys.stderr)
            continue
        results.append(result)
        if not args.quiet:
            errs = result.errors_m()
            shown = ", ".join(f"{m} {errs[m]:.2f} m" for m in ("ridge", "mle") if errs.get(m) is not None)
            print(f"{name}: {result.n_observations} observations, {sum(result.timings_s.values()):.2f} s"
                  + (f", error {shown}" if shown else ""))
    md, tab = write_table4(args.outdir, results, failures)
    if not args.quiet:
        print(f"wrote {md} and {tab}" + (f"; {len(failures)} group(s) failed" if failures else ""))
    return 1 if failures else 0
