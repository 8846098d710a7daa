"""`ridgeloc init` on synthetic flights of every log format: what it leaves to fill in, and the answer once the
target's pixel (and, where no file states them, the camera's intrinsics) are given, against the truth and against
the flight's hand-written config (the table in docs/init.md).

    python scripts/init_flights.py                    # seeds 11, 12, 13; 6 observations each, a few seconds a flight
    python scripts/init_flights.py --seeds 1,2 --formats ros1,tlog
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from pipeline.autoconfig import config_text, draft_flight_config
from pipeline.flight_config import flight_config_from_dict, load_flight_config
from pipeline.run import process_group
from pipeline.synth.config import SynthConfig, with_sections
from pipeline.synth.flight import generate

# the flights of tests/test_init.py
TINY = {"group": "tiny", "observations": {"count": 6, "lead_in_s": 3.0, "lead_out_s": 1.0},
        "path": {"intersection_angle_deg": 50.0, "speed_mps": 120.0},
        "noise": {"gnss_drift_m": 0.25, "gnss_white_m": 0.15, "attitude_deg": 0.02, "gimbal_deg": 0.02,
                  "laser_m": 1.0, "attitude_tau_s": 7.0, "gnss_tau_s": 30.0},
        "video": {"burst_frames": 3, "start_delay_s": 0.5},
        "scene": {"texture_px": 2048, "texture_res_m": 2.0, "supersample": 1}}
FORMATS = {
    "tlog": {"format": "tlog"},
    "ros1 (images in the bag)": {"format": "ros1", "video": {"images_in_bag": True}},
    "ros2-sqlite3 + mp4": {"format": "ros2-sqlite3"},
    "ros2-mcap (images in the bag)": {"format": "ros2-mcap", "video": {"images_in_bag": True}},
    "mcap + mp4": {"format": "mcap"},
    "klv": {"format": "klv", "camera": {"dist": [0.0] * 5},
            "lever_arms_m": {"camera": [0.0] * 3, "rangefinder": [0.0] * 3}},
}



def _ecef(result) -> np.ndarray:
    import pymap3d

    return np.array(pymap3d.enu2ecef(*result.estimates["mle"].position_m, *result.origin_lla))


def one(fmt: str, seed: int, tmp: Path) -> list[str]:
    folder = tmp / f"{seed}-{fmt.split()[0]}"
    cfg = SynthConfig.from_dict(with_sections({**TINY, "seed": seed}, FORMATS[fmt]))
    generate(cfg, folder, write_flight_config=True)
    out = tmp / f"{folder.name}.yaml"
    draft = draft_flight_config(folder, out)
    out.write_text(config_text(draft, "ridgeloc init"))
    truth = json.loads((folder / "truth.json").read_text())
    doc = dict(draft.doc)
    required = [f.key for f in draft.fill_in if f.required]
    if "camera" in required:
        doc["camera"] = {k: truth["camera"][k] for k in ("width_px", "height_px", "fx_px", "fy_px", "cx_px",
                                                        "cy_px", "dist")}
    doc["target"] = truth["target_mark"]
    doc["truth_file"] = str(folder / "truth.json")
    mine = process_group(flight_config_from_dict(doc, out))
    hand = process_group(load_flight_config(folder / "flight.yaml"))
    return [fmt, str(seed), ", ".join(required), f"{mine.errors_m()['mle']:.1f}", f"{hand.errors_m()['mle']:.1f}",
            f"{np.linalg.norm(_ecef(mine) - _ecef(hand)):.2f}"]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", default="11,12,13")
    ap.add_argument("--formats", default=None, help="comma-separated prefixes of the format names")
    args = ap.parse_args(argv)
    formats = [f for f in FORMATS if args.formats is None or any(f.startswith(p) for p in args.formats.split(","))]
    print("| format | seed | init leaves to fill in | mle error, init config m | mle error, hand-written m | "
          "init - hand-written m |")
    print("|---|---:|---|---:|---:|---:|")
    with tempfile.TemporaryDirectory() as tmp:
        for seed in (int(s) for s in args.seeds.split(",")):
            for fmt in formats:
                print("| " + " | ".join(one(fmt, seed, Path(tmp))) + " |", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
