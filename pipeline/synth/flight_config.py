"""The flight config (docs/flight_config.md) of a synthetic flight: what an operator would know about it.

Built from the flight's truth.json alone (its metadata and the generator config it records), so that
`ridgeloc synth X -o D` can write D/flight.yaml and scripts/make_sample_data.py can rewrite
configs/flights/<group>.yaml from the committed sample_data/<group>/truth.json.

Only operator knowledge goes in: files, camera calibration, lever arms, the video clock offset, the geoid
separation, the target mark (a pixel in one frame), the observation mode and the sensors' specified
accuracies. The true target position stays in truth.json (`truth_file`), which feeds the error columns only.
"""

from __future__ import annotations

import math
import os
import textwrap
from pathlib import Path

import yaml

# The tracker's pixel error is not a generator setting: the prior is a few times the error measured by
# tests/test_track_sift.py (below 0.3 px on rendered frames).
PIXEL_SIGMA_PX = 0.5


def sensor_sigmas(truth: dict) -> dict:
    """The MLE's sigma priors: the generator's noise as the sensors' spec sheets state it.

    range_m = noise.laser_m; position_m = the GNSS error per axis (drift and white parts combined,
    hypot(gnss_drift_m, gnss_white_m)) to one decimal, as a receiver spec gives it (1.97 -> 2.0 m);
    attitude_deg = noise.attitude_deg; pixel_px = PIXEL_SIGMA_PX. No correlation times: an operator does not
    know them (the generator's attitude and GNSS errors do drift); the MLE learns from the flight what it can
    (a boresight bias, drifting residuals) and says when its model does not fit.
    """
    noise = truth["config"]["noise"]
    return {"pixel_px": PIXEL_SIGMA_PX, "range_m": float(noise["laser_m"]),
            "position_m": round(math.hypot(noise["gnss_drift_m"], noise["gnss_white_m"]), 1),
            "attitude_deg": float(noise["attitude_deg"])}


def _rel(path: Path, relative_to: Path) -> str:
    return Path(os.path.relpath(Path(path).resolve(), Path(relative_to).resolve())).as_posix()


def operator_flight_config(truth: dict, flight_dir: str | os.PathLike, relative_to: str | os.PathLike) -> dict:
    """The flight config (a dict in the key order of configs/flights/*.yaml) of the synthetic flight in
    `flight_dir`, described by its parsed truth.json `truth`; file paths are relative to `relative_to` (the
    folder the config file will be written to). Raises ValueError if the target is never visible (no mark)."""
    flight_dir = Path(flight_dir)
    meta = truth["metadata"]
    if truth.get("target_mark") is None:
        raise ValueError("the target is visible in no observation frame: no mark for a flight config")
    files_in = meta["files"]
    files: dict = {"telemetry": [_rel(flight_dir / files_in["telemetry"], relative_to)]}
    if "video" in files_in:  # else images in the bag, or video and telemetry in one MPEG-TS
        files["video"] = _rel(flight_dir / files_in["video"], relative_to)
        files["frames_csv"] = _rel(flight_dir / files_in["frames_csv"], relative_to)
    cam = truth["camera"]
    arms = truth["lever_arms_m"]
    mark = truth["target_mark"]
    if meta["format"] == "klv":  # full-motion video: one file; intrinsics from its field of view, one clock
        return {
            "name": truth["group"],
            "files": files,
            "lever_arms_m": {"camera": [float(v) for v in arms["camera"]],
                             "rangefinder": [float(v) for v in arms["rangefinder"]]},
            "target": {"frame_index": int(mark["frame_index"]), "pixel": [float(v) for v in mark["pixel"]]},
            "sigma": sensor_sigmas(truth),
            "truth_file": _rel(flight_dir / "truth.json", relative_to),
        }
    return {
        "name": truth["group"],
        "files": files,
        "altitude": {"geoid_separation_m": float(meta["geoid_separation_m"])},
        "camera": {**{k: cam[k] for k in ("width_px", "height_px", "fx_px", "fy_px", "cx_px", "cy_px")},
                   "dist": [float(v) for v in cam["dist"]],
                   "R_optical_from_gimbal": [[float(v) for v in row] for row in cam["R_optical_from_gimbal"]]},
        "lever_arms_m": {"camera": [float(v) for v in arms["camera"]],
                         "rangefinder": [float(v) for v in arms["rangefinder"]]},
        "clock": {"video_to_telemetry_offset_ns": int(meta["clock"]["video_to_telemetry_offset_ns"])},
        **_targets(truth, mark),
        "observations": _observations(truth),
        "sigma": sensor_sigmas(truth),
        "truth_file": _rel(flight_dir / "truth.json", relative_to),
    }


def _targets(truth: dict, mark: dict) -> dict:
    """`target:` (one mark), or `targets:` when the flight has several (issue 21): each named target marked at
    its true pixel in the first observation frame showing it (a target never visible is left out)."""
    if not truth.get("targets"):
        return {"target": {"frame_index": int(mark["frame_index"]), "pixel": [float(v) for v in mark["pixel"]]}}
    return {"targets": [{"name": t["name"], "frame_index": int(t["mark"]["frame_index"]),
                         "pixel": [float(v) for v in t["mark"]["pixel"]]} for t in truth["targets"] if t["mark"]]}


def _observations(truth: dict) -> dict:
    """Bursts video: one observation per burst (the camera is triggered around the laser shots). Continuous
    video: the frames the operator designated as observations, listed (the laser fires all flight long)."""
    if truth["metadata"].get("video_mode", "bursts") == "bursts":
        return {"mode": "bursts"}
    return {"mode": "frames", "frame_indices": [int(o["frame_index"]) for o in truth["observations"]]}


