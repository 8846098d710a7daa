"""`mle` on flights it was not written for (issue 19): a handful of scripts/zoo.py's flights, each asserting the
no-catastrophe rule, mle error <= 2 x median(the other methods' errors) + 5 m (methods that cannot solve a flight
are left out of the median). The full zoo (210 flights, coverage, the median rule) is `python scripts/zoo.py`;
docs/validation.md has its figures.

The flights: the issue's named shapes (the continuous-video arc, the straight pass with two laser returns and a
1.5 s occlusion, the observation file) and zoo flights of every family, among them the ones where commit c9d7636's
mle was far beyond the bound (z020: 27.7 km, here every third observation: 26.0 m against 11.3 m; z038: 6.3 km;
z104, z132: 1.6-1.7 x the bound; docs/validation.md)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from support.zoo import catastrophe_bound
from support.zoo import zoo as _zoo

FLIGHTS = ["arc", "straight", "obsfile",  # the named shapes
           "z001", "z002", "z004", "z005", "z010",  # gauss_markov, bias, gnss_drift, range_outliers, random_walk
           "z020/3", "z038", "z104",  # mistracked, random_walk, mistracked: c9d7636 failed these
           "z127",  # gauss_markov: a bias estimated 5x beyond the stated attitude sigma (40.9 m before 2026-11-23)
           "z132"]  # mistracked: a run of frames off by 3.3-5.4 sigma read as drift (11.4 m before 2026-11-24)
# "name/k": every k-th observation of the flight (z020 has 415; c9d7636's mle: 26.0 m against a bound of 11.3 m on
# every third, 27.7 km against 12.0 m on all)


@pytest.mark.parametrize("name", FLIGHTS)
def test_mle_is_no_catastrophe(name):
    base, _, k = name.partition("/")
    f = _zoo().flight(base, seed=0)
    obs = f.obs.subset(np.arange(0, f.obs.n, int(k or 1)))
    mle, bound, solved = catastrophe_bound(obs)
    assert solved >= 3, f"{name}: only {solved} other methods solved"
    assert mle is not None, f"{name}: mle did not solve"
    assert mle <= bound, (f"{name} ({f.family}, {f.shape}, n={obs.n}): mle error {mle:.1f} m > 2 x median "
                          f"of the others' errors + 5 m = {bound:.1f} m")


# flights of other seeds (mle was developed on seed 0's, the evidence step on seeds 0-7's; `python scripts/zoo.py
# --seed 0,1,...`, docs/validation.md, "How the MLE got here"), each mle's error before 2026-11-24 -> now: where the
# first answer with a boresight bias missed and a drift model the evidence chose (outside the first answer's 99.9 %
# ellipsoid) did not (z150 32.1 -> 1.6 m, z024 74.5 -> 1.8 m); where a drift model inside that ellipsoid missed that
# needs the ranges' variance 1,560-2,000 x the stated, now not admitted (z019 28.4 -> 4.0 m); where the likeliest
# drift model needs the ranges' variance 121 x the stated (z162: 1,062 m with that model admitted); where the
# chi-square was far too small for white errors and no drift was tried (z003 12.5 -> 3.3 m); where a bias would
# lose to a drift without the white models with a bias among the candidates (z065, 5.0 m with them); where the
# first answer's variance components put the ranges' sigma beyond 3 x the stated (the rule every candidate is held
# to) and nothing else called the evidence step (s7/z183 127.4 -> 51.8 m, bound 114.4 m; s16/z099 49.5 -> 4.7 m,
# bound 30.2 m: a range variance factor of 290 on two ranges); where a tracker slip (a run of frames on a wrong
# feature at 1-5 sigma) read as a drift, before a slip was among the candidates (s24/z034 32.5 -> 0.8 m, bound
# 16.4 m; s30/z027 63.4 m, bound 27.8 m); where a constant attitude error under white attitude noise (the bias
# family) lost to a drift while the white models with a bias had the scales 0.5 and 1 only, not the first fit's
# grid (s18/z128 34.0 -> 0.8 m, bound 15.7 m; s43/z009 101.7 -> 3.6 m, bound 70.8 m); where a Gauss-Markov attitude
# drift showed in the batch-means test only, before that test called the evidence step (s3/z043 22.8 -> 6.0 m,
# bound 18.5 m); where the position drifting with the attitude was the likeliest model only because its fit took
# a stated pixel or range variance many times larger, before the evidence counted the variance factors' prior
# (s72/z036 45.9 -> 5.4 m, bound 35.3 m; s33/z141 129.6 -> 16.9 m, bound 37.0 m; s65/z183
# 55.5 -> 19.3 m, bound 43.9 m; s4/z108 27.7 -> 7.1 m, bound 22.4 m)
OTHER_SEEDS = [(1, "z150"), (2, "z024"), (1, "z019"), (0, "z162"), (3, "z003"), (5, "z065"), (7, "z183"),
               (16, "z099"), (24, "z034"), (30, "z027"), (18, "z128"), (43, "z009"), (3, "z043"), (67, "z080"),
               (25, "z164"), (5, "z124"), (72, "z036"), (33, "z141"), (65, "z183"), (4, "z108")]
#: flights whose few laser ranges gave a variance factor near zero (pixel sigma unstated): far outside their
#: ellipsoid before the stated range sigma counted in its component (`mle.VCE_PRIOR_DOF`)
FEW_RANGES = [(40, "z183"), (42, "z083")]


@pytest.mark.parametrize("seed,name", OTHER_SEEDS, ids=[f"s{s}/{n}" for s, n in OTHER_SEEDS])
def test_mle_is_no_catastrophe_on_flights_of_other_seeds(seed, name):
    f = _zoo().flight(name, seed=seed)
    mle, bound, _ = catastrophe_bound(f.obs)
    assert mle is not None and mle <= bound, f"s{seed}/{name} ({f.family}, {f.shape}): mle {mle} m > {bound:.1f} m"


@pytest.mark.parametrize("seed,name", FEW_RANGES, ids=[f"s{s}/{n}" for s, n in FEW_RANGES])
def test_a_few_ranges_do_not_shrink_the_stated_range_sigma(seed, name):
    """s40/z183 (2 ranges; e^T C^-1 e 1,684 before) and s42/z083 (2 ranges; 408): inside the 99.9 % ellipsoid."""
    from pipeline.solve import solve

    f = _zoo().flight(name, seed=seed)
    est = solve("mle", f.obs)
    e = est.position_m - f.obs.truth_m
    assert est.extras["variance_factors"]["range"] > 0.3
    assert e @ np.linalg.solve(est.covariance_m2, e) < 16.27  # chi2_3(0.999)


def test_zoo_is_deterministic_and_as_specified():
    zoo = _zoo()
    a, b = zoo.flight("z017", seed=3), zoo.flight("z017", seed=3)
    np.testing.assert_array_equal(a.obs.P, b.obs.P)
    np.testing.assert_array_equal(a.obs.pixel, b.obs.pixel)
    assert not np.array_equal(zoo.flight("z017", seed=4).obs.pixel[:5], a.obs.pixel[:5])
    for i in range(21):  # three rounds of the family x shape cycle
        f = zoo.random_flight(0, i)
        m = f.meta
        assert 10.0 <= m["gamma_deg"] <= 80.0 and 1000.0 <= m["fx_px"] <= 12000.0 and 2000 <= m["slant_m"] <= 10000
        assert m["fps"] in (25.0, 29.97, 30.0) and f.obs.n <= 600
        dt_s = np.diff(f.obs.t_ns) / 1e9
        assert dt_s.min() >= 1 / 30.0 - 1e-6  # frames on the video's grid
        assert f.obs.has_range.sum() <= (f.obs.t_ns[-1] - f.obs.t_ns[0]) / 1e9 + 1  # the laser at 1 Hz
        assert int(f.bad_range.sum()) == m["bad_ranges"] <= 3
        if f.family == "mistracked":
            assert f.bad_pixel.any()
        assert (f.obs.sigma.pixel_px is None) == (not m["pixel_stated"])
        assert f.obs.sigma.attitude_tau_s is None and f.obs.sigma.position_tau_s is None
    arc = zoo.flight("arc")
    assert (arc.obs.n, arc.meta["gamma_deg"], arc.meta["fx_px"], arc.meta["image"]) == (58, 35.0, 10000.0, [600, 400])
    straight = zoo.flight("straight")
    assert straight.obs.has_range.sum() == 2 and straight.meta["occlusion_s"] == 1.5
    gap_s = np.diff(straight.obs.t_ns).max() / 1e9
    assert 1.5 <= gap_s < 1.6


def test_a_tracker_slip_is_reported_where_the_tracker_slipped():
    """s24/z034 (mistracked: 32 consecutive frames on a wrong feature): mle's `tracker_slip` extra names exactly
    those frames and its note says so."""
    from pipeline.solve import solve
    from pipeline.solve.mle_outputs import notes

    f = _zoo().flight("z034", seed=24)
    bad = np.flatnonzero(f.bad_pixel)
    extras = solve("mle", f.obs).extras
    assert extras["tracker_slip"] == {"first_observation": int(bad[0]), "last_observation": int(bad[-1]),
                                      "observations": int(bad.size)}
    assert any("tracker slip" in line for line in notes(extras))


def test_a_flight_that_does_not_pin_down_its_error_model_says_so():
    """s74/z206 (no ranges; random-walk attitude): the likely drift models' answers spread 364 m, more than each
    one's own 168 m; the error_model extra gives both and a note says the answer is their average. On z001 (seed 0)
    one model's uncertainty dominates: no such note."""
    from pipeline.solve import solve
    from pipeline.solve.mle_outputs import notes

    spread = solve("mle", _zoo().flight("z206", seed=74).obs).extras
    model = spread["error_model"]
    assert model["models_spread_m"] > model["model_sd_m"] > 0
    assert any("does not pin down its error model" in line for line in notes(spread))
    tight = solve("mle", _zoo().flight("z001", seed=0).obs).extras
    assert tight["error_model"]["models_spread_m"] < tight["error_model"]["model_sd_m"]
    assert not any("does not pin down" in line for line in notes(tight))


