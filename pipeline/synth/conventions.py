"""Small synthetic flights written in other vehicles' conventions, and the config mistakes `ridgeloc check` must
diagnose on them (tests/test_check_conventions.py; the table in docs/check.md comes from
`python scripts/check_conventions.py`).

Each flight is written by `ridgeloc synth` with one convention changed (the gimbal topic's frame, its yaw
reference, the quaternion's element order); each case is the operator's flight config for it, with the mistake a
new user makes (or the right settings).
"""

from __future__ import annotations

import copy
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import yaml

# Small flights: 6 observations, one frame each, a coarse ground texture (about 1-2 s each to write).
BASE = {"seed": 11, "observations": {"count": 6, "lead_in_s": 3.0, "lead_out_s": 1.0},
        "path": {"intersection_angle_deg": 50.0, "speed_mps": 120.0},
        "noise": {"gnss_drift_m": 0.25, "gnss_white_m": 0.15, "attitude_deg": 0.02, "gimbal_deg": 0.02,
                  "laser_m": 1.0},
        "video": {"burst_frames": 1, "start_delay_s": 0.5},
        "scene": {"texture_px": 2048, "texture_res_m": 2.0, "supersample": 1}}

FLIGHTS = {
    "ros_optical_vehicle_yaw": {"format": "ros1", "gimbal": {"ros_frame": "optical_enu",
                                                             "yaw_in_vehicle_frame": True}},
    "ros_frd_ned": {"format": "ros1", "gimbal": {"ros_frame": "frd_ned"}},
    "mcap_xyzw": {"format": "mcap", "gimbal": {"quat_order": "xyzw"}},
    "tlog": {"format": "tlog"},
}
IDENTITY = [[1, 0, 0], [0, 1, 0], [0, 0, 1]]


def _ros_gimbal(**keys) -> Callable[[dict], None]:
    return lambda d: d.setdefault("mapping", {}).setdefault("ros", {}).setdefault("gimbal", {}).update(keys)


def _mount(R) -> Callable[[dict], None]:
    return lambda d: d["camera"].update(R_optical_from_gimbal=R)


def _swap_mark(d: dict) -> None:
    d["target"]["pixel"] = d["target"]["pixel"][::-1]


def _no_clock(d: dict) -> None:
    d["clock"] = {}


def _no_camera(d: dict) -> None:
    d.pop("camera")


@dataclass(frozen=True)
class Case:
    """name; flight: a FLIGHTS key; mistake: what the config gets wrong ("" when right); change: edits the
    operator's config dict; expect: text that check's problem line must contain (None: consistent);
    refused: `ridgeloc run` must refuse the flight (the fix named in the reason)."""

    name: str
    flight: str
    mistake: str
    change: Callable[[dict], None] | None
    expect: str | None
    refused: bool


CASES = [
    Case("ros_optical_default", "ros_optical_vehicle_yaw", "camera-optical gimbal topic with vehicle-relative yaw, "
         "read with the defaults (flu_enu, earth-referenced)", None,
         "mapping: {ros: {gimbal: {frame: optical_enu, yaw_in_vehicle_frame: true}}}", True),
    Case("ros_optical_frame_only", "ros_optical_vehicle_yaw", "frame set, yaw reference forgotten",
         _ros_gimbal(frame="optical_enu"), "mapping: {ros: {gimbal: {yaw_in_vehicle_frame: true}}}", True),
    Case("ros_optical_yaw_only", "ros_optical_vehicle_yaw", "yaw reference set, frame forgotten",
         _ros_gimbal(yaw_in_vehicle_frame=True), "mapping: {ros: {gimbal: {frame: optical_enu}}}", True),
    Case("ros_optical_right", "ros_optical_vehicle_yaw", "", _ros_gimbal(frame="optical_enu",
                                                                         yaw_in_vehicle_frame=True), None, False),
    Case("ros_optical_no_camera", "ros_optical_vehicle_yaw", "(no mistake: intrinsics from the bag's CameraInfo)",
         lambda d: (_ros_gimbal(frame="optical_enu", yaw_in_vehicle_frame=True)(d), _no_camera(d)), None, False),
    Case("ros_frd_default", "ros_frd_ned", "FRD -> NED gimbal topic read as REP-103 flu_enu", None,
         "mapping: {ros: {gimbal: {frame: frd_ned}}}", True),
    Case("mcap_xyzw_default", "mcap_xyzw", "scalar-last quaternion read as scalar-first", None,
         "mapping: {mcap: {gimbal: {quat_order: xyzw}}}", True),
    Case("tlog_identity_mount", "tlog", "camera mount given as identity (as if the gimbal frame were optical)",
         _mount(IDENTITY), "camera: {R_optical_from_gimbal: [[0, 1, 0], [0, 0, 1], [1, 0, 0]]}", True),
    Case("tlog_right", "tlog", "", None, None, False),
    Case("tlog_mark_row_column", "tlog", "target pixel given as [row, column]", _swap_mark, "swapped to", True),
    Case("tlog_no_clock", "tlog", "video clock offset left out (video times from 0)", _no_clock,
         "set clock.video_start", True),
]


def write_flights(root: str | Path, names=None) -> dict[str, Path]:
    """Write the FLIGHTS (or `names` of them) under root/<name>/ (kept when already there); returns name -> the
    operator's flight.yaml."""
    from pipeline.synth import flight as synth
    from pipeline.synth.config import SynthConfig

    root = Path(root)
    out = {}
    for name in names or FLIGHTS:
        folder = root / name
        if not (folder / "flight.yaml").exists():
            doc = copy.deepcopy(BASE)
            doc.update(group=name, **copy.deepcopy(FLIGHTS[name]))
            synth.generate(SynthConfig.from_dict(doc), folder, overwrite=True, write_flight_config=True)
        out[name] = folder / "flight.yaml"
    return out


def case_config(flight_yaml: Path, case: Case) -> Path:
    """Write the case's flight config next to the flight's (flight folder/<case>.yaml) and return its path."""
    doc = yaml.safe_load(Path(flight_yaml).read_text())
    doc["name"] = case.name
    if case.change is not None:
        case.change(doc)
    path = Path(flight_yaml).with_name(f"{case.name}.yaml")
    path.write_text(yaml.safe_dump(doc, sort_keys=False))
    return path
