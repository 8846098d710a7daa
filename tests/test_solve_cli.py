"""`ridgeloc solve` on the shipped example file and on broken files; the example file is reproducible."""

import importlib.util
import json
from pathlib import Path

import numpy as np
import pytest

from pipeline.cli import main
from pipeline.observation_file import to_dict
from pipeline.solve import METHODS

ROOT = Path(__file__).resolve().parent.parent
EXAMPLE = ROOT / "configs" / "example_observations.json"


def _load_script():
    spec = importlib.util.spec_from_file_location("make_example", ROOT / "scripts" / "make_example_observations.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _numbers_close(a, b):
    if isinstance(a, dict):
        assert a.keys() == b.keys()
        for k in a:
            _numbers_close(a[k], b[k])
    elif isinstance(a, list):
        assert len(a) == len(b)
        for x, y in zip(a, b, strict=True):
            _numbers_close(x, y)
    elif isinstance(a, float):
        assert a == pytest.approx(b, rel=1e-12, abs=1e-9)
    else:
        assert a == b


def test_example_file_is_what_the_script_generates():
    _numbers_close(_load_script().build(), json.loads(EXAMPLE.read_text()))


def test_solve_all_json(capsys):
    assert main(["solve", str(EXAMPLE), "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    est = doc["estimates"]
    assert list(est) == list(METHODS)
    for d in est.values():
        assert len(d["position_m"]) == 3
        assert isinstance(d["iterations"], int) and isinstance(d["converged"], bool)
        assert "condition_number" in d and d["error_m"] >= 0
    assert len(est["los"]["points_m"]) == 10 and est["los"]["points_m"][3] is None  # frame 3 has no pixel
    assert est["los"]["oracle_error_m"] > 0
    assert np.array(est["mle"]["covariance_m2"]).shape == (3, 3)
    assert 0 < est["mle"]["cep50_m"] < est["mle"]["cep90_m"]
    # the weighted MLE is accurate on this problem; the paper's range-only is not (small arc)
    assert est["mle"]["error_m"] < 15
    assert est["range"]["error_m"] > est["mle"]["error_m"]


def test_solve_table_and_selected_methods(capsys):
    assert main(["solve", str(EXAMPLE), "--method", "vision", "--method", "mle"]) == 0
    out = capsys.readouterr().out
    lines = out.splitlines()
    # the answer first (the weighted MLE: its fit checks pass here), then every method
    assert lines[0].startswith("answer: mle at (") and "CE90" in lines[0] and lines[1] == ""
    assert lines[2].split()[:4] == ["method", "x_m", "y_m", "z_m"]
    assert lines[3].startswith("vision") and lines[4].startswith("mle")
    assert "CEP50" in out


def _write(tmp_path, doc):
    path = tmp_path / "obs.json"
    path.write_text(json.dumps(doc))
    return path


def test_bad_file_is_one_line_error(tmp_path, capsys):
    doc = json.loads(EXAMPLE.read_text())
    doc["observations"][2]["P"] = [[1, 2, 3]]
    path = _write(tmp_path, doc)
    assert main(["solve", str(path)]) == 1
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and str(path) in err and "must be 3x4" in err


def test_method_that_cannot_solve_exits_non_zero(tmp_path, capsys):
    doc = json.loads(EXAMPLE.read_text())
    for row in doc["observations"][2:]:
        row["range_m"] = None
    path = _write(tmp_path, doc)
    assert main(["solve", str(path), "--method", "range"]) == 1
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "at least three laser ranges" in err
    # --method all (the default): the others solve, range is listed with its status and reason, exit 0
    for argv in (["solve", str(path), "--json"], ["solve", str(path), "--method", "all", "--json"]):
        assert main(argv) == 0
        doc = json.loads(capsys.readouterr().out)
        assert doc["unsolved"]["range"]["status"] == "insufficient_data"
        assert "at least three laser ranges" in doc["unsolved"]["range"]["reason"]
        assert "range" not in doc["estimates"] and "mle" in doc["estimates"] and "vision" in doc["estimates"]
    assert main(["solve", str(path)]) == 0
    out = capsys.readouterr().out
    assert "range      not solved (insufficient_data): range needs at least three laser ranges" in out
    # named methods must all solve
    assert main(["solve", str(path), "--method", "mle", "--method", "range"]) == 1
    assert "at least three laser ranges" in capsys.readouterr().err


def test_method_all_fails_only_when_nothing_solves(tmp_path, capsys):
    doc = json.loads(EXAMPLE.read_text())
    for i, row in enumerate(doc["observations"]):
        row["pixel"] = None
        if i >= 2:
            row["range_m"] = None
    path = _write(tmp_path, doc)
    assert main(["solve", str(path), "--method", "all"]) == 1
    captured = capsys.readouterr()
    assert "not solved" in captured.out and captured.err.count("\n") == 1 and "estimators failed" in captured.err


def test_unknown_method_is_rejected_by_argparse(capsys):
    with pytest.raises(SystemExit) as info:
        main(["solve", str(EXAMPLE), "--method", "magic"])
    assert info.value.code == 2


def test_a_gross_pixel_outlier_is_listed_with_its_time_in_the_table_and_json(tmp_path, capsys):
    """Issue 12: a mis-tracked pixel (60 px off, ~17 sigma) gets zero weight in mle; the console names the
    observation, which residual, its time in the flight and its size; --json lists it under `rejected`."""
    from support.scenes import paper_problem

    doc = to_dict(paper_problem(n=20, gamma_deg=30.0, seed=5))  # frames 1 s apart
    doc["observations"][6]["pixel"][0] += 60.0
    path = _write(tmp_path, doc)
    assert main(["solve", str(path), "--method", "mle"]) == 0
    out = capsys.readouterr().out
    # a frame's pixel is rejected whole (u and v), said once
    assert ("mle: rejected the pixel of observation 6 (t = 6.00 s after the first observation): residual (+6"
            in out) and "zero weight" in out and out.count("rejected the pixel") == 1
    assert main(["solve", str(path), "--method", "mle", "--json"]) == 0
    rejected = json.loads(capsys.readouterr().out)["estimates"]["mle"]["rejected"]
    assert [(r["frame"], r["residual"], r["t_ns"]) for r in rejected] == [(6, "u", 6_000_000_000),
                                                                         (6, "v", 6_000_000_000)]
    assert rejected[0]["value"] == pytest.approx(60.0, abs=3.0) and rejected[0]["sigmas"] > 8
    assert abs(rejected[1]["value"]) < 3.0
    # without timestamps (t_ns defaults to the frame's index) there is no time in the flight to give
    for row in doc["observations"]:
        del row["t_ns"]
    assert main(["solve", str(_write(tmp_path, doc)), "--method", "mle"]) == 0
    assert "mle: rejected the pixel of observation 6 (t_ns 6): residual" in capsys.readouterr().out


def test_method_all_on_a_file_without_pixels_solves_what_ranges_can(tmp_path, capsys):
    """Issue 12: a file with no pixels. range solves from the laser ranges; the methods that need pixels (mle
    among them: no honest covariance from ranges alone) are listed as insufficient_data with their reason;
    exit 0."""
    doc = json.loads(EXAMPLE.read_text())
    for row in doc["observations"]:
        row["pixel"] = None
    assert main(["solve", str(_write(tmp_path, doc)), "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert sorted(out["estimates"]) == ["range"]
    assert sorted(out["unsolved"]) == ["dlt", "fusion", "fusion-raw", "los", "mle", "ridge", "vision"]
    assert {u["status"] for u in out["unsolved"].values()} == {"insufficient_data"}
    assert all("pixel" in u["reason"] for u in out["unsolved"].values())
