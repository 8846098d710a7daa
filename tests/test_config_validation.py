"""Declarative validation at load: a config mistake is one line naming the file, the dotted key and a suggestion,
raised before any data is read; the estimators' option table agrees with what `solve` accepts."""

from __future__ import annotations

import copy
from pathlib import Path

import pytest
import yaml

from pipeline.errors import ConfigError
from pipeline.flight_config import load_flight_config, load_run_config
from pipeline.solve_options import METHODS, NOT_IN_CONFIG, OPTIONS, given_options

ROOT = Path(__file__).resolve().parents[1]


def _flight(tmp_path) -> dict:
    (tmp_path / "flight.tlog").write_bytes(b"x")
    return {"name": "g1", "files": {"telemetry": ["flight.tlog"]},
            "target": {"frame_index": 0, "pixel": [300.0, 200.0]},
            "sigma": {"pixel_px": 0.5, "range_m": 5.0, "position_m": 2.0, "attitude_deg": 0.2}}


def _write(path: Path, doc) -> Path:
    path.write_text(yaml.safe_dump(doc, sort_keys=False))
    return path


MISTAKES = [  # (change, the whole message after "<file>: ")
    (lambda d: d.update(solve={"options": {"mle": {"robst": "huber"}}}),
     "solve.options.mle.robst: unknown key (did you mean 'robust'?)"),
    (lambda d: d.update(solve={"options": {"mle": {"terrain": 5.0}}}),
     "solve.options.mle.terrain: not an option of solve.options (give the DEM as the flight config's top-level "
     "`terrain: {dem: DEM.tif, vertical_sigma_m: ...}`)"),
    (lambda d: d["sigma"].update(range_m=-1),
     "sigma.range_m: must be >= 0, got -1 (did you mean 1?)"),
    (lambda d: d.update(sigmas=d.pop("sigma")),
     "sigmas: unknown key (did you mean 'sigma'?)"),
    (lambda d: d.update(solve={"methods": ["fusion", "rigde"]}),
     "solve.methods[1]: must be one of 'dlt', 'vision', 'range', 'los', 'fusion-raw', 'fusion', 'ridge', 'mle', "
     "got 'rigde' (did you mean 'ridge'?)"),
    (lambda d: d.update(solve={"methods": "mel"}),
     "solve.methods: must be one of 'dlt', 'vision', 'range', 'los', 'fusion-raw', 'fusion', 'ridge', 'mle', 'all', "
     "got 'mel' (did you mean 'mle'?)"),
    (lambda d: d.update(solve={"options": {"mel": {"robust": "huber"}}}),
     "solve.options.mel: unknown key (did you mean 'mle'?)"),
    (lambda d: d.update(solve={"options": {"ridge": {"hkb": "papr"}}}),
     "solve.options.ridge.hkb: must be one of 'paper', 'textbook', got 'papr' (did you mean 'paper'?)"),
    (lambda d: d.update(solve={"options": {"fusion-raw": {"tol": 0.001}}}),
     "solve.options.fusion-raw.tol: unknown key (did you mean 'tol_m'?)"),
    (lambda d: d.update(solve={"options": {"mle": {"sigma": {"range_m": -2.0}}}}),
     "solve.options.mle.sigma.range_m: must be >= 0, got -2.0 (did you mean 2.0?)"),
    (lambda d: d.update(solve={"options": {"dlt": {"tol_m": 0.001}}}),
     "solve.options.dlt.tol_m: unknown key (known: )"),
    (lambda d: d.update(observations={"frame_tolerance_s": 0}),
     "observations.frame_tolerance_s: must be > 0, got 0"),
    (lambda d: d.update(tracking={"ratio": 1.5}),
     "tracking.ratio: must be < 1, got 1.5"),
]


@pytest.mark.parametrize(("change", "message"), MISTAKES)
def test_a_mistake_is_one_line_naming_file_key_and_suggestion(tmp_path, change, message):
    doc = _flight(tmp_path)
    change(doc)
    path = _write(tmp_path / "bad.yaml", doc)
    with pytest.raises(ConfigError) as info:
        load_flight_config(path)
    assert str(info.value) == f"{path}: {message}"


def test_check_and_run_refuse_a_mistake_before_reading_data(tmp_path, capsys):
    from pipeline.cli import main

    doc = _flight(tmp_path)
    doc["solve"] = {"options": {"mle": {"robst": "huber"}}}
    path = _write(tmp_path / "bad.yaml", doc)  # its telemetry file is 1 byte of garbage: never read
    for cmd in (["check", str(path)], ["run", str(path), "-q", "-o", str(tmp_path / "out")]):
        assert main(cmd) != 0
        out, err = capsys.readouterr()
        assert err.splitlines() == [
            f"ridgeloc: error: {path}: solve.options.mle.robst: unknown key (did you mean 'robust'?)"]
        assert out == ""
        assert not (tmp_path / "out").exists()


def test_a_mapping_typo_names_the_config_file_not_a_log(tmp_path, capsys):
    """`mapping:` is checked against the readers' keys when the logs are opened: the error names the config file and
    the dotted key, as every other config mistake does, before the (1 byte of garbage) telemetry is read."""
    from pipeline.cli import main

    doc = _flight(tmp_path)
    doc["mapping"] = {"klv": {"azimuth_nort": "grid"}}
    path = _write(tmp_path / "bad.yaml", doc)
    for cmd in (["check", str(path)], ["run", str(path), "-q", "-o", str(tmp_path / "out")]):
        assert main(cmd) != 0
        _out, err = capsys.readouterr()
        assert f"{path}: mapping.klv: unknown key 'azimuth_nort' (did you mean 'azimuth_north'? known: " \
               "azimuth_north)" in err, (cmd, err)
        assert "Traceback" not in err
        assert not (tmp_path / "out").exists()


