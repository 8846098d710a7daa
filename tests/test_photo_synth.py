"""Synthetic DJI photo flights: written by pipeline.synth.photos, read back by pipeline.ingest.photo, compared with
the values the synth recorded (not with the reader)."""

import math

import numpy as np
import pytest

from pipeline.ingest.photo import read_photos
from pipeline.synth.photos import PhotoFlightSpec, simulate_photo_flight, write_photo_flight


@pytest.mark.parametrize("laser", [True, False])
def test_round_trip(tmp_path, laser):
    flight = simulate_photo_flight(PhotoFlightSpec(seed=7, laser=laser, mark_offset_px=100.0))
    write_photo_flight(flight, tmp_path)
    photos, bad = read_photos([tmp_path])
    assert bad == [] and len(photos) == 5
    for p, tag in zip(photos, flight.tags, strict=True):
        assert p.lat_deg == pytest.approx(tag["lat_deg"], abs=1e-9)  # DMS seconds written to 1e-6"
        assert p.lon_deg == pytest.approx(tag["lon_deg"], abs=1e-9)
        assert p.alt_m == pytest.approx(tag["abs_alt_m"], abs=1e-3)
        assert (p.alt_source, p.alt_datum) == ("drone-dji:AbsoluteAltitude", "amsl")
        assert p.gimbal_ypr_deg == pytest.approx(tag["gimbal_ypr_deg"], abs=0.006)
        assert p.flight_ypr_deg == pytest.approx(tag["flight_ypr_deg"], abs=0.006)
        assert p.t_ns == tag["t_unix_s"] * 10**9 and p.time_zone == "+00:00"
        k = p.intrinsics
        assert k.source == "drone-dji Calibrated* + DewarpData"
        assert (k.fx_px, k.fy_px, k.cx_px, k.cy_px) == pytest.approx((tag["fx_px"], tag["fx_px"], tag["cx_px"],
                                                                       tag["cy_px"]), abs=1e-4)
        assert k.dist == pytest.approx(tag["dist"], abs=1e-6)
        assert (p.rtk_flag, p.rtk_std_m) == (16, (1.5, 1.5, 2.0))
        if laser:
            assert p.lrf_valid and p.lrf_range_m == pytest.approx(tag["lrf_range_m"], abs=1e-3)
            assert p.dji_target_lla[:2] == pytest.approx(tag["dji_target"][:2], abs=1e-9)
            assert p.dji_target_lla[2] == pytest.approx(tag["dji_target"][2], abs=1e-3)
        else:
            assert not p.lrf_valid and math.isnan(p.lrf_range_m) and p.dji_target_lla is None


def test_marks_project_from_the_true_poses(tmp_path):
    """The synth's marked pixels are where its true cameras see the target: with no recorded error the photo
    views (reader + pose chain) triangulate the target exactly."""
    from pipeline.locate import locate_photos

    spec = PhotoFlightSpec(seed=2, laser=False, compass_bias_deg=(0.0, 0.0), pitch_bias_deg=0.0,
                           attitude_jitter_deg=0.0,
                           gnss_offset_sigma_m=(0.0, 0.0), gnss_noise_sigma_m=(0.0, 0.0),
                           datum_offset_m=(0.0, 0.0), mark_sigma_px=0.0,
                           mark_offset_px=150.0)
    flight = simulate_photo_flight(spec)
    write_photo_flight(flight, tmp_path)
    photos, _ = read_photos([tmp_path])
    loc = locate_photos(photos, flight.marks_px, methods=["vision"])
    lat, lon, h = loc.views.lla(loc.estimates["vision"].position_m)
    from pipeline.geometry.frames import enu_from_lla
    err = enu_from_lla(lat, lon, h, tuple(flight.truth["target_lla"]))
    # tags are written to 0.01 deg (~0.1 m at 600 m) and 1 mm
    assert np.linalg.norm(err) < 0.5
