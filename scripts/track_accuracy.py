"""Tracking accuracy: the tracked target pixel against the true projection, per flight group.

    python scripts/track_accuracy.py [CONFIG] [--true-poses]     (default: configs/sample.yaml)

For every group whose flight config has a `truth_file` (a synthetic flight's truth.json), the observation
frames are tracked exactly as `ridgeloc run` tracks them, and each tracked pixel (image pixels, distorted) is
compared with the frame's `true_target_pixel`. Frames where the target is truly visible but was flagged lost, and
frames where it is not visible but was reported, are counted separately. Prints a table and the pooled median
and 95th percentile.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

from pipeline.flight import Flight
from pipeline.flight_config import load_run_config
from pipeline.track.sift import SiftTracker


def track_group(cfg):
    with Flight.open(cfg) as flight:
        tracker = SiftTracker(cfg.tracking)
        return tracker.track(flight.decoder, cfg.target.frame_index, cfg.target.pixel,
                             flight.require_plan().frame_index.tolist(),
                             available=np.asarray(flight.frames.index).tolist())


def true_pose_errors(cfg, truth: dict) -> tuple[dict, dict]:
    """(errors with logged poses, errors with true poses) of mle and ridge for one group."""
    import dataclasses

    import pymap3d

    from pipeline.geometry.camera import projection_matrix
    from pipeline.geometry.frames import R_ecef_from_enu
    from pipeline.run import process_group
    from pipeline.solve import solve

    r = process_group(cfg)
    by_index = {f["frame_index"]: f for f in truth["frames"]}
    used = r.tracking.get("used") or [True] * len(r.tracking["frame_index"])
    frames = [by_index[i] for i, u in zip(r.tracking["frame_index"], used, strict=True) if u]
    lat0, lon0, h0 = r.origin_lla
    R_enu0_from_ecef = R_ecef_from_enu(lat0, lon0).T
    R_enu_from_opt = np.array([R_enu0_from_ecef @ np.array(f["R_ecef_from_optical"]) for f in frames])
    cam = np.array([pymap3d.ecef2enu(*f["camera_position_ecef_m"], lat0, lon0, h0) for f in frames])
    P = projection_matrix(cfg.camera.K, np.swapaxes(R_enu_from_opt, 1, 2), cam)
    ideal = dataclasses.replace(r.observations, P=P, platform_m=cam)
    logged = {m: r.errors_m().get(m) for m in ("ridge", "mle")}
    true = {m: solve(m, ideal).error_m(r.truth_m) for m in ("ridge", "mle")}
    return logged, true


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("config", nargs="?", default="configs/sample.yaml")
    ap.add_argument("--true-poses", action="store_true", help="also solve with the true camera poses (the groups "
                    "whose config gives the camera's intrinsics)")
    args = ap.parse_args(argv)
    pose_rows = []
    pooled = []
    print(f"{'group':<14} {'frames':>6} {'tracked':>7} {'lost(vis)':>9} {'false':>5} {'median px':>9} {'p95 px':>7} "
          f"{'max px':>7}")
    for entry in load_run_config(args.config):
        cfg = entry.config
        if cfg is None or cfg.truth_file is None or cfg.target is None:  # named targets: tests/test_multi_target_run
            continue
        truth = json.loads(Path(cfg.truth_file).read_text())
        by_index = {f["frame_index"]: f for f in truth["frames"]}
        res = track_group(cfg)
        errs, lost_visible, false_reports = [], 0, 0
        for ft in res.frames:
            t = by_index.get(ft.frame_index)
            if t is None:
                continue
            visible = bool(t.get("target_visible", True)) and not t.get("occluded", False)
            if ft.lost:
                lost_visible += visible
                continue
            if not visible:
                false_reports += 1
                continue
            errs.append(float(np.hypot(*(np.array(ft.pixel_px) - np.array(t["true_target_pixel"])))))
        e = np.array(errs)
        pooled.extend(errs)
        if args.true_poses and cfg.camera.has_intrinsics:  # a field of view's K changes with the zoom: not rebuilt
            pose_rows.append((cfg.name, *true_pose_errors(cfg, truth)))
        fmt = (lambda v: f"{v:.3f}") if e.size else (lambda v: "-")
        print(f"{cfg.name:<14} {len(res.frames):>6} {e.size:>7} {lost_visible:>9} {false_reports:>5} "
              f"{fmt(np.median(e) if e.size else 0):>9} {fmt(np.percentile(e, 95) if e.size else 0):>7} "
              f"{fmt(e.max() if e.size else 0):>7}")
    if pooled:
        p = np.array(pooled)
        print(f"pooled: {p.size} frames, median {np.median(p):.3f} px, 95th percentile {np.percentile(p, 95):.3f} px")
    if pose_rows:
        print(f"\n{'group':<14} {'ridge m':>8} {'mle m':>8}   with the true camera poses: {'ridge m':>8} {'mle m':>8}")
        for name, logged, true in pose_rows:
            print(f"{name:<14} {logged['ridge']:>8.2f} {logged['mle']:>8.2f}   {'':>27}{true['ridge']:>8.2f} "
                  f"{true['mle']:>8.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
