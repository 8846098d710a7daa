"""`terrain:` in a flight config: the `dem` method in `ridgeloc run` for video/log flights (pipeline.terrain.flight)."""

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from pipeline.errors import ConfigError
from pipeline.flight_config import Terrain, flight_config_from_dict, load_flight_config
from pipeline.run import process_group
from pipeline.synth.dem import Hills, write_dem

ROOT = Path(__file__).resolve().parents[1]
GROUP6 = ROOT / "configs" / "flights" / "group6.yaml"


def test_the_terrain_section_resolves_its_dem_and_checks_its_values(tmp_path):
    dem = write_dem(tmp_path / "dem.tif", Hills(34.36, 108.76, ridges=()), extent_m=600.0)
    doc = {"name": "t", "files": {"telemetry": [str(ROOT / "sample_data/group6/flight.tlog")]},
           "terrain": {"dem": "dem.tif", "vertical_sigma_m": 4.0}}
    cfg = flight_config_from_dict(doc, tmp_path / "flight.yaml")
    assert cfg.terrain == Terrain(dem=str(dem.resolve()), vertical_sigma_m=4.0)
    with pytest.raises(ConfigError, match=r"terrain\.dem: file not found"):
        flight_config_from_dict({**doc, "terrain": {"dem": "nope.tif"}}, tmp_path / "flight.yaml")
    with pytest.raises(ConfigError, match="vertical_sigma_m"):
        flight_config_from_dict({**doc, "terrain": {"dem": "dem.tif", "vertical_sigma_m": -1}}, tmp_path / "f.yaml")
    with pytest.raises(ConfigError, match="vertical_datum"):
        flight_config_from_dict({**doc, "terrain": {"dem": "dem.tif", "vertical_datum": "navd88"}}, tmp_path / "f.yaml")


@pytest.mark.skipif(not (ROOT / "sample_data/group6/flight.tlog").is_file(), reason="sample data absent")
def test_dem_runs_on_a_video_flight_and_a_dem_that_misses_is_reported(tmp_path):
    """group6 (5 km slant range, 23 deg down, attitude sigma 0.2 deg) over a flat DEM at the target's true
    ellipsoidal height: `dem` lands as close as the laser's `los` does (both ~15-20 m here); a DEM away from the
    target leaves `dem` unsolved with one line naming a frame and its pixel."""
    cfg = load_flight_config(GROUP6)
    truth = cfg.truth_lla()
    flat = write_dem(tmp_path / "flat.tif", Hills(truth[0], truth[1], base_m=truth[2], ridges=()), extent_m=3000.0,
                     crs="EPSG:4979")
    r = process_group(dataclasses.replace(cfg, terrain=Terrain(dem=str(flat))))
    dem = r.estimates["dem"]
    assert dem.extras["n_points"] == r.observations.has_pixel.sum() and not dem.extras["missed"]
    assert dem.error_m(r.truth_m) < 30.0
    assert dem.error_m(r.truth_m) < 2 * r.estimates["los"].error_m(r.truth_m)

    away = write_dem(tmp_path / "away.tif", Hills(truth[0] + 0.2, truth[1], base_m=truth[2], ridges=()),
                     extent_m=1000.0, crs="EPSG:4979")
    r = process_group(dataclasses.replace(cfg, terrain=Terrain(dem=str(away))))
    assert "dem" not in r.estimates and "mle" in r.estimates
    failure = r.settings["solve_failures"]["dem"]
    assert failure["status"] == "degenerate" and "\n" not in failure["reason"]
    assert failure["reason"].startswith("dem: frame ") and "pixel (" in failure["reason"]
    assert "away.tif" in failure["reason"]
    assert np.isfinite(r.estimates["mle"].position_m).all()
