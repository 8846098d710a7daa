"""`ridgeloc check CONFIG`: resolve a flight config against its data and check its geometry (a dry run)."""

from __future__ import annotations

import argparse
import json
import sys

HELP = ("dry-run a flight config: what each role comes from, spans and overlap, and geometry checks that name the "
        "config lines fixing a wrong convention")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("config", metavar="CONFIG", help="a flight config (YAML), a full-motion video with KLV or a "
                        "raw KLV dump (ST 0601 or EG 0104)")
    parser.add_argument("--json", action="store_true", help="print one JSON document instead of text")
    parser.add_argument("--no-clock", action="store_true",
                        help="skip the clock offset estimate (it tracks the target through the frames: the slow part)")


def main(args) -> int:
    from pipeline.commands import not_a_config
    from pipeline.errors import InputError
    from pipeline.flight_config import flight_config_for_video, load_flight_config

    kind = _klv_kind(args.config)  # a video or KLV dump given alone
    if kind == "klv":
        return _check_klv_dump(args)
    # a mistake in the config is refused before the heavy imports below
    try:
        config = flight_config_for_video(args.config) if kind == "video" else load_flight_config(args.config)
    except InputError as exc:
        raise not_a_config(args.config) or exc from None
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


def _klv_kind(path) -> str | None:
    """"video" or "klv" when `path` is a video or a raw KLV dump rather than a YAML config, else None."""
    from pathlib import Path

    from pipeline.errors import RidgelocError
    from pipeline.flight_config import FMV_SUFFIXES
    from pipeline.ingest.dispatch import detect_format

    p = Path(path)
    if p.suffix.lower() in (".yaml", ".yml") or not p.is_file():
        return None
    if p.suffix.lower() in FMV_SUFFIXES:
        return "video"
    try:
        return "klv" if detect_format(p) == "klv" else None
    except RidgelocError:  # not a log: read as a config (a YAML file named other than .yaml)
        return None


def _check_klv_dump(args) -> int:
    """A raw KLV dump has no frames to check: the frame-centre check alone."""
    from pipeline.ingest.frame_centre import LARGE_M, check_file, frame_centre_document

    r = check_file(args.config)
    checks = [] if r is None else [(str(args.config), r)]
    problems = [r.line()] if r is not None and r.median_m > LARGE_M else []
    if args.json:
        print(json.dumps({"flight": args.config, "frame_centre": frame_centre_document(checks),
                          "problems": problems}, indent=1))
    else:
        print(r.line() if r is not None else "frame centre: no packet with sensor position, angles, slant range "
              "and frame centre")
    return 1 if problems else 0