def test_a_bias_beyond_its_prior_calls_the_evidence_step(monkeypatch):
    """s62/z143 (random-walk attitude, pixel sigma unstated): no residual test fires, but the white fit's
    boresight bias comes out beyond twice the stated attitude sigma, which the stated model allows on < 5 % of
    flights per axis: the error model is chosen by evidence (a long correlation time) and the truth is inside the
    99.9 % ellipsoid. Without that gate the white fit stands, 16.5 m off at e^T C^-1 e = 40.8."""
    from pipeline.solve import methods, solve

    f = _zoo().flight("z143", seed=62)

    def nees(est):
        e = est.position_m - f.obs.truth_m
        return float(e @ np.linalg.solve(est.covariance_m2, e))

    est = solve("mle", f.obs)
    assert est.extras["error_model"]["chosen_by"] == "likelihood"
    assert est.extras["error_model"]["attitude_tau_s"] is not None
    assert nees(est) < 16.27  # chi2_3(0.999)
    monkeypatch.setattr(methods, "BIAS_BEYOND_STATED", np.inf)
    white = solve("mle", f.obs)
    assert "error_model" not in white.extras and nees(white) > 16.27


def test_a_misfit_alone_looks_for_a_tracker_slip_only():
    """s38/z174 (mistracked, pixel sigma unstated: 10 frames off by 1-5 sigma): no drift test fires, the first
    fit's chi-square is above its upper 1 % tail; the evidence step finds the slip inside the mistracked run and
    the answer is within the no-catastrophe bound (24.5 m against 18.8 m before 2026-11-24). s55/z058 (bias
    family: a stated attitude sigma 1.5-3 x too small): the same misfit, where a drift model that absorbs it would
    claim an accuracy the flight lacks (10.5 m at e^T C^-1 e 53.0 with the drift's answer taken); the first answer
    stands and the truth is inside its 99.9 % ellipsoid."""
    from pipeline.solve import solve

    f = _zoo().flight("z174", seed=38)
    mle, bound, _ = catastrophe_bound(f.obs)
    assert mle <= bound, f"s38/z174: mle {mle:.1f} m > {bound:.1f} m"
    slip = solve("mle", f.obs).extras["tracker_slip"]
    bad = np.flatnonzero(f.bad_pixel)
    assert bad[0] <= slip["first_observation"] <= slip["last_observation"] <= bad[-1]

    f = _zoo().flight("z058", seed=55)
    est = solve("mle", f.obs)
    assert est.extras["fit"]["p_value"] < 0.01
    assert "error_model" not in est.extras and "tracker_slip" not in est.extras
    e = est.position_m - f.obs.truth_m
    assert e @ np.linalg.solve(est.covariance_m2, e) < 16.27  # chi2_3(0.999)


