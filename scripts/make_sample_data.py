#!/usr/bin/env python
"""Regenerate sample_data/ deterministically from configs/synth/<group>.yaml, and configs/flights/<group>.yaml.

    python scripts/make_sample_data.py                 # all groups into sample_data/, and their flight configs
    python scripts/make_sample_data.py --only group6 -o /tmp/sd
    python scripts/make_sample_data.py --configs-only  # only configs/flights/*.yaml, from sample_data/*/truth.json
    python scripts/make_sample_data.py --only h20_laser  # the photo flight sample_data/photos/h20_laser only

Writes sample_data/MANIFEST.json: per flight, the generation time and per file the size and sha256 of its
bytes, and for each video the sha256 of its decoded frames (tests/test_synth_sample_data.py checks them).
The flight configs (what an operator knows: files, camera, lever arms, clock offset, mark, sensor specs) are
written by pipeline/synth/flight_config.py from each flight's truth.json, with paths relative to configs/flights/
(tests/test_synth_flight_config.py checks that the committed ones are what it writes). They are written only when
the output folder is sample_data/ (the folder configs/sample.yaml points at).

The photo flight sample_data/photos/h20_laser (issue 22) is written by pipeline/synth/photos.py (PHOTO_SAMPLES
below: its seed and its three targets), with configs/flights/h20_laser.yaml; it is not in MANIFEST.json
(tests/test_photo_sample.py checks it against a regeneration).
"""

from __future__ import annotations

import argparse
import hashlib
import json
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import cv2  # noqa: E402

from pipeline.synth.config import SynthConfig  # noqa: E402
from pipeline.synth.flight import generate  # noqa: E402
from pipeline.synth.flight_config import write_flight_config  # noqa: E402
from pipeline.synth.writers.video import read_video_frames  # noqa: E402

SAMPLE_DATA = ROOT / "sample_data"
FLIGHT_CONFIGS = ROOT / "configs" / "flights"
GROUPS = ("group1", "group2", "group3", "group4", "group5", "group6", "hard_outliers", "angle10", "fmv",
          "three_targets")
#: photo flights: sample_data/photos/<name>, PhotoFlightSpec changes (pipeline/synth/photos.py), with a DEM. The
#: laser's target at every image centre, two more targets marked where the photos see them
PHOTO_SAMPLES = {"h20_laser": {"seed": 1, "extra_targets": (("cairn", 40.0, 15.0), ("gate", -20.0, 35.0))}}
PHOTO_CONFIG_HEADER = """\
# Sample photo flight {name}: five JPEGs with DJI-style XMP (pose, calibrated intrinsics, laser range and DJI's
# one-shot laser target), a consumer drone's compass bias, GNSS error and altitude datum offset in the poses, a
# GeoTIFF DEM of the site, and three targets marked in the photos (targets.csv, docs/run.md "Many targets per
# flight"): the laser's spot at every image centre, and two more seen off-centre (pixels only). Written by
# scripts/make_sample_data.py (pipeline/synth/photos.py). `ridgeloc locate sample_data/photos/{name} --marks
# sample_data/photos/{name}/marks.csv --dem sample_data/photos/{name}/dem.tif` locates the laser's target.
"""


def decoded_video_sha256(path: Path) -> str:
    h = hashlib.sha256()
    for img in read_video_frames(path):
        h.update(img.tobytes())
    return h.hexdigest()


def file_manifest(folder: Path) -> dict:
    out = {}
    for p in sorted(q for q in folder.rglob("*") if q.is_file()):
        rel = p.relative_to(folder).as_posix()
        entry = {"bytes": p.stat().st_size, "sha256": hashlib.sha256(p.read_bytes()).hexdigest()}
        if p.suffix == ".mp4":
            entry["decoded_frames_sha256"] = decoded_video_sha256(p)
        out[rel] = entry
    return out


def write_frame_png(flight: Path, png: Path) -> None:
    """One observation frame of a sample video, with the target region magnified 5x in an inset."""
    truth = json.loads((flight / "truth.json").read_text())
    k = truth["target_mark"]["frame_index"]
    img = read_video_frames(flight / "video.mp4")[k].copy()
    u, v = (round(x) for x in truth["frames"][k]["true_target_pixel"])
    crop = img[v - 15:v + 15, u - 20:u + 20].copy()
    inset = cv2.resize(crop, (200, 150), interpolation=cv2.INTER_NEAREST)
    cv2.rectangle(img, (u - 21, v - 16), (u + 20, v + 15), (255, 255, 255), 1)
    w = img.shape[1]
    img[8:162, w - 212:w - 8] = 255
    img[10:160, w - 210:w - 10] = inset
    cv2.imwrite(str(png), img)


