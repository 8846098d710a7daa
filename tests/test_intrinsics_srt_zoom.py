"""A DJI SRT zoom change alters the intrinsics of each frame (pipeline.intrinsics.frame_K, the K that
pipeline.run gives assemble_observations for the projection matrices) when the flight config has no `camera:`."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np

from pipeline.flight_config import flight_config_for_video
from pipeline.ingest import read_flight
from pipeline.ingest.model import FrameSeries
from pipeline.intrinsics import FIELD_OF_VIEW, frame_K, resolve_camera

SRT = Path(__file__).parent / "data" / "srt" / "mavic3_bracketed.SRT"
MS = 10**6
W, H = 1920, 1080


def test_srt_zoom_change_changes_each_frames_K():
    # the fixture's cues at 33 and 66 ms print [focal_len : 24.00] [dzoom_ratio: 1.00], at 99 and 132 ms 2.00
    log = read_flight([SRT])
    log = dataclasses.replace(log, frames=FrameSeries(np.arange(5, dtype=np.int64) * 33 * MS, np.arange(5),
                                                      source="video.mp4", width_px=W, height_px=H))
    cam, source = resolve_camera(flight_config_for_video(SRT), log)
    assert source.startswith(FIELD_OF_VIEW)

    K = frame_K(cam, source, log, np.array([33, 66, 99, 132], dtype=np.int64) * MS)
    assert K.shape == (4, 3, 3)
    # by hand: 35 mm-equivalent 24 mm on a 4:3 sensor (diagonal 43.27 mm of 36 x 24), width = 0.8 of the diagonal;
    # 16:9 video keeps the full width, so fx = (W / 2) / tan(hfov / 2) with tan(hfov / 2) = 43.27 * 0.8 / (2 f z)
    tan_half_hfov_zoom1 = math.hypot(36, 24) * 0.8 / (2 * 24.0)
    fx_zoom1 = (W / 2) / tan_half_hfov_zoom1
    np.testing.assert_allclose(K[:2, 0, 0], fx_zoom1, rtol=1e-9)
    np.testing.assert_allclose(K[2:, 0, 0], 2 * fx_zoom1, rtol=1e-9)  # 2x digital zoom doubles the focal length
    np.testing.assert_allclose(K[:, 0, 2], (W - 1) / 2)
    np.testing.assert_allclose(K[:, 1, 2], (H - 1) / 2)
    # the same ray off the optical axis lands twice as far from the principal point after the zoom
    ray = np.array([0.1, -0.05, 1.0])
    px = np.einsum("nij,j->ni", K, ray)
    off = px[:, :2] / px[:, 2:] - K[:, :2, 2]
    np.testing.assert_allclose(off[2:], 2 * off[:2], rtol=1e-9)
    # halfway between the cues at 66 and 99 ms the field of view is interpolated, so K lies in between
    K_mid = frame_K(cam, source, log, np.array([82 * MS + MS // 2]))
    assert fx_zoom1 < K_mid[0, 0, 0] < 2 * fx_zoom1
