"""`solve_problems` (a flight's targets solved together) gives what `solve` gives one problem at a time: the same
estimates, covariances, iterations, statuses and multistart choices, and the same error where `solve` raises."""

import dataclasses

import numpy as np
import pytest

from pipeline.solve import METHODS, solve
from pipeline.solve.methods import SOLVE_ERRORS, solve_problems
from support.scenes import PAPER_SIGMA, correlated_problems, paper_problem


def _problems():
    probs = [paper_problem(seed=s) for s in range(3)]  # one group: n = 10, one sigma, with truth
    probs.append(paper_problem(n=12, seed=5))  # a group of its own
    no_truth = paper_problem(seed=7)
    probs.append(dataclasses.replace(no_truth, truth_m=None))
    no_range = paper_problem(seed=8)  # fusion, ridge, range and los cannot run
    probs.append(dataclasses.replace(no_range, range_m=np.full(no_range.n, np.nan)))
    lost = paper_problem(seed=9)  # pixels lost in two frames
    pix = lost.pixel.copy()
    pix[[2, 6]] = np.nan
    probs.append(dataclasses.replace(lost, pixel=pix))
    # drifting telemetry errors the stated sigma gives no correlation time for: the learned drift model
    probs += correlated_problems(3, n=16, seed=1, attitude_tau_s=30.0, position_tau_s=120.0)
    # and in their group (n = 16, the same sigma) two with white errors: answers with and without a drift model in
    # one batch, whose extras differ (error_model; the boresight bias)
    probs += [paper_problem(n=16, seed=s) for s in (11, 12)]
    return probs


def _one_by_one(problems, methods, options):
    out = []
    for obs in problems:
        r = {}
        for m in methods:
            try:
                r[m] = solve(m, obs, **options.get(m, {}))
            except SOLVE_ERRORS as exc:
                r[m] = exc
        out.append(r)
    return out


def _assert_same(a, b):
    assert list(a) == list(b)
    for m in a:
        x, y = a[m], b[m]
        if isinstance(x, Exception):
            assert type(y) is type(x) and str(y) == str(x), (m, x, y)
            continue
        assert not isinstance(y, Exception), (m, y)
        assert (x.status, x.iterations) == (y.status, y.iterations), m
        np.testing.assert_allclose(y.position_m, x.position_m, rtol=1e-10, atol=1e-9, err_msg=m)
        if x.covariance_m2 is not None:
            np.testing.assert_allclose(y.covariance_m2, x.covariance_m2, rtol=1e-8, atol=1e-12, err_msg=m)
        np.testing.assert_allclose(y.residuals, x.residuals, rtol=1e-8, atol=1e-9, err_msg=m)
        if m == "mle":
            sx, sy = x.extras["starts"], y.extras["starts"]
            assert (sx["chosen"], sx["not_determined"], sx["refits"]) == (sy["chosen"], sy["not_determined"],
                                                                         sy["refits"])
            assert set(x.extras) == set(y.extras), m
            assert x.extras["fit"]["consistent"] == y.extras["fit"]["consistent"]
            assert x.extras["fit"]["message"] == y.extras["fit"]["message"]
            bx, by = x.extras.get("boresight_bias"), y.extras.get("boresight_bias")
            assert (bx is None) == (by is None), m
            if bx is not None:
                np.testing.assert_allclose([bx["u_deg"], bx["v_deg"]], [by["u_deg"], by["v_deg"]], rtol=1e-8,
                                           atol=1e-12)
            ex, ey = x.extras.get("error_model"), y.extras.get("error_model")
            assert (ex is None) == (ey is None), m
            if ex is not None:  # the same model chosen; its likelihoods and spreads to rounding (the first fit ran
                spreads = ("log_likelihood", "models_spread_m", "model_sd_m")  # in a batch)
                assert {k: v for k, v in ex.items() if k not in spreads} == \
                    {k: v for k, v in ey.items() if k not in spreads}
                np.testing.assert_allclose(list(ey["log_likelihood"].values()), list(ex["log_likelihood"].values()),
                                           rtol=1e-10)
                np.testing.assert_allclose([ey["models_spread_m"], ey["model_sd_m"]],
                                           [ex["models_spread_m"], ex["model_sd_m"]], rtol=1e-8, atol=1e-9)


@pytest.mark.parametrize("options", [{}, {"mle": {"tol_m": 1e-6}, "vision": {"max_iterations": 7}}],
                         ids=["defaults", "own-options"])
def test_solve_problems_equals_solve_one_at_a_time(options, monkeypatch):
    from pipeline.solve import correlated

    problems = _problems()
    expected = _one_by_one(problems, METHODS, options)
    batched = []  # the learned drift models fitted side by side (problems with the same rows)
    gls = correlated.gls
    monkeypatch.setattr(correlated, "gls", lambda sts, *a, **k: batched.append(len(sts)) or gls(sts, *a, **k))
    got = solve_problems(problems, METHODS, options)
    assert len(got) == len(problems)
    for a, b in zip(expected, got, strict=True):
        _assert_same(a, b)
    # the cases the problems were built for did occur
    assert isinstance(got[5]["fusion"], Exception) and not isinstance(got[5]["mle"], Exception)
    if not options:
        assert all("error_model" in g["mle"].extras for g in got[7:10])
        assert not any("error_model" in g["mle"].extras for g in got[10:])  # white errors in the same batch
        # one call per family of states: both errors drifting, the attitude's alone, the position's alone, neither
        assert [n for n in batched if n > 1] == [3, 3, 3, 3]


def test_solve_problems_reports_a_bad_option_for_every_problem():
    problems = [paper_problem(seed=s) for s in range(2)]
    got = solve_problems(problems, ["dlt", "ridge"], {"ridge": {"hkb": "nonsense"}})
    for r in got:
        assert not isinstance(r["dlt"], Exception)
        assert isinstance(r["ridge"], ValueError) and "hkb must be one of" in str(r["ridge"])


def test_solve_problems_with_time_correlated_sigma_solves_each_alone():
    sigma = dataclasses.replace(PAPER_SIGMA, attitude_tau_s=20.0, position_tau_s=60.0)
    problems = correlated_problems(3, n=12, seed=1, sigma=sigma)
    for a, b in zip(_one_by_one(problems, ["mle"], {}), solve_problems(problems, ["mle"], {}), strict=True):
        _assert_same(a, b)
