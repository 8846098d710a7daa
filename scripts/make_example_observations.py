"""Write configs/example_observations.json: one noisy problem on the paper's simulation geometry.

10 frames on a circular arc 2 km above the target at 5 km slant range, 30 deg intersection angle, the
paper's noise (position 5 m per axis, range 2.5 m, attitude 0.2 deg per axis, pixel 0.1 px), seeded, with
the truth. Frame 3 has no pixel (target not tracked) and frame 7 no range, to show the null entries.

    python scripts/make_example_observations.py [--out configs/example_observations.json]
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT), str(ROOT / "tests")]  # this checkout's pipeline; test support (support.scenes)

from pipeline.observation_file import to_dict  # noqa: E402
from support.scenes import PAPER_SIGMA, paper_problem  # noqa: E402

SEED = 2026
DEFAULT_OUT = Path(__file__).resolve().parent.parent / "configs" / "example_observations.json"


def build() -> dict:
    obs = paper_problem(n=10, gamma_deg=30.0, sigma=PAPER_SIGMA, seed=SEED)
    pixel, rng = obs.pixel.copy(), obs.range_m.copy()
    pixel[3] = np.nan
    rng[7] = np.nan
    obs = dataclasses.replace(obs, pixel=pixel, range_m=rng)
    doc = to_dict(obs)
    doc["meta"] = {
        "generator": "scripts/make_example_observations.py",
        "seed": SEED,
        "frame": "local ENU at the target, metres",
        "geometry": "10 frames, circular arc, height 2000 m, slant range 5000 m, intersection angle 30 deg",
        "camera": "fx = fy = 1000 px, principal point (300, 200), 600 x 400 px",
    }
    return doc


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=DEFAULT_OUT)
    args = parser.parse_args(argv)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(build(), indent=1) + "\n")
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
