"""`ridgeloc inspect LOG...`: what each log, bag or video holds and what is missing for localization."""

from __future__ import annotations

import argparse
import json
import sys

HELP = "summarise flight logs, bags and videos: streams, counts, rates, spans, and what localization lacks"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("logs", nargs="+", metavar="LOG",
                        help="telemetry logs (.tlog .bin .ulg .bag .mcap .SRT), ROS 2 bag folders, videos, a flight "
                             "folder (all of those in it), or one flight config (.yaml): the roles it resolves to "
                             "(`ridgeloc check` adds the geometry checks)")
    parser.add_argument("--json", action="store_true", help="print one JSON document instead of tables")


def _inspect_config(path: str, as_json: bool) -> int:
    from pipeline.check.flight import mapping_lines
    from pipeline.flight import Flight
    from pipeline.flight_config import load_flight_config

    with Flight.open(load_flight_config(path)) as flight:
        lines = mapping_lines(flight)
    print(json.dumps({"config": path, "mapping": lines}, indent=2) if as_json else "\n".join(lines))
    return 0


def main(args) -> int:
    from pipeline.ingest.inspect import combined_missing, format_result, inspect_paths, result_as_dict

    if len(args.logs) == 1 and args.logs[0].lower().endswith((".yaml", ".yml")):
        return _inspect_config(args.logs[0], args.json)
    results = inspect_paths(args.logs)
    if args.json:
        doc = {"files": [result_as_dict(r) for r in results],
               "missing_for_localization_together": combined_missing(results)}
        print(json.dumps(doc, indent=2))
    else:
        for r in results:
            if r.log is not None:
                print(format_result(r))
                print()
        for group, missing in combined_missing(results).items():
            what = f"files of {group}" if group else "files named"
            print(f"all {what} together, missing for localization: " + (", ".join(missing) if missing else "nothing"))
    failed = [r for r in results if r.error is not None]
    for r in failed:
        print(f"ridgeloc: error: {r.error}", file=sys.stderr)
    return 1 if failed else 0
