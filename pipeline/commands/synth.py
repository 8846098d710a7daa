"""`ridgeloc synth CONFIG -o DIR`: generate a synthetic flight (video, telemetry, laser, truth.json) from a YAML
config (see configs/synth/ and docs/synth.md), with DIR/flight.yaml, its flight config for `ridgeloc run`."""

from __future__ import annotations

import argparse
from pathlib import Path

from pipeline.commands import output_folder
from pipeline.errors import InputError

HELP = "generate a synthetic flight (video + telemetry + laser + ground truth) from a YAML config"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("config", nargs="?", help="flight config YAML (e.g. configs/synth/example.yaml); not with "
                                                  "--photos")
    parser.add_argument("-o", "--output", required=True, help="output folder for the flight (must not exist)")
    parser.add_argument("--overwrite", action="store_true", help="replace the output folder if it exists")
    parser.add_argument("--seed", type=int, help="override the config's noise seed")
    parser.add_argument("--video", choices=("bursts", "continuous"),
                        help="override video.mode: bursts around observations, or continuous 25 Hz video")
    parser.add_argument("--format", choices=("tlog", "ros1", "ros2-sqlite3", "ros2-mcap", "mcap", "klv"),
                        help="override the telemetry format")
    photos = parser.add_argument_group("photo flights (pipeline/synth/photos.py, docs/locate.md)")
    photos.add_argument("--photos", type=int, metavar="N", help="write a DJI photo flight of N photos instead")
    photos.add_argument("--no-laser", action="store_true", help="photos without LRF tags (a consumer drone)")
    photos.add_argument("--dem", action="store_true", help="the target on synthetic hills, with their GeoTIFF dem.tif")


def _photo_flight(args) -> int:
    import shutil

    from pipeline.synth.photos import PhotoFlightSpec, write_photo_sample

    out = Path(args.output)
    if out.exists():
        if not args.overwrite:
            raise InputError("output folder exists (use --overwrite)", out)
        shutil.rmtree(out)
    spec = PhotoFlightSpec(seed=args.seed or 0, n_photos=args.photos, laser=not args.no_laser,
                           mark_offset_px=0.0 if not args.no_laser else 150.0)
    flight = write_photo_sample(out, spec, dem=args.dem)
    t = flight.truth
    print(f"{args.photos} photos ({'with' if spec.laser else 'without'} laser), compass bias "
          f"{t['compass_bias_deg']:+.2f} deg, altitude datum offset {t['datum_offset_m']:+.1f} m -> {out}")
    print(f"locate it: ridgeloc locate {out} --marks {out / 'marks.csv'}" + (f" --dem {out / 'dem.tif'}"
                                                                            if args.dem else ""))
    return 0


def main(args) -> int:
    import dataclasses

    output_folder(args.output)  # a file there is refused, even with --overwrite
    if args.photos is not None:
        if args.config is not None:
            raise InputError("give a config or --photos, not both")
        if args.photos < 1:
            raise InputError(f"--photos must be at least 1, got {args.photos}")
        return _photo_flight(args)
    if args.config is None:
        raise InputError("give a flight config YAML (or --photos N)")

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
    res = generate(cfg, out, overwrite=args.overwrite, write_flight_config=True)
    print(f"{cfg.group}: {res.n_observations} observations, intersection angle {res.intersection_angle_deg:.2f} deg, "
          f"{res.n_frames} frames, {cfg.format} -> {out} ({res.seconds:.1f} s)")
    if res.flight_config is not None:
        print(f"run it: ridgeloc run {res.flight_config} -o OUTDIR")
    else:
        print("no flight.yaml: the target is visible in no observation frame, so there is no mark to give")
    return 0
