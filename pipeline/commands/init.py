"""`ridgeloc init FOLDER [-o FLIGHT.yaml]`: write the flight config of a folder of flight files (docs/init.md)."""

from __future__ import annotations

import argparse
from pathlib import Path

HELP = ("write a flight config from a folder of flight files (logs, bags, MCAP, video, SRT, KLV video, photos): "
        "what the files state and the data show, and the lines still to fill in")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("folder", metavar="FOLDER", help="the flight's folder (or one file: a full-motion video, a "
                        "log)")
    parser.add_argument("-o", "--output", default=None,
                        help="the flight config to write (default: flight.yaml in FOLDER)")
    parser.add_argument("--overwrite", action="store_true", help="replace the config if it exists")


def main(args) -> int:
    import shlex

    from pipeline.atomic import atomic_write_text
    from pipeline.autoconfig import config_text, draft_flight_config
    from pipeline.commands import output_file
    from pipeline.errors import InputError

    folder = Path(args.folder)
    flight_folder = folder.is_dir() and not (folder / "metadata.yaml").is_file()  # not a ROS 2 bag's folder
    default = (folder if flight_folder else folder.parent) / "flight.yaml"
    out = output_file(args.output or default, "flight.yaml")
    if out.exists() and not args.overwrite:
        raise InputError("exists: give another -o, or --overwrite to replace it", out)
    draft = draft_flight_config(folder, out)
    command = "ridgeloc init " + " ".join(shlex.quote(a) for a in [str(args.folder)] +
                                          (["-o", str(args.output)] if args.output else []))
    atomic_write_text(out, config_text(draft, command))
    print(f"wrote {out}")
    for line in draft.found:
        print(f"  file         {line}")
    for key, how in draft.decisions:
        print(f"  {key:<12} {how}")
    for w in draft.warnings:
        print(f"  warning      {w}")
    for p in draft.problems:
        print(f"  problem      {p}")
    required = [f for f in draft.fill_in if f.required]
    print(f"to fill in ({len(required)}), marked FILL IN in {out.name}:")
    for f in required:
        print(f"  {f.why}")
    for f in draft.fill_in:
        if not f.required:
            print(f"  optional: {f.why}")
    cfg = shlex.quote(str(out))
    first = [f.key for f in required if f.key in ("camera", "clock", "mapping")]
    where = "in every photo that shows it" if "photos" in draft.doc["files"] else ""
    steps = ([f"fill in {' and '.join(first)}"] if first else []) + [
        f"ridgeloc mark {cfg} (click the target{' ' + where if where else ''}; set marks_file: to the saved CSV)",
        f"ridgeloc run {cfg}"]
    print("next: " + ", then ".join(steps))
    return 0
