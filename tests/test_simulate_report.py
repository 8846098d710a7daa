"""Statistics and output files of the simulation, on hand-made estimator answers (no real estimators)."""

import csv
import json
import zlib

import numpy as np
import pytest

import pipeline.solve
from pipeline.simulate import SimulationConfig, run_simulation, write_outputs
from pipeline.simulate.statistics import summarize
from pipeline.solve.estimate import BatchEstimate, Status


def _estimate(positions, status, iterations=None, cond=None):
    positions = np.asarray(positions, dtype=float)
    B = len(positions)
    return BatchEstimate(method="x", position_m=positions,
                         iterations=np.zeros(B, int) if iterations is None else np.asarray(iterations),
                         status=np.asarray(status, dtype=np.int8),
                         condition_number=np.full(B, np.nan) if cond is None else np.asarray(cond, float))


def test_summarize_counts_failures_apart_from_errors():
    truth = np.zeros((5, 3))
    est = _estimate([[3, 4, 0], [0, 0, 1], [0, 2, 0], [1e60, 0, 0], [np.nan] * 3],
                    [Status.CONVERGED, Status.MAX_ITERATIONS, Status.CONVERGED, Status.DEGENERATE, Status.DIVERGED],
                    iterations=[3, 100, 4, 7, 9], cond=[10, 20, 30, np.inf, 50])
    s = summarize(est, truth)
    # answered: errors 5, 1, 2 (the iteration-limit trial still answered; degenerate and diverged did not)
    assert s["median_m"] == pytest.approx(2.0)
    assert s["rms_m"] == pytest.approx(np.sqrt((25 + 1 + 4) / 3))
    assert s["nonconverged_pct"] == pytest.approx(60.0)
    assert s["degenerate_pct"] == pytest.approx(20.0)
    assert s["failed_pct"] == pytest.approx(40.0)
    assert s["median_iterations"] == 7
    assert s["median_condition"] == pytest.approx(25.0)


def test_summarize_all_degenerate_gives_no_error_figure():
    est = _estimate([[1e60, 0, 0]] * 4, [Status.DEGENERATE] * 4)
    s = summarize(est, np.zeros((4, 3)))
    assert np.isnan(s["median_m"]) and np.isnan(s["rms_m"])
    assert s["degenerate_pct"] == 100.0


def _fake_solve_batch(method, batch, **options):
    """A stand-in with known behaviour: the truth plus seeded noise of a method-dependent size; `range` on a
    few trials reports DEGENERATE, `los` gives per-frame points."""
    B, n = batch.size, batch.n
    scale = {"vision": 50.0, "range": 100.0, "mle": 5.0}.get(method, 20.0)
    rng = np.random.default_rng(zlib.crc32(f"{method}{batch.range_m[0, 0]}".encode()))
    pos = batch.truth_m + scale * rng.standard_normal((B, 3))
    status = np.zeros(B, np.int8)
    if method == "range":
        status[:2] = Status.DEGENERATE
    extras = {}
    if method == "los":
        status[:] = Status.CLOSED_FORM
        extras["points_m"] = batch.truth_m[:, None, :] + 30.0 * rng.standard_normal((B, n, 3))
    return BatchEstimate(method=method, position_m=pos, iterations=np.full(B, 3), status=status,
                         condition_number=np.full(B, 10.0), extras=extras)


def test_outputs_have_the_documented_layout(tmp_path, monkeypatch):
    monkeypatch.setattr(pipeline.solve, "solve_batch", _fake_solve_batch, raising=False)
    cfg = SimulationConfig(trials=20, angles_deg=(10.0, 45.0, 80.0), methods=("vision", "range", "los", "mle"))
    result = run_simulation(cfg)
    paths = write_outputs(result, tmp_path / "out")
    assert sorted(p.name for p in paths) == ["fig4.png", "fig5.png", "summary.json", "table2.csv", "table2.md"]
    with open(tmp_path / "out" / "table2.csv") as f:
        rows = list(csv.reader(f))
    assert rows[0] == ["method", "statistic", "10", "45", "80"]
    keyed = {(r[0], r[1]): r[2:] for r in rows[1:]}
    for m in ("vision", "range", "los", "los-oracle", "mle"):
        for stat in ("median_m", "rms_m", "nonconverged_pct", "median_iterations"):
            assert (m, stat) in keyed
    assert keyed[("range", "degenerate_pct")] == ["10", "10", "10"]
    # the paper's Table 2 rows, only at the paper's angles
    assert keyed[("paper:ridge", "median_m")] == ["22.52", "", "14.79"]
    assert ("paper:ridge", "rms_m") not in keyed
    # the oracle picks the best frame: never worse than a single frame's typical error
    assert float(keyed[("los-oracle", "median_m")][0]) < 30.0
    md = (tmp_path / "out" / "table2.md").read_text()
    assert "| *paper:vision* | *355.52* | *–* | *35.96* |" in md
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert summary["config"]["trials"] == 20 and set(summary["method_seconds"]) == set(cfg.methods)
    assert (tmp_path / "out" / "fig4.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
