"""The committed sample photo flight sample_data/photos/h20_laser (scripts/make_sample_data.py, PHOTO_SAMPLES): its
files are what the generator writes for that spec, and `ridgeloc run` of configs/flights/h20_laser.yaml locates its
three named targets, each MLE holding the truth in its 95 % ellipsoid."""

import json
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
SAMPLE = ROOT / "sample_data" / "photos" / "h20_laser"
CHI2_3_95 = 7.814727903251178


def test_sample_photos_are_what_the_script_writes(tmp_path):
    from pipeline.ingest.photo import read_photos

    sys.path.insert(0, str(ROOT / "scripts"))
    try:
        import make_sample_data
    finally:
        sys.path.remove(str(ROOT / "scripts"))
    truth = make_sample_data.make_photo_sample("h20_laser", tmp_path, write_config=False)
    fresh = tmp_path / "photos" / "h20_laser"
    for name in ("targets.csv", "marks.csv", "flight.yaml"):
        assert (SAMPLE / name).read_text() == (fresh / name).read_text(), name
    committed = json.loads((SAMPLE / "truth.json").read_text())
    assert [t["name"] for t in committed["targets"]] == [t["name"] for t in truth["targets"]]
    for c, t in zip(committed["targets"], truth["targets"], strict=True):
        assert [c[k] for k in ("lat_deg", "lon_deg", "alt_m")] == pytest.approx([t[k] for k in ("lat_deg", "lon_deg",
                                                                                                 "alt_m")])
    photos, bad = read_photos([SAMPLE])
    again, _ = read_photos([fresh])
    assert bad == [] and len(photos) == 5
    for p, q in zip(photos, again, strict=True):
        assert (p.lat_deg, p.lon_deg, p.alt_m) == (q.lat_deg, q.lon_deg, q.alt_m)
        assert (p.gimbal_ypr_deg, p.lrf_range_m, p.dji_target_lla) == (q.gimbal_ypr_deg, q.lrf_range_m,
                                                                       q.dji_target_lla)


def test_run_of_the_sample_flight_locates_its_three_targets():
    from pipeline.flight_config import load_flight_config
    from pipeline.run import process_group

    result = process_group(load_flight_config(ROOT / "configs" / "flights" / "h20_laser.yaml"))
    assert result.failed == []
    assert [r.target for r in result.targets] == ["laser_spot", "cairn", "gate"]
    for r in result.targets:
        truth = np.asarray(r.truth_m)
        e = r.estimates["mle"]
        d = e.position_m - truth
        assert float(d @ np.linalg.solve(e.covariance_m2, d)) < CHI2_3_95, r.target

        def horizontal(m, r=r, truth=truth):
            return float(np.linalg.norm((r.estimates[m].position_m - truth)[:2]))

        assert horizontal("mle") < horizontal("dem"), r.target
    laser = result.targets[0]
    assert laser.observations.has_range.all()  # the laser's spot: every photo's range
    assert {"los", "dji"} <= set(laser.estimates)
    assert not any(r.observations.has_range.any() for r in result.targets[1:])  # the others: pixels only
    assert "dji" not in result.targets[1].estimates  # DJI's laser target is not theirs
    assert laser.estimates["mle"].extras["error_model"]["source"] == "GNSS without RTK, laser"


def test_a_rerun_sees_a_change_of_the_photos_the_dem_or_the_marks():
    """`ridgeloc run` reuses a finished flight only while its inputs are unchanged: a photo flight's inputs are its
    photos, the DEM and the marks file, not only its config."""
    from pipeline.commands.run import _input_files
    from pipeline.flight_config import load_flight_config

    files = {p.name for p in _input_files(load_flight_config(ROOT / "configs" / "flights" / "h20_laser.yaml"))}
    assert {"dem.tif", "targets.csv", "truth.json"} <= files
    assert sum(name.endswith(".JPG") for name in files) == 5
