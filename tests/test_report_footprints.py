"""A video flight's camera footprints and frame-centre tracks on the report's map (issue 40), on the KWIVER clip:
ridgeloc's frame centre lands on the payload's own where the azimuths are read as the payload wrote them."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pymap3d
import pytest

from pipeline.flight_config import load_run_config
from pipeline.report.footprints import flight_footprints
from pipeline.report.webmap import map_fragment
from pipeline.run import process_group

CLIP = Path(__file__).resolve().parents[1] / ".." / "shared" / "fmv" / "aphill_klv_10s.ts"


def _run(tmp_path, north: str):
    if not CLIP.is_file():
        pytest.skip(f"{CLIP} absent (the shared read-only material is not beside this checkout)")
    cfg = tmp_path / f"{north}.yaml"
    cfg.write_text(f"name: clip_{north}\nfiles: {{telemetry: [{CLIP.resolve()}]}}\n"
                   f"altitude: {{geoid_separation_m: auto}}\nmapping: {{klv: {{azimuth_north: {north}}}}}\n")
    return process_group(load_run_config(str(cfg))[0].config)


def _distances_m(a_lla: np.ndarray, b_deg: np.ndarray) -> np.ndarray:
    e, n, _ = pymap3d.geodetic2enu(b_deg[:, 0], b_deg[:, 1], 0.0, a_lla[:, 0], a_lla[:, 1], 0.0)
    return np.hypot(e, n)


@pytest.mark.parametrize("north, lo_m, hi_m", [("grid", 0.0, 5.0), ("true", 60.0, 80.0)])
def test_frame_centre_tracks_and_footprints_on_the_kwiver_clip(tmp_path, north, lo_m, hi_m):
    r = _run(tmp_path, north)
    fp = flight_footprints(r)
    assert fp is not None and fp.payload_deg is not None and len(fp.payload_deg) == r.observations.n == 10
    d = _distances_m(fp.centre_lla, fp.payload_deg)
    assert lo_m <= np.median(d) < hi_m  # 72 m read from true north: the meridian convergence at 2.8 km
    # a footprint is the 0.8 x 0.6 deg field of view at ~3.5 km: tens of metres across, around the frame centre
    assert fp.outline_lla.shape == (4, 8, 3) and "laser points" in fp.ground
    first = fp.outline_lla[0]
    e, n, _ = pymap3d.geodetic2enu(first[:, 0], first[:, 1], 0.0, *fp.centre_lla[fp.frames[0], :2], 0.0)
    width = np.hypot(e[2] - e[0], n[2] - n[0])
    assert 20.0 < width < 120.0 and abs(np.mean(e)) < width / 4 and abs(np.mean(n)) < width
    html = map_fragment(r, tiles=False)
    for layer in ("Camera footprints", "Frame centre: ridgeloc", "Frame centre: payload (KLV)"):
        assert layer in html
