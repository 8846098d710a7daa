"""Every reader on the synthetic sample flights (sample_data/<group>/), against their truth.json: frame times,
platform positions, gimbal optical axes and laser ranges."""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np
import pymap3d
import pytest
from scipy.spatial.transform import Rotation

from pipeline.ingest import BagImages, gimbal_to_earth, read_flight, read_video
from pipeline.ingest.clocks import series_to_clock

REPO = Path(__file__).resolve().parents[1]
ROOTS = [REPO / "sample_data", *(Path(p) for p in os.environ.get("RIDGELOC_EXTRA_FLIGHTS", "").split(":") if p)]
FLIGHTS = sorted({p.parent for root in ROOTS if root.is_dir() for p in root.glob("*/truth.json")})


def _telemetry_files(folder: Path, truth: dict) -> list[Path]:
    tel = truth["metadata"]["files"]["telemetry"]
    return [folder / t for t in ([tel] if isinstance(tel, str) else tel)]


def _interp(t_query, t, values):
    return np.column_stack([np.interp(t_query.astype(float), t.astype(float), v) for v in np.atleast_2d(values.T)])


@pytest.mark.skipif(not FLIGHTS, reason="no sample flights under sample_data/ yet")
@pytest.mark.parametrize("folder", FLIGHTS, ids=[f.name for f in FLIGHTS])
def test_sample_flight_against_truth(folder):
    truth = json.loads((folder / "truth.json").read_text())
    meta = truth["metadata"]
    files = _telemetry_files(folder, truth)
    video = meta["files"].get("video")
    log = read_flight(files + ([folder / video] if video else []))
    assert log.position is not None and log.attitude is not None and log.gimbal is not None
    assert log.range is not None and log.frames is not None
    assert not [w for w in log.warnings if "truncated" in w or "skipped" in w]

    # frame times: video clock + offset (or bag stamps, already on the telemetry clock) = truth frame times
    fmv = meta["format"] == "klv"  # video and telemetry in one MPEG-TS, on the video clock
    offset = meta["clock"]["video_to_telemetry_offset_ns"] if video or fmv else 0
    if video:
        frames = read_video(folder / video)
    elif fmv:
        frames = log.frames
    else:
        frames = BagImages(files[0]).frames
    tf = {f["frame_index"]: f for f in truth["frames"]}
    idx = np.searchsorted(frames.index, list(tf))
    got_t = frames.t_ns[idx] + offset
    np.testing.assert_array_equal(got_t, [tf[k]["t_ns"] for k in tf])
    assert frames.index.size >= len(tf)

    t_obs = np.array([tf[k]["t_ns"] for k in tf], np.int64)
    pos = series_to_clock(log.position, log.clock_links, "unix")
    alt = pos.alt_m + (meta["geoid_separation_m"] if pos.alt_datum == "amsl" else 0.0)
    lla = _interp(t_obs, pos.t_ns, np.column_stack([pos.lat_deg, pos.lon_deg, alt]))
    cam = np.array([tf[k]["camera_lla"] for k in tf])
    e, n, u = pymap3d.geodetic2enu(lla[:, 0], lla[:, 1], lla[:, 2], cam[:, 0], cam[:, 1], cam[:, 2])
    err = np.sqrt(e**2 + n**2 + u**2)
    assert err.max() < 5 * meta["noise"]["gnss_m"] + 2.0, err  # GNSS noise plus the lever arm

    # optical axis: gimbal FRD x at the frame time (yaw referred to north where the log gives it relative to
    # the vehicle), NED at the vehicle -> ECEF, against truth R_ecef_from_optical's z (optical axis)
    assert bool(log.gimbal.yaw_in_vehicle_frame.any()) == bool(meta.get("gimbal_yaw_in_vehicle_frame"))
    g = series_to_clock(gimbal_to_earth(log.gimbal, log.attitude), log.clock_links, "unix")
    j = np.clip(np.searchsorted(g.t_ns, t_obs), 0, g.t_ns.size - 1)
    axis_ned = Rotation.from_quat(g.quat_wxyz[j], scalar_first=True).apply([1.0, 0.0, 0.0])
    u_e, v_e, w_e = pymap3d.enu2uvw(axis_ned[:, 1], axis_ned[:, 0], -axis_ned[:, 2], cam[:, 0], cam[:, 1])
    axis_ecef = np.column_stack([u_e, v_e, w_e])
    true_axis = np.array([np.asarray(tf[k]["R_ecef_from_optical"])[:, 2] for k in tf])
    ang = np.degrees(np.arccos(np.clip(np.sum(axis_ecef * true_axis, axis=1), -1, 1)))
    assert ang.max() < 1.5, ang  # 0.2 deg gimbal (+ attitude) noise, jitter, up to 1/25 s between samples

    # laser ranges: one sample per logged shot, and the measured value at each observation
    r = series_to_clock(log.range, log.clock_links, "unix")
    shots = truth.get("laser_shots")
    if isinstance(shots, dict) and "logged" in shots:
        assert r.t_ns.size == sum(shots["logged"])
    for ob in truth["observations"]:
        k = np.searchsorted(r.t_ns, ob["t_ns"])
        if ob["range_valid"]:
            assert k < r.t_ns.size and r.t_ns[k] == ob["t_ns"] and r.valid[k]
            assert r.range_m[k] == pytest.approx(ob["range_measured_m"], abs=2e-3)
        elif k < r.t_ns.size and r.t_ns[k] == ob["t_ns"]:
            assert not r.valid[k]
