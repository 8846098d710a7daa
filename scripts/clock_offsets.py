"""Clock offsets estimated from the data (`clock: {estimate: true}`) on synthetic flights whose configs state
the video offset wrong by -1.5 .. +1.5 s: the estimate, its 95 % interval, and the localization error (mle) with
the true offset, with the wrong offset as configured, and with the estimate started from the wrong one.

    python scripts/clock_offsets.py [--workdir DIR] [--errors -1.5,-1,-0.5,0,0.5,1,1.5] [--flights precise,paper]

Flights (written once into --workdir, reused): "precise" = gimbal and attitude errors 0.02 deg (encoder-grade),
GNSS 0.3 m; "paper" = the paper's 0.2 deg attitude and gimbal errors, 2 m GNSS. Both: 8 bursts of 9 frames at
25 Hz around 1 Hz laser shots, an arc at 5 km, tracker jitter 2 px (tau 2 s). Prints a Markdown table.
"""

from __future__ import annotations

import argparse
import json
import math
import re
from pathlib import Path

FLIGHTS = {
    "precise": {"noise": {"gnss_drift_m": 0.25, "gnss_white_m": 0.15, "attitude_deg": 0.02, "gimbal_deg": 0.02,
                          "laser_m": 1.0}},
    "paper": {"noise": {}},
}


def synth_config(name: str, extra: dict) -> dict:
    return {"group": f"clock_{name}", "seed": 21, "format": "tlog",
            "observations": {"count": 8, "lead_in_s": 4.0, "lead_out_s": 3.0},
            "path": {"intersection_angle_deg": 40.0, "speed_mps": 60.0},
            "video": {"burst_frames": 9, "start_delay_s": 0.7},
            "scene": {"texture_px": 2048, "texture_res_m": 2.0, "supersample": 1}, **extra}


def make_flight(workdir: Path, name: str) -> Path:
    from pipeline.synth import flight as synth
    from pipeline.synth.config import SynthConfig

    folder = workdir / name
    if not (folder / "flight.yaml").exists():
        synth.generate(SynthConfig.from_dict(synth_config(name, FLIGHTS[name])), folder, overwrite=True,
                       write_flight_config=True)
    return folder / "flight.yaml"


def with_clock(config_path: Path, error_s: float, estimate: bool, tag: str) -> Path:
    """A copy of the flight config with the video offset `error_s` off and clock.estimate set."""
    text = config_path.read_text()
    m = re.search(r"clock: \{video_to_telemetry_offset_ns: (\d+)\}", text)
    offset = int(m.group(1)) + round(error_s * 1e9)
    clock = f"clock: {{video_to_telemetry_offset_ns: {offset}" + (", estimate: true}" if estimate else "}")
    name = re.search(r"^name: (\S+)", text, re.M).group(1)
    out = config_path.with_name(f"{tag}.yaml")
    out.write_text(text.replace(m.group(0), clock).replace(f"name: {name}", f"name: {tag}"))
    return out


def main(argv=None) -> int:
    from pipeline.errors import RidgelocError
    from pipeline.flight_config import load_flight_config
    from pipeline.run import process_group

    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--workdir", default="out/clock_offsets")
    ap.add_argument("--errors", default="-1.5,-1,-0.5,0,0.5,1,1.5")
    ap.add_argument("--flights", default="precise,paper")
    args = ap.parse_args(argv)
    workdir = Path(args.workdir)
    workdir.mkdir(parents=True, exist_ok=True)
    errors = [float(x) for x in args.errors.split(",")]
    print("| flight | configured error s | estimate error ms | 95 % interval ms | truth inside | error true m | "
          "error configured m | error estimated m |")
    print("|---|---:|---:|---|---|---:|---:|---:|")
    rows = []
    for name in args.flights.split(","):
        base = make_flight(workdir, name)
        true_err = process_group(load_flight_config(base)).errors_m().get("mle", math.nan)
        for e in errors:
            try:
                wrong = process_group(load_flight_config(with_clock(base, e, False, f"wrong{e:+.1f}")))
                err_wrong = wrong.errors_m().get("mle", math.nan)
            except RidgelocError:  # a refused flight is a result here
                err_wrong = math.nan
            est = process_group(load_flight_config(with_clock(base, e, True, f"est{e:+.1f}")))
            v = est.settings["clock_estimate"]["video"]
            # estimated offset minus the true one (the true correction is -e)
            got_ms = (v["delta_s"] + e) * 1000
            lo, hi = (v["ci95_delta_s"][0] + e) * 1000, (v["ci95_delta_s"][1] + e) * 1000
            inside = lo <= 0 <= hi
            err_est = est.errors_m().get("mle", math.nan)
            rows.append({"flight": name, "error_s": e, "estimate_ms": got_ms, "ci_ms": [lo, hi], "inside": inside,
                         "determined": v["determined"], "err_true_m": true_err, "err_wrong_m": err_wrong,
                         "err_est_m": err_est})
            print(f"| {name} | {e:+.1f} | {got_ms:+.0f} | [{lo:+.0f}, {hi:+.0f}]"
                  f"{'' if v['determined'] else ' (not determined)'} | {'yes' if inside else 'NO'} | "
                  f"{true_err:.1f} | {err_wrong:.1f} | {err_est:.1f} |", flush=True)
    (workdir / "clock_offsets.json").write_text(json.dumps(rows, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