def test_numbers_with_an_exponent_are_numbers(tmp_path):
    """`1e-6` and `2.5e3` are numbers as a user (and YAML 1.2) writes them; PyYAML's YAML 1.1 resolver read them as
    text, which the schema refused as "must be a plain number (the unit is in the key's name)". Quoted, a string."""
    (tmp_path / "flight.tlog").write_bytes(b"x")
    head = "name: g1\nfiles: {telemetry: [flight.tlog]}\n"
    path = tmp_path / "f.yaml"
    path.write_text(head + "sigma: {range_m: 5e-1, position_m: 2E0, attitude_deg: .2e+0}\n"
                    "target: {frame_index: 0, pixel: [3e2, 2.0e2]}\n")
    cfg = load_flight_config(path)
    assert (cfg.sigma.range_m, cfg.sigma.position_m, cfg.sigma.attitude_deg) == (0.5, 2.0, 0.2)
    assert tuple(cfg.target.pixel) == (300.0, 200.0)
    path.write_text(head + "sigma: {range_m: '5e-1'}\n")
    with pytest.raises(ConfigError, match=r"sigma\.range_m: must be a plain number"):
        load_flight_config(path)


def test_a_geoid_separation_no_geoid_has_is_refused(tmp_path):
    doc = _flight(tmp_path)
    doc["altitude"] = {"geoid_separation_m": 1200.0}  # an altitude typed into the wrong key, say
    with pytest.raises(ConfigError) as info:
        load_flight_config(_write(tmp_path / "bad.yaml", doc))
    assert "altitude: geoid_separation_m must be within +-150 m" in str(info.value)
    doc["altitude"] = {"geoid_separation_m": -106.5}
    assert load_flight_config(_write(tmp_path / "ok.yaml", doc)).altitude.geoid_separation_m == -106.5


def test_good_options_are_read_as_a_plain_dict_of_the_given_keys(tmp_path):
    doc = _flight(tmp_path)
    doc["solve"] = {"methods": ["ridge", "mle"],
                    "options": {"ridge": {"hkb": "textbook", "k": 0},
                                "mle": {"robust": None, "sigma": {"range_m": 3}, "bias_prior_deg": 0.5},
                                "fusion-raw": {"initial_m": [1, 2, 3]}}}
    cfg = load_flight_config(_write(tmp_path / "ok.yaml", doc))
    assert cfg.solve.methods == ("ridge", "mle")
    # robust: null (the squared loss) is a given value, not "left out"; sigma keeps only its given keys
    assert cfg.solve.options == {"fusion-raw": {"initial_m": (1.0, 2.0, 3.0)},
                                 "ridge": {"hkb": "textbook", "k": 0.0},
                                 "mle": {"robust": None, "sigma": {"range_m": 3.0}, "bias_prior_deg": 0.5}}
    assert cfg.to_dict()["solve"]["options"]["mle"] == {"robust": None, "sigma": {"range_m": 3.0},
                                                        "bias_prior_deg": 0.5}
    assert load_flight_config(_write(tmp_path / "none.yaml", _flight(tmp_path))).solve.options == {}


def test_the_option_table_is_what_solve_accepts():
    from pipeline.solve import METHODS as SOLVE_METHODS
    from pipeline.solve.methods import _OPTIONS, _check_options
    from pipeline.solve.observations import Sigma

    assert SOLVE_METHODS is METHODS and set(OPTIONS) == set(METHODS)
    for m in METHODS:
        assert {o.name for o in OPTIONS[m]} | NOT_IN_CONFIG.get(m, frozenset()) == _OPTIONS[m], m
    # every literal value the table allows is one solve accepts, and the sigma option's keys are Sigma's
    _check_options("ridge", {"hkb": "textbook"})
    for robust in ("redescending", "huber", "cauchy", None):
        _check_options("mle", {"robust": robust})
    sigma = next(o.type for o in OPTIONS["mle"] if o.name == "sigma")
    import dataclasses
    assert [f.name for f in dataclasses.fields(sigma)] == [f.name for f in dataclasses.fields(Sigma)]
    assert given_options({"mle": {"robust": "huber"}}) == {"mle": {"robust": "huber"}}


@pytest.mark.parametrize("path", sorted((ROOT / "configs" / "flights").glob("*.yaml")), ids=lambda p: p.stem)
def test_every_shipped_flight_config_loads(path):
    if not (ROOT / "sample_data" / "group1").is_dir():
        pytest.skip("sample_data/ is not present")
    assert load_flight_config(path).name == path.stem


def test_a_manifest_and_a_run_config_are_one_parser(tmp_path):
    _write(tmp_path / "a.yaml", _flight(tmp_path))
    b = copy.deepcopy(_flight(tmp_path))
    b["name"] = "g2"
    _write(tmp_path / "b.yaml", b)
    manifest = _write(tmp_path / "manifest.yaml", ["a.yaml", "b.yaml"])
    run = _write(tmp_path / "run.yaml", {"description": "two", "groups": ["a.yaml", "b.yaml"]})
    assert [e.config.name for e in load_run_config(manifest)] == ["g1", "g2"]
    assert [e.config.name for e in load_run_config(run)] == ["g1", "g2"]
    with pytest.raises(ConfigError, match=r"run\.yaml: descripton: unknown key \(did you mean 'description'\?\)"):
        load_run_config(_write(tmp_path / "run.yaml", {"descripton": "two", "groups": ["a.yaml"]}))
    with pytest.raises(ConfigError, match=r"manifest\.yaml: groups\[1\]: must be a string, got int 3"):
        load_run_config(_write(tmp_path / "manifest.yaml", ["a.yaml", 3]))
