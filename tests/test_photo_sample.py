"""The committed sample photo flight sample_data/photos/h20_laser (`ridgeloc synth --photos 5 --dem --seed 1`):
its photos hold what the synth generates for that seed, and `ridgeloc run` of its flight.yaml locates the target."""

import json
from pathlib import Path

import numpy as np
import pytest

SAMPLE = Path(__file__).resolve().parents[1] / "sample_data" / "photos" / "h20_laser"


def test_sample_photos_hold_the_synth_flight_of_seed_1():
    from pipeline.ingest.photo import read_photos
    from pipeline.synth.dem import Hills
    from pipeline.synth.photos import PhotoFlightSpec, simulate_photo_flight

    spec = PhotoFlightSpec(seed=1)
    flight = simulate_photo_flight(PhotoFlightSpec(seed=1, hills=Hills(spec.lat_deg, spec.lon_deg,
                                                                        base_m=spec.ground_h_m)))
    photos, bad = read_photos([SAMPLE])
    assert bad == [] and len(photos) == 5
    for p, tag in zip(photos, flight.tags, strict=True):
        assert (p.lat_deg, p.lon_deg) == pytest.approx((tag["lat_deg"], tag["lon_deg"]), abs=1e-9)
        assert p.gimbal_ypr_deg == pytest.approx(tag["gimbal_ypr_deg"], abs=0.006)
        assert p.lrf_range_m == pytest.approx(tag["lrf_range_m"], abs=1e-3)
    truth = json.loads((SAMPLE / "truth.json").read_text())
    assert truth["target_lla"] == pytest.approx(flight.truth["target_lla"], abs=1e-9)


def test_run_of_the_sample_flight(tmp_path):
    from pipeline.flight_config import load_flight_config
    from pipeline.run import process_group

    result = process_group(load_flight_config(SAMPLE / "flight.yaml"))
    assert {"mle", "dem", "dji", "los"} <= set(result.estimates)
    truth = np.asarray(result.truth_m)

    def horizontal(m):
        return float(np.linalg.norm((result.estimates[m].position_m - truth)[:2]))

    assert horizontal("mle") < min(horizontal("dji"), horizontal("dem"))