def test_a_bias_alone_stays_in_the_evidence_whatever_its_scale():
    """s31/z205 (bias family): the likeliest candidate is a boresight bias alone, without the white attitude error
    the flight also has, which fits only with the likelihood's overall scale k = 11.7. The limit on k keeps a drift
    or a slip out of the evidence (unseen s11/u039), not a white model, whose evidence keeps the first answer
    (5.0 m); with the bias alone out, a drift at tau 320 s took its place (35.9 m)."""
    from pipeline.solve import solve

    f = _zoo().flight("z205", seed=31)
    est = solve("mle", f.obs)
    assert "error_model" not in est.extras
    assert np.linalg.norm(est.position_m - f.obs.truth_m) < 10.0


def test_zoo_compare_counts_flight_by_flight(tmp_path, capsys):
    """scripts/zoo_compare.py (the before / after tables of docs/validation.md) on two hand-made runs: one flight
    closer and no longer a catastrophe, one further, one unchanged; the coverage counts e^T C^-1 e <= 7.81."""
    from support.zoo import script

    def flight(name, mle, nees, cat):
        return {"name": name, "family": "bias", "errors_m": {"mle": mle}, "mle_nees": nees, "catastrophe": cat,
                "bound_m": 10.0}
    before = [flight("s0/z001", 20.0, 9.0, True), flight("s0/z002", 2.0, 1.0, False),
              flight("s9/z003", 3.0, 1.0, False)]
    after = [flight("s0/z001", 4.0, 2.0, False), flight("s0/z002", 5.0, 1.0, False),
             flight("s9/z003", 3.0, 1.0, False)]
    for name, rows in (("a.json", before), ("b.json", after)):
        (tmp_path / name).write_text(json.dumps({"flights": rows}))
    assert script("zoo_compare").main([str(tmp_path / "a.json"), "--after", str(tmp_path / "b.json")]) == 0
    out = capsys.readouterr().out
    assert "| 0-7 | 2 | 1 / 0 | 11.00 / 4.50 m | 50.0 % / 100.0 % | 2, 1 closer, sum -13 m |" in out
    assert "| all | 3 | 1 / 0 | 3.00 / 4.00 m | 66.7 % / 100.0 % | 2, 1 closer, sum -13 m |" in out
    assert "catastrophes gone: s0/z001" in out and "catastrophes new: -" in out
