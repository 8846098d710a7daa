import copy

import pytest
import yaml

from pipeline.errors import ConfigError
from pipeline.flight_config import flight_config_from_dict, load_flight_config, load_run_config


def _doc():
    return {
        "name": "g1",
        "files": {"telemetry": ["flight.tlog"], "video": "video.mp4"},
        "camera": {"width_px": 600, "height_px": 400, "fx_px": 1000, "fy_px": 1000.5, "cx_px": 300, "cy_px": 200,
                   "dist": [0.01, 0, 0, 0, 0]},
        "target": {"frame_index": 3, "pixel": [301.5, 199]},
        "clock": {"video_to_telemetry_offset_ns": 1_700_000_000_000_000_000},
        "origin": {"lat_deg": 30, "lon_deg": 114, "alt_m": 10},
        "sigma": {"pixel_px": 1.0},
    }


@pytest.fixture
def flight_dir(tmp_path):
    (tmp_path / "data").mkdir()
    for name in ("flight.tlog", "video.mp4"):
        (tmp_path / "data" / name).write_bytes(b"x")
    return tmp_path


def _write(path, doc):
    path.write_text(yaml.safe_dump(doc))
    return path


def test_paths_resolve_relative_to_the_config_and_values_are_typed(flight_dir):
    doc = _doc()
    doc["files"] = {"telemetry": ["data/flight.tlog"], "video": "data/video.mp4"}
    cfg = load_flight_config(_write(flight_dir / "g1.yaml", doc))
    assert cfg.files.telemetry == (str((flight_dir / "data/flight.tlog").resolve()),)
    assert cfg.files.video == str((flight_dir / "data/video.mp4").resolve())
    assert cfg.camera.fy_px == 1000.5 and isinstance(cfg.camera.width_px, int)
    assert cfg.camera.K[0, 2] == 300.0
    assert cfg.clock.video_to_telemetry_offset_ns == 1_700_000_000_000_000_000
    assert cfg.origin.as_tuple() == (30.0, 114.0, 10.0)
    assert cfg.observations.mode == "range_times" and cfg.tracking.ratio == 0.75  # defaults
    assert cfg.to_dict()["camera"]["fx_px"] == 1000.0


@pytest.mark.parametrize(("change", "message"), [
    (lambda d: d["camera"].update(fx=1000), r"camera\.fx: unknown key \(did you mean 'fx_px'\?\)"),
    (lambda d: d["camera"].update(fx_px="1000 px"), r"camera\.fx_px: must be a plain number \(the unit"),
    (lambda d: d.update(colour="red"), r"colour: unknown key"),
    (lambda d: d["clock"].update(video_to_telemetry_offset_ns=1.5), r"must be an integer"),
    (lambda d: d["camera"].update(dist=[1, 2, 3]), r"'dist' must be"),
    (lambda d: d["camera"].pop("fx_px"), r"camera: give all of .* or none .*missing: fx_px"),
    (lambda d: d["clock"].update(video_offset_s=2.5), r"give one of video_to_telemetry_offset_ns and video_offset_s"),
    (lambda d: d["clock"].update(video_to_telemetry_offset_ns=0, video_start="yesterday"), r"'video_start' must be"),
    (lambda d: d["clock"].update(search_s=0.0), r"clock\.search_s: must be > 0"),
    (lambda d: d.update(origin="here"), r"'origin' must be 'auto'"),
    (lambda d: d["origin"].update(lat_deg=95), r"origin\.lat_deg: must be <= 90"),
    (lambda d: d.update(observations={"mode": "every"}), r"observations\.mode: must be one of"),
    (lambda d: d.update(lever_arms_m={"camera": [1, 2]}), r"lever_arms_m\.camera: must have 3 elements"),
    (lambda d: d["target"].pop("pixel"), r"give either"),
    (lambda d: d["files"].update(video="nope.mp4"), r"files\.video: file not found: .*nope\.mp4"),
    (lambda d: d.update(name="a/b"), r"folder-safe"),
    (lambda d: d.update(name="COT"), r"taken by the run's TAK events"),
])
def test_mistakes_are_named(flight_dir, change, message):
    doc = copy.deepcopy(_doc())
    doc["files"] = {"telemetry": ["data/flight.tlog"], "video": "data/video.mp4"}
    change(doc)
    path = _write(flight_dir / "bad.yaml", doc)
    with pytest.raises(ConfigError, match=message) as exc:
        load_flight_config(path)
    assert str(path) in str(exc.value)


def test_missing_and_malformed_files(tmp_path):
    with pytest.raises(ConfigError, match="config file not found"):
        load_flight_config(tmp_path / "none.yaml")
    (tmp_path / "bad.yaml").write_text("name: [unclosed\n")
    with pytest.raises(ConfigError, match="not valid YAML at line"):
        load_flight_config(tmp_path / "bad.yaml")
    (tmp_path / "list.yaml").write_text("- 1\n")
    with pytest.raises(ConfigError, match="top level must be a mapping"):
        load_flight_config(tmp_path / "list.yaml")


