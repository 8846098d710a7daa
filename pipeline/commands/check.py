"""`ridgeloc check CONFIG`: resolve a flight config against its data and check its geometry (a dry run)."""

from __future__ import annotations

import argparse
import json
import sys

HELP = ("dry-run a flight config: what each role comes from, spans and overlap, and geometry checks that name the "
        "config lines fixing a wrong convention")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("config", metavar="CONFIG", help="a flight config (YAML)")
    parser.add_argument("--json", action="store_true", help="print one JSON document instead of text")
    parser.add_argument("--no-clock", action="store_true",
                        help="skip the clock offset estimate (it tracks the target through the frames: the slow part)")


def main(args) -> int:
    from pipeline.flight_config import load_flight_config

    config = load_flight_config(args.config)  # a mistake in the config is refused before the heavy imports below
    from pipeline.check.report import check_flight, format_check

    result = check_flight(config, clock=not args.no_clock)
    if args.json:
        print(json.dumps(result.to_dict(), indent=1))
    else:
        print(format_check(result))
    for p in result.problems:
        if args.json:
            print(f"ridgeloc: problem: {p}", file=sys.stderr)
    return 1 if result.problems else 0