def write_sample_flight_config(group: str, sample_data: Path = SAMPLE_DATA,
                               configs: Path = FLIGHT_CONFIGS) -> Path:
    """configs/<group>.yaml from sample_data/<group>/truth.json (paths relative to `configs`)."""
    flight = sample_data / group
    truth = json.loads((flight / "truth.json").read_text())
    path = configs / f"{group}.yaml"
    write_flight_config(path, truth, flight, f"Sample flight {group}")
    return path


def make_photo_sample(name: str, out: Path, write_config: bool) -> dict:
    """sample_data/photos/<name> (and configs/flights/<name>.yaml when write_config): the flight's truth."""
    import shutil

    from pipeline.synth.photos import PhotoFlightSpec, write_photo_sample

    folder = out / "photos" / name
    if folder.exists():
        shutil.rmtree(folder)
    flight = write_photo_sample(folder, PhotoFlightSpec(**PHOTO_SAMPLES[name]), dem=True)
    if write_config:
        rel = f"../../sample_data/photos/{name}"
        (FLIGHT_CONFIGS / f"{name}.yaml").write_text(
            PHOTO_CONFIG_HEADER.format(name=name) + f"name: {name}\nfiles:\n  photos: {rel}\n"
            f"marks_file: {rel}/targets.csv\ntruth_file: {rel}/truth.json\n"
            f"terrain:\n  dem: {rel}/dem.tif\n  vertical_sigma_m: 2.0\n")
    return flight.truth


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--only", action="append", choices=(*GROUPS, *PHOTO_SAMPLES),
                    help="generate only this group (repeatable)")
    ap.add_argument("-o", "--output", default=str(ROOT / "sample_data"), help="output folder (default sample_data/)")
    ap.add_argument("--no-frame-png", action="store_true", help="do not write docs/sample_frame.png")
    ap.add_argument("--configs-only", action="store_true",
                    help="only rewrite configs/flights/<group>.yaml from the existing sample_data/<group>/truth.json")
    args = ap.parse_args(argv)
    out = Path(args.output)
    write_configs = out.resolve() == SAMPLE_DATA.resolve()
    if args.configs_only:
        if not write_configs:
            ap.error("--configs-only rewrites configs/flights/ from sample_data/: do not combine it with -o")
        for group in args.only or GROUPS:
            if group in GROUPS:
                print(f"wrote {write_sample_flight_config(group).relative_to(ROOT)}")
        return 0
    out.mkdir(parents=True, exist_ok=True)
    manifest_path = out / "MANIFEST.json"
    manifest = json.loads(manifest_path.read_text()) if manifest_path.exists() else {}
    for name in PHOTO_SAMPLES:
        if not args.only or name in args.only:
            truth = make_photo_sample(name, out, write_configs)
            n_targets = len(truth.get("targets") or [1])
            print(f"photos/{name}: {len(truth['camera_lla_true'])} photos, {n_targets} targets", flush=True)
    for group in [g for g in args.only or GROUPS if g in GROUPS]:
        cfg = SynthConfig.load(ROOT / "configs" / "synth" / f"{group}.yaml")
        t = time.perf_counter()
        res = generate(cfg, out / group, overwrite=True)
        dt = time.perf_counter() - t
        files = file_manifest(out / group)
        size = sum(f["bytes"] for f in files.values())
        manifest[group] = {"format": cfg.format, "n_observations": res.n_observations,
                           "intersection_angle_deg": round(res.intersection_angle_deg, 6), "frames": res.n_frames,
                           "total_bytes": size, "files": files}
        print(f"{group}: {cfg.format}, {res.n_observations} obs, {res.intersection_angle_deg:.4f} deg, "
              f"{res.n_frames} frames, {size / 1e6:.2f} MB, {dt:.1f} s", flush=True)
        if write_configs:
            write_sample_flight_config(group)
    manifest = dict(sorted(manifest.items()))
    manifest_path.write_text(json.dumps(manifest, indent=1) + "\n")
    total = sum(v["total_bytes"] for v in manifest.values())
    print(f"total {total / 1e6:.2f} MB")
    if not args.no_frame_png and (out / "group1" / "video.mp4").exists() and (not args.only or "group1" in args.only):
        write_frame_png(out / "group1", ROOT / "docs" / "sample_frame.png")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
