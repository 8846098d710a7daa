#!/usr/bin/env python
"""What each of issue 40's speed changes costs and buys, side by side on one flight: `ridgeloc run`'s work
(`pipeline.run.process_group`) in a fresh process per variant, the variants taken in turn `--repeats` times,
medians printed (wall s, CPU s, peak RSS MiB, decode / track stage wall s, the tracked pixels' distance from the
true target pixel, the MLE's error).

    python scripts/bench_video.py --seconds 60 --workdir /tmp/bv60          # makes the 4K flight
    python scripts/bench_video_ablation.py /tmp/bv60/flight.yaml --repeats 3

Variants (each switches off one change of today's reader/tracker, by a config key or by patching it in the
child only):
  today            the defaults
  no re-anchoring  the homography chain not re-anchored on the refined pixel (`SiftTracker._reanchor` a no-op)
  shot frames      observations at the laser shots' own frames (observations.at_key_frames: false)
  whole frame      features on the whole frame reduced to 960 px, not in a window (tracking.detect_window_px: 0)
  first round      all three of the above switched back: the plan and tracker of issue 40's first round
  sift 1280 px     that, with features on the frame reduced to 1280 px (tracking.max_detect_px, the old default)
  no prefetch      that, with frames decoded one at a time when the tracker asks (no worker threads ahead)
  before           the last two, frames decoded as BGR then made grey, and a frame cache kept for every flight
                   (the reader and tracker before issue 40)
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

VARIANTS = ("today", "no re-anchoring", "shot frames", "whole frame", "first round", "sift 1280 px", "no prefetch",
            "before")

CHILD = r"""
import dataclasses, json, sys, time
import numpy as np
sys.path.insert(0, sys.argv[3])
variant = sys.argv[2]
from pipeline.flight_config import load_run_config
import pipeline.ingest.video as video
import pipeline.flight.frames as frames
import pipeline.run as run
cfg = load_run_config(sys.argv[1])[0].config
if variant not in ("today", "shot frames", "whole frame"):
    import pipeline.track.sift as sift
    sift.SiftTracker._reanchor = staticmethod(lambda H, predicted_px, found_px: H)
if variant not in ("today", "no re-anchoring", "whole frame"):
    cfg = dataclasses.replace(cfg, observations=dataclasses.replace(cfg.observations, at_key_frames=False))
if variant not in ("today", "no re-anchoring", "shot frames"):
    cfg = dataclasses.replace(cfg, tracking=dataclasses.replace(cfg.tracking, detect_window_px=0))
if variant in ("sift 1280 px", "before"):
    cfg = dataclasses.replace(cfg, tracking=dataclasses.replace(cfg.tracking, max_detect_px=1280))
if variant in ("no prefetch", "before"):
    video.VideoFrames.prefetch = lambda self, order, **kw: None
if variant == "before":  # BGR frames made grey, frame threads, and every frame kept in a cache, as before
    real = video.VideoFrames.__init__
    def bgr(self, path, seek_after=None, gray=False, index=None, thread_type="AUTO"):
        real(self, path, seek_after=seek_after, gray=False, index=index, thread_type="AUTO")
    video.VideoFrames.__init__ = bgr
    unbounded = run.ViewCache
    run.ViewCache = lambda share_matches=False: unbounded(share_matches, max_bytes=2**62)
    class FP(run.FlightPass):
        def __init__(self, flight, plan, origin, tracker, cache, **kw):
            super().__init__(flight, plan, origin, tracker, cache if cache is not None else run.ViewCache(), **kw)
    run.FlightPass = FP
t, c = time.perf_counter(), time.process_time()
r = run.process_group(cfg)
wall, cpu = time.perf_counter() - t, time.process_time() - c
sys.path.insert(0, sys.argv[4])
import bench_video as bv
gen = json.loads((__import__("pathlib").Path(sys.argv[1]).parent / "generate.json").read_text())
px = bv.pixel_errors(r.tracking, gen["seconds"])
print(json.dumps({"wall_s": wall, "cpu_s": cpu, "decode_s": r.timings_s.get("decode"),
                  "track_s": r.timings_s.get("track"), "px_median": float(np.median(px)) if px.size else None,
                  "tracked": int(px.size), "px_p95": float(np.percentile(px, 95)) if px.size else None,
                  "mle_m": r.errors_m().get("mle"), "ridge_m": r.errors_m().get("ridge")}))
"""


def _one(cfg: str, variant: str) -> dict:
    proc = subprocess.Popen([sys.executable, "-c", CHILD, cfg, variant, str(ROOT), str(ROOT / "scripts")], cwd=ROOT,
                            stdout=subprocess.PIPE, text=True)
    out = proc.stdout.read()
    _, status, ru = os.wait4(proc.pid, 0)
    if os.waitstatus_to_exitcode(status):
        raise SystemExit(f"variant {variant!r} failed")
    doc = json.loads(out.strip().splitlines()[-1])
    doc["peak_mib"] = ru.ru_maxrss / 1024.0
    return doc


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("config", help="a flight made by scripts/bench_video.py (its flight.yaml)")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--variants", nargs="+", default=list(VARIANTS), choices=VARIANTS)
    args = ap.parse_args(argv)
    print(f"load average before: {' '.join(f'{v:.2f}' for v in os.getloadavg())}", flush=True)
    runs: dict[str, list[dict]] = {v: [] for v in args.variants}
    for k in range(args.repeats):
        for v in args.variants:
            runs[v].append(_one(args.config, v))
            print(f"  {k + 1}/{args.repeats} {v}: {runs[v][-1]}", flush=True)
    keys = ("wall_s", "cpu_s", "peak_mib", "decode_s", "track_s", "px_median", "px_p95", "mle_m", "ridge_m")
    print(f"{'variant':<26} " + " ".join(f"{k:>10}" for k in keys) + "   (medians)")
    for v, rs in runs.items():
        med = {k: statistics.median(r[k] for r in rs if r[k] is not None) for k in keys}
        print(f"{v:<26} " + " ".join(f"{med[k]:>10.3f}" for k in keys))
    print(f"load average after: {' '.join(f'{v:.2f}' for v in os.getloadavg())}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
