"""`ridgeloc synth CONFIG -o DIR`: generate a synthetic flight (video, telemetry, laser, truth.json) from a YAML
config (see configs/synth/ and docs/synth.md), with DIR/flight.yaml, its flight config for `ridgeloc run`."""

from __future__ import annotations

import argparse
from pathlib import Path

from pipeline.errors import InputError

HELP = "generate a synthetic flight (video + telemetry + laser + ground truth) from a YAML config"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("config", help="flight config YAML (e.g. configs/synth/example.yaml)")
    parser.add_argument("-o", "--output", required=True, help="output folder for the flight (must not exist)")
    parser.add_argument("--overwrite", action="store_true", help="replace the output folder if it exists")
    parser.add_argument("--seed", type=int, help="override the config's noise seed")
    parser.add_argument("--video", choices=("bursts", "continuous"),
                        help="override video.mode: bursts around observations, or continuous 25 Hz video")
    parser.add_argument("--format", choices=("tlog", "ros1", "ros2-sqlite3", "ros2-mcap", "mcap", "klv"),
                        help="override the telemetry format")


def main(args) -> int:
    import dataclasses

    from pipeline.synth.config import SynthConfig
    from pipeline.synth.flight import generate

    cfg = SynthConfig.load(args.config)
    changes = {}
    if args.seed is not None:
        changes["seed"] = args.seed
    if args.format is not None:
        changes["format"] = args.format
        if args.format in ("tlog", "mcap") and cfg.video.images_in_bag:
            changes["video"] = dataclasses.replace(cfg.video, images_in_bag=False)
    if args.video is not None:
        changes["video"] = dataclasses.replace(changes.get("video", cfg.video), mode=args.video)
    if changes:
        cfg = cfg.replace(**changes)
    out = Path(args.output)
    if out.exists() and not out.is_dir():
        raise InputError("output exists and is not a folder", out)
    res = generate(cfg, out, overwrite=args.overwrite, write_flight_config=True)
    print(f"{cfg.group}: {res.n_observations} observations, intersection angle {res.intersection_angle_deg:.2f} deg, "
          f"{res.n_frames} frames, {cfg.format} -> {out} ({res.seconds:.1f} s)")
    if res.flight_config is not None:
        print(f"run it: ridgeloc run {res.flight_config} -o OUTDIR")
    else:
        print("no flight.yaml: the target is visible in no observation frame, so there is no mark to give")
    return 0