def _flow(value) -> str:
    text = yaml.safe_dump(value, default_flow_style=True, width=10**6, sort_keys=False)
    return text.removesuffix("\n...\n").strip()  # a plain scalar's dump ends with a document-end marker


def _comment(paragraph: str) -> list[str]:
    return ["# " + line for line in textwrap.wrap(paragraph, width=108)]


def flight_config_text(doc: dict, title: str) -> str:
    """YAML text of `doc` (from operator_flight_config) with its explanatory comments; `title` starts the header,
    e.g. "Sample flight group1" or "Synthetic flight example"."""
    s = doc["sigma"]
    if "camera" not in doc:
        return _fmv_config_text(doc, title)
    cam = doc["camera"]
    paper = (s["range_m"], s["position_m"], s["attitude_deg"]) == (5.0, 2.0, 0.2)
    header = (
        f"{title}: what an operator knows about it (docs/flight_config.md): files, camera calibration, lever "
        "arms, the video clock offset, the geoid separation, the target mark, and the sensors' specified "
        "accuracies as the MLE's priors (the generator's noise as spec sheets state it: "
        f"laser {s['range_m']:g} m, position {s['position_m']:g} m, attitude {s['attitude_deg']:g} deg"
        + (", the paper's section 3.2 figures" if paper else "")
        + f"; pixel {s['pixel_px']:g} px, a few times the tracker's measured error). "
        + ("The camera was triggered in bursts around the laser shots: one observation per burst. "
           if doc["observations"]["mode"] == "bursts" else
           "The video is continuous: the observations are the listed frames, the instants the operator chose. ")
        + "truth_file feeds the error columns only; "
        "nothing reads it during processing. Written from truth.json by pipeline/synth/flight_config.py "
        "(docs/synth.md).")
    tau_note = (
        "No error correlation times (attitude_tau_s, position_tau_s): spec sheets do not give them. The MLE "
        "estimates a constant boresight bias from the flight, tests its residuals for drift and inflates its "
        "covariance when they do not fit (docs/solvers.md); add them here if you know them.")
    lines = [
        *_comment(header),
        f"name: {_flow(doc['name'])}",
        "files:",
        *(f"  {k}: {_flow(v)}" for k, v in doc["files"].items()),
        f"altitude: {_flow(doc['altitude'])}",
        "camera:",
        *(f"  {k}: {_flow(cam[k])}" for k in cam if k != "R_optical_from_gimbal"),
        "  R_optical_from_gimbal:",
        *(f"  - {_flow(row)}" for row in cam["R_optical_from_gimbal"]),
        "lever_arms_m:",
        *(f"  {k}: {_flow(v)}" for k, v in doc["lever_arms_m"].items()),
        f"clock: {_flow(doc['clock'])}",
        *(["target:", *(f"  {k}: {_flow(v)}" for k, v in doc["target"].items())] if "target" in doc else
          ["targets:", *(f"- {_flow(t)}".replace("- ", "  - ", 1) for t in doc["targets"])]),
        f"observations: {_flow(doc['observations'])}",
        *_comment(tau_note),
        "sigma: {" + ", ".join(f"{k}: {_flow(v)}" for k, v in s.items()) + "}",
        f"truth_file: {_flow(doc['truth_file'])}",
    ]
    text = "\n".join(lines) + "\n"
    if yaml.safe_load(text) != doc:  # the layout above must not change any value
        raise AssertionError(f"flight config text does not parse back to its values: {doc['name']}")
    return text


def _fmv_config_text(doc: dict, title: str) -> str:
    s = doc["sigma"]
    header = (
        f"{title}: a MISB ST 0601 full-motion video (STANAG 4609 MPEG-TS: H.264 and KLV metadata in one file). "
        "The file carries the position, attitude, sensor pointing, laser slant range and field of view, all on "
        "the video's clock, so an operator gives only the target mark, the lever arms and the sensors' specified "
        f"accuracies (laser {s['range_m']:g} m, position {s['position_m']:g} m, attitude {s['attitude_deg']:g} "
        f"deg; pixel {s['pixel_px']:g} px). No camera calibration: the intrinsics of each frame come from its "
        "field of view (tags 16/17), so a zoom changes them frame by frame. truth_file feeds the error columns "
        "only. Written from truth.json by pipeline/synth/flight_config.py (docs/synth.md).")
    lines = [
        *_comment(header),
        f"name: {_flow(doc['name'])}",
        "files:",
        *(f"  {k}: {_flow(v)}" for k, v in doc["files"].items()),
        "lever_arms_m:",
        *(f"  {k}: {_flow(v)}" for k, v in doc["lever_arms_m"].items()),
        "target:",
        *(f"  {k}: {_flow(v)}" for k, v in doc["target"].items()),
        "sigma: {" + ", ".join(f"{k}: {_flow(v)}" for k, v in s.items()) + "}",
        f"truth_file: {_flow(doc['truth_file'])}",
    ]
    text = "\n".join(lines) + "\n"
    if yaml.safe_load(text) != doc:
        raise AssertionError(f"flight config text does not parse back to its values: {doc['name']}")
    return text


def write_flight_config(path: str | os.PathLike, truth: dict, flight_dir: str | os.PathLike, title: str) -> dict:
    """Write the flight config of the flight in `flight_dir` to `path` (paths relative to its folder); returns it."""
    path = Path(path)
    doc = operator_flight_config(truth, flight_dir, path.parent)
    path.write_text(flight_config_text(doc, title))
    return doc