def test_run_config_lists_groups_and_keeps_a_bad_group_as_an_error(flight_dir):
    good = _doc()
    good["files"] = {"telemetry": ["data/flight.tlog"]}
    _write(flight_dir / "good.yaml", good)
    bad = copy.deepcopy(good)
    bad["name"] = "g2"
    bad["files"]["telemetry"] = ["data/missing.tlog"]
    _write(flight_dir / "bad.yaml", bad)
    run = _write(flight_dir / "run.yaml", {"groups": ["good.yaml", "bad.yaml"]})
    entries = load_run_config(run)
    assert entries[0].config.name == "g1" and entries[0].error is None
    assert entries[1].config is None and "missing.tlog" in entries[1].error
    single = load_run_config(flight_dir / "good.yaml")
    assert len(single) == 1 and single[0].config.name == "g1"
    with pytest.raises(ConfigError, match=r"r2\.yaml: output: unknown key \(did you mean 'groups'\?\)"):
        load_run_config(_write(flight_dir / "r2.yaml", {"groups": ["good.yaml"], "output": "x"}))


def test_truth_from_file(flight_dir):
    (flight_dir / "truth.json").write_text('{"target": {"lat_deg": 1.5, "lon_deg": 2.5, "alt_m": 3.5}}')
    doc = _doc()
    doc["files"] = {"telemetry": ["data/flight.tlog"]}
    doc["truth_file"] = "truth.json"
    cfg = flight_config_from_dict(doc, flight_dir / "x.yaml")
    assert cfg.truth_lla() == (1.5, 2.5, 3.5)


def test_the_bundled_sample_configs_load():
    from pathlib import Path

    root = Path(__file__).resolve().parents[1]
    if not (root / "sample_data" / "group1").is_dir():
        pytest.skip("sample_data/ is not present")
    entries = load_run_config(root / "configs" / "sample.yaml")
    assert [e.error for e in entries] == [None] * len(entries)
    names = [e.config.name for e in entries]
    assert names == ["group1", "group2", "group3", "group4", "group5", "group6", "hard_outliers", "angle10", "fmv",
                     "three_targets", "h20_laser"]  # three_targets: issue 21; h20_laser: drone photos, issue 22
    for e in entries:
        assert Path(e.config.truth_file).parent.name == e.config.name
        if e.config.files.photos:  # a photo flight: photos, marks and a DEM, no video or observation plan
            assert e.config.terrain is not None and (e.config.files.marks or e.config.marks_file)
            continue
        # fmv: continuous full-motion video, every laser shot an observation; the others: triggered bursts
        mode = "range_times" if e.config.name == "fmv" else "bursts"
        assert e.config.observations.mode == mode and e.config.sigma.range_m == 5.0


def test_geoid_separation_auto_is_the_geoid_model_at_the_first_position(flight_dir):
    """`altitude.geoid_separation_m: auto` resolves to EGM2008's N where the flight starts; a word other than auto
    is refused with the key named."""
    from types import SimpleNamespace

    import numpy as np

    from pipeline.flight import geoid_separation_m
    from pipeline.geometry.geoid import geoid_undulation_m

    doc = copy.deepcopy(_doc())
    doc["files"] = {"telemetry": ["data/flight.tlog"], "video": "data/video.mp4"}
    doc["altitude"] = {"geoid_separation_m": "auto"}
    cfg = load_flight_config(_write(flight_dir / "g1.yaml", doc))
    assert cfg.altitude.geoid_separation_m == "auto"
    log = SimpleNamespace(position=SimpleNamespace(lat_deg=np.array([np.nan, 20.0, 21.0]),
                                                   lon_deg=np.array([np.nan, 50.0, 50.0])))
    # GeographicLib GeoidEval (egm2008-1) gives -30.7048 m at (20 N, 50 E): see tests/test_geoid.py
    assert geoid_separation_m(cfg, log) == pytest.approx(-30.7048, abs=0.003)
    assert geoid_separation_m(cfg, log) == pytest.approx(float(geoid_undulation_m(20.0, 50.0)))
    doc["altitude"] = {"geoid_separation_m": -28.5}
    cfg = load_flight_config(_write(flight_dir / "g1.yaml", doc))
    assert geoid_separation_m(cfg, log) == -28.5
    doc["altitude"] = {"geoid_separation_m": "egm96"}
    with pytest.raises(ConfigError, match=r"altitude: geoid_separation_m must be a number \(m\) or .auto."):
        load_flight_config(_write(flight_dir / "bad.yaml", doc))


def test_camera_default_mounting_is_the_geometry_convention():
    """flight_config sits below geometry in the layers, so Camera keeps its own literal: it must stay the one
    pipeline.geometry.pose uses (optical x = gimbal right (y), optical y = down (z), optical z = forward (x))."""
    import numpy as np

    from pipeline.flight_config import Camera
    from pipeline.geometry.pose import R_OPTICAL_FROM_GIMBAL_DEFAULT

    expected = [[0, 1, 0], [0, 0, 1], [1, 0, 0]]
    np.testing.assert_array_equal(Camera().R_optical_from_gimbal, expected)
    np.testing.assert_array_equal(R_OPTICAL_FROM_GIMBAL_DEFAULT, expected)
