"""solve_batch splits large batches into chunks (`pipeline.solve.methods.CHUNK`): the answers must not depend on it
(beyond rounding: a vectorised sum may group its terms differently on arrays of another length)."""

import numpy as np
import pytest

from pipeline.solve import METHODS, solve_batch
from pipeline.solve import methods as solve_pkg
from support.scenes import paper_batch


@pytest.mark.parametrize("method", METHODS)
def test_chunked_batch_equals_one_batch(method, monkeypatch):
    batch = paper_batch(23, gamma_deg=15.0, seed=4)
    opts = {} if method in ("dlt", "los") else {"max_iterations": 8}
    whole = solve_batch(method, batch, **opts)
    monkeypatch.setattr(solve_pkg, "CHUNK", 5)
    x0 = np.nan_to_num(whole.position_m) + 1.0
    parts = solve_batch(method, batch, **opts)
    np.testing.assert_allclose(parts.position_m, whole.position_m, rtol=0, atol=1e-9)
    np.testing.assert_array_equal(parts.status, whole.status)
    np.testing.assert_array_equal(parts.iterations, whole.iterations)
    assert set(parts.extras) == set(whole.extras)
    for k, v in whole.extras.items():
        np.testing.assert_allclose(parts.extras[k], v, rtol=1e-9, atol=1e-9)
    if method not in ("dlt", "los"):  # a per-problem initial_m is split with the problems
        a = solve_batch(method, batch, initial_m=x0, max_iterations=3)
        monkeypatch.setattr(solve_pkg, "CHUNK", 10 ** 6)
        b = solve_batch(method, batch, initial_m=x0, max_iterations=3)
        np.testing.assert_allclose(a.position_m, b.position_m, rtol=0, atol=1e-9)
