"""`ridgeloc inspect LOG...`: what each log, bag or video holds and what is missing for localization."""

from __future__ import annotations

import argparse
import json
import sys

HELP = "summarise flight logs, bags and videos: streams, counts, rates, spans, and what localization lacks"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("logs", nargs="+", metavar="LOG",
                        help="telemetry logs (.tlog .bin .ulg .bag .mcap .SRT), ROS 2 bag folders, videos, drone "
                             "photos (.jpg, or a folder of them), a flight "
                             "folder (all of those in it), or one flight config (.yaml): the roles it resolves to "
                             "(`ridgeloc check` adds the geometry checks)")
    parser.add_argument("--json", action="store_true", help="print one JSON document instead of tables")


def _inspect_config(path: str, as_json: bool) -> int:
    from pipeline.check.flight import mapping_lines
    from pipeline.flight import Flight
    from pipeline.flight_config import load_flight_config

    config = load_flight_config(path)
    if config.files.photos:  # a photo flight: what its photos state
        doc, errors = _inspect_photos(list(config.files.photos), as_json)
        for e in errors:
            print(f"ridgeloc: error: {e}", file=sys.stderr)
        if as_json:
            print(json.dumps({"config": path, **doc}, indent=2))
        return 1 if errors else 0
    with Flight.open(config) as flight:
        lines = mapping_lines(flight)
    print(json.dumps({"config": path, "mapping": lines}, indent=2) if as_json else "\n".join(lines))
    return 0


def _inspect_photos(paths: list[str], as_json: bool) -> tuple[dict, list[str]]:
    """What each drone photo states (printed as text unless as_json, else returned as a dict for the one JSON
    document), and the one-line errors of the unreadable ones."""
    from pipeline.ingest.photo import read_photos
    from pipeline.ingest.photo_inspect import format_photo, photo_as_dict

    photos, bad = read_photos(paths)
    if not as_json:
        for p in photos:
            print(format_photo(p))
            print()
    return ({"photos": [photo_as_dict(p) for p in photos], "errors": [{"path": p, "error": e} for p, e in bad]},
            [e for _, e in bad])


def main(args) -> int:
    from pipeline.ingest.inspect import combined_missing, format_result, inspect_paths, result_as_dict
    from pipeline.ingest.photo_inspect import is_photo_input

    if len(args.logs) == 1 and args.logs[0].lower().endswith((".yaml", ".yml")):
        return _inspect_config(args.logs[0], args.json)
    photo_inputs = [p for p in args.logs if is_photo_input(p)]
    photo_doc, photo_errors = {}, []
    if photo_inputs:  # drone photos (docs/ingest.md, "Drone photos"); logs named with them are inspected after
        photo_doc, photo_errors = _inspect_photos(photo_inputs, args.json)
        for e in photo_errors:
            print(f"ridgeloc: error: {e}", file=sys.stderr)
    logs = [p for p in args.logs if p not in photo_inputs]
    if not logs:
        if args.json:
            print(json.dumps(photo_doc, indent=2))
        return 1 if photo_errors else 0
    results = inspect_paths(logs)
    if args.json:
        doc = {"files": [result_as_dict(r) for r in results],
               "missing_for_localization_together": combined_missing(results), **photo_doc}
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
    return 1 if failed or photo_errors else 0
