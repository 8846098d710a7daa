"""`ridgeloc mark FLIGHT.yaml | PHOTO...`: write an offline HTML page to mark targets on frames of a video flight
(issue 21), or in drone photos (a folder, photos, or a photo flight config: issue 41)."""

from __future__ import annotations

import argparse
from pathlib import Path

HELP = ("write an HTML page showing frames of a flight, or drone photos, to click targets and save the marks CSV "
        "(marks_file:, locate --marks)")
#: a photo larger than this (either side, px) is embedded scaled down (clicks still give its own pixels)
PHOTO_MAX_SIDE_PX = 4096


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("config", nargs="+", metavar="FLIGHT.yaml|PHOTO",
                        help="a flight config (YAML, video or photos), or drone photos / a folder of them")
    parser.add_argument("-o", "--output", default=None,
                        help="the page to write (default: marks.html beside the flight config, or in the photos' "
                             "folder)")
    parser.add_argument("--frames", type=int, nargs="+", default=None,
                        help="frame numbers to show (default: up to --max-frames observation frames, evenly spread)")
    parser.add_argument("--max-frames", type=int, default=6, help="how many observation frames by default (6)")


def _photo_page(paths, config, out: Path) -> int:
    """The marking page of photos (files, folders, or a photo flight config's files.photos): each photo keyed by
    its path relative to the page's folder (where marks.csv is to be saved), with the config's known marks."""
    import os

    import cv2
    import numpy as np

    from pipeline.atomic import atomic_write_text
    from pipeline.commands import read_photos_reporting
    from pipeline.errors import InputError
    from pipeline.report.mark_page import mark_page

    photos, bad = read_photos_reporting(paths)
    base = out.resolve().parent
    images, sizes, keys = {}, {}, {}
    for p in photos:
        key = Path(os.path.relpath(Path(p.path).resolve(), base)).as_posix()
        if "," in key or "\n" in key:
            raise InputError("a photo path with a comma cannot be named in the marks CSV: rename it", p.path)
        img = cv2.imread(p.path, cv2.IMREAD_COLOR | cv2.IMREAD_IGNORE_ORIENTATION)  # the stored pixels
        if img is None:
            raise InputError("cannot decode the image (OpenCV)", p.path)
        s = min(1.0, PHOTO_MAX_SIDE_PX / max(img.shape[:2]))
        images[key] = img if s == 1.0 else cv2.resize(img, None, fx=s, fy=s, interpolation=cv2.INTER_AREA)
        sizes[key] = (p.width_px, p.height_px)
        keys[str(Path(p.path).resolve())] = key
    known = []
    if config is not None:
        from pipeline.locate import target_pixels
        from pipeline.targets import flight_targets

        for t in flight_targets(config):
            if t.name is None:
                continue
            px = target_pixels(t, photos)
            known += [{"name": t.name, "frame": keys[str(Path(p.path).resolve())], "x": float(u), "y": float(v)}
                      for p, (u, v) in zip(photos, px, strict=True) if np.isfinite(u)]
    title = f"ridgeloc mark: {config.name if config is not None else base.name}"
    atomic_write_text(out, mark_page(images, title, known, sizes=sizes))
    print(f"wrote {out} ({len(images)} photo(s)); open it in a browser, click the target in every photo that shows "
          f"it and save marks.csv in {base}, then `ridgeloc locate {' '.join(str(p) for p in paths)} --marks "
          f"{base / 'marks.csv'}` (or `marks_file: marks.csv` in a photo flight config)")
    return 1 if bad else 0


def main(args) -> int:
    import numpy as np

    from pipeline.atomic import atomic_write_text
    from pipeline.commands import not_a_config, output_file
    from pipeline.errors import ConfigError, InputError
    from pipeline.flight import Flight
    from pipeline.flight_config import FMV_SUFFIXES, flight_config_for_video, load_flight_config
    from pipeline.ingest.photo_inspect import is_photo_input
    from pipeline.report.mark_page import mark_page
    from pipeline.targets import flight_targets

    paths = [Path(c) for c in args.config]
    if all(is_photo_input(p) for p in paths):
        first = paths[0] if paths[0].is_dir() else paths[0].resolve().parent
        out = output_file(args.output or first / "marks.html", "marks.html")
        return _photo_page(paths, None, out)
    if len(paths) > 1:
        raise InputError(f"give one flight config, or drone photos: {', '.join(map(str, paths))}")
    if paths[0].is_dir() and not (paths[0] / "flight.yaml").is_file():  # mark takes photo folders: say it has none
        raise InputError(f"no drone photos (.jpg, .jpeg files) here, and a folder is not a flight config: `ridgeloc "
                         f"init {paths[0]}` writes one from a flight's files", paths[0])
    clip = paths[0].is_file() and paths[0].suffix.lower() in FMV_SUFFIXES
    # a folder or a file in the page's way is refused before the video is read; a clip's folder may be a
    # read-only archive: its page goes into the current folder
    out = output_file(args.output or (Path("marks.html") if clip else paths[0].resolve().parent / "marks.html"),
                      "marks.html")
    if clip:  # a full-motion video alone, as `run` and `check` take it
        config = flight_config_for_video(paths[0])
    else:
        try:
            config = load_flight_config(paths[0])
        except InputError as exc:
            raise not_a_config(paths[0]) or exc from None
    if config.files.photos:
        return _photo_page(list(config.files.photos), config, out)
    with Flight.open(config) as flight:
        available = set(np.asarray(flight.frames.index).tolist())
        if args.frames:
            wanted = [int(i) for i in args.frames]
            missing = [i for i in wanted if i not in available]
            if missing:
                raise ConfigError(f"--frames: {missing} not frames of the video ({min(available)}..{max(available)})")
        else:
            obs = (flight.plan.frame_index.tolist() if flight.plan is not None else []) or sorted(available)
            k = max(1, min(args.max_frames, len(obs)))
            wanted = sorted({int(obs[round(j * (len(obs) - 1) / max(k - 1, 1))]) for j in range(k)})
        known = [{"name": t.name, "frame": int(m.frame_index), "x": float(m.pixel[0]), "y": float(m.pixel[1])}
                 for t in flight_targets(config) if t.name is not None for m in t.marks if m.template is None]
        wanted = sorted(set(wanted) | {m["frame"] for m in known})
        images = flight.source.colour(wanted)  # in colour: the person marking tells targets apart by it
    atomic_write_text(out, mark_page(images, f"ridgeloc mark: {config.name}", known))
    # init of the clip itself: its folder may hold other clips (init of a folder reads them all as one flight)
    # and may be read-only
    then = (f"then write a flight config for the clip (`ridgeloc init {paths[0].resolve()} -o flight.yaml`) and "
            "set `marks_file: marks.csv` in it") if clip else \
        "then set `marks_file: marks.csv` in the flight config"
    print(f"wrote {out} ({len(images)} frame(s)); open it in a browser, click the targets and save marks.csv, {then}")
    return 0
