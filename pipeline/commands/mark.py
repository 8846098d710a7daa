"""`ridgeloc mark FLIGHT.yaml`: write an offline HTML page to mark targets on frames of the flight (issue 21)."""

from __future__ import annotations

import argparse
from pathlib import Path

HELP = "write an HTML page showing frames of a flight, to click targets and save the marks CSV (marks_file:)"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("config", metavar="FLIGHT.yaml", help="a flight config (YAML)")
    parser.add_argument("-o", "--output", default=None,
                        help="the page to write (default: marks.html beside the flight config)")
    parser.add_argument("--frames", type=int, nargs="+", default=None,
                        help="frame numbers to show (default: up to --max-frames observation frames, evenly spread)")
    parser.add_argument("--max-frames", type=int, default=6, help="how many observation frames by default (6)")


def main(args) -> int:
    import numpy as np

    from pipeline.atomic import atomic_write_text
    from pipeline.commands import not_a_config, output_file
    from pipeline.errors import ConfigError, InputError
    from pipeline.flight import Flight
    from pipeline.flight_config import load_flight_config
    from pipeline.report.mark_page import mark_page
    from pipeline.targets import flight_targets

    # a folder or a file in the page's way is refused before the video is read
    out = output_file(args.output or Path(args.config).resolve().parent / "marks.html", "marks.html")
    try:
        config = load_flight_config(args.config)
    except InputError as exc:
        raise not_a_config(args.config) or exc from None
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
        images = flight.decoder(wanted)
    atomic_write_text(out, mark_page(images, f"ridgeloc mark: {config.name}", known))
    print(f"wrote {out} ({len(images)} frame(s)); open it in a browser, click the targets and save marks.csv, "
          "then set `marks_file: marks.csv` in the flight config")
    return 0
