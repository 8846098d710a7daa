"""The correlation time learned by evidence (`pipeline.solve.learned_tau`): the likelihood depends on tau, also
where the sigma states no attitude or position accuracy, and the tau the data were drawn with wins."""

import dataclasses

import numpy as np
import pytest
from scipy.optimize import minimize_scalar
from scipy.special import logsumexp

from pipeline.solve import learned_tau
from pipeline.solve.observations import Sigma
from pipeline.solve.stacked import Stacked
from support.scenes import PAPER_SIGMA, correlated_problems
from support.zoo import zoo as _zoo

TRUE_TAU_S = 20.0


@pytest.mark.parametrize("told", [PAPER_SIGMA, Sigma(range_m=2.5)], ids=["stated", "unstated"])
def test_likelihood_changes_with_tau_and_the_true_tau_wins(told):
    """20 problems of 60 frames 1 s apart whose attitude and position errors are Gauss-Markov with tau 20 s:
    the summed restricted likelihood over the grid peaks at 20 s, and within each problem it spans more than
    one log unit (the bug this guards against: with the attitude and position sigmas unstated the correlated
    part had no size, and all seven taus gave the same likelihood)."""
    total = np.zeros(len(learned_tau.TAU_GRID_S))
    for obs in correlated_problems(20, n=60, attitude_tau_s=TRUE_TAU_S, position_tau_s=TRUE_TAU_S, seed=5):
        st = Stacked.from_observations(dataclasses.replace(obs, sigma=told))
        got = learned_tau.learn_tau([st], obs.truth_m[None] + 1.0, told, None, told.pixel_px is None, 1e-4, 50)[0]
        assert got is not None
        _, att, lls, _ = got
        # the position error drifting too; a model not admitted (a far tau that fits only with every variance
        # scaled beyond 9 x) is out of the evidence: -inf
        ll = np.array([lls.get((t, att, t), -np.inf) for t in learned_tau.TAU_GRID_S])
        assert np.isfinite(ll[learned_tau.TAU_GRID_S.index(TRUE_TAU_S)])
        assert np.ptp(ll[np.isfinite(ll)]) > 1.0
        total += ll
    assert learned_tau.TAU_GRID_S[int(np.argmax(total))] == TRUE_TAU_S


def test_the_attitude_size_is_learned_where_unstated():
    """Told nothing but the range sigma, the learned attitude sigma (the grid's, times the pixel group's
    variance factor's square root: variance components scale the whole pixel covariance) is within a factor 2
    of the true 0.2 deg on most problems."""
    told = Sigma(range_m=2.5)
    chosen = []
    for obs in correlated_problems(12, n=60, attitude_tau_s=TRUE_TAU_S, position_tau_s=TRUE_TAU_S, seed=6):
        st = Stacked.from_observations(dataclasses.replace(obs, sigma=told))
        _, att, _, res = learned_tau.learn_tau([st], obs.truth_m[None], told, None, True, 1e-4, 50)[0]
        assert res is not None, "the evidence was for white errors on drifting data"
        chosen.append(att * np.sqrt(res[5]["variance_factor_pixel"][0]))
    assert np.mean((np.array(chosen) > 0.1) & (np.array(chosen) < 0.4)) >= 0.75


@pytest.mark.parametrize("name", ["z029", "z087"])
def test_the_learned_answer_does_not_jump_when_its_start_moves_by_a_micrometre(name, monkeypatch):
    """Zoo flights z029 (gauss_markov) and z087 (random_walk), whose residuals drift: `learn_tau` from the first
    fit's answer and from three starts 1e-6 m away gives answers within 1 % of the answer's largest standard
    deviation (and 1 cm) of each other. Before 2026-11-24 the candidates' fits were robust IRLS-GLS, whose weights
    wandered without converging: z029's answer moved by 12-18 m (0.2-0.3 sigma), z087's by 180-590 m."""
    from pipeline.solve import methods, solve

    calls = []
    real = learned_tau.learn_tau

    def spy(*args):
        calls.append(args)
        return real(*args)

    monkeypatch.setattr(methods._learned, "learn_tau", spy)
    solve("mle", _zoo().flight(name).obs)
    assert calls, "the flight no longer calls for the learned model: pick another flight"
    args = calls[0]
    X0 = np.asarray(args[1], dtype=np.float64)
    answers = []
    for d in [np.zeros(3), *np.random.default_rng(3).normal(size=(3, 3))]:
        got = real(args[0], X0 + 1e-6 * d / max(np.linalg.norm(d), 1e-300), *args[2:])[0]
        assert got is not None and got[3] is not None, "no drift model answers: pick another flight"
        answers.append((got[3][0][0], got[3][4][0]))
    sd = float(np.sqrt(np.linalg.eigvalsh(answers[0][1]).max()))
    for X, _ in answers[1:]:
        assert np.linalg.norm(X - answers[0][0]) < min(0.01 * sd, 0.01)


@pytest.mark.parametrize("attitude_tau_s,position_tau_s", [(TRUE_TAU_S, TRUE_TAU_S), (TRUE_TAU_S, None),
                                                            (None, TRUE_TAU_S)],
                         ids=["both-drifting", "attitude-drifting", "position-drifting"])
def test_the_evidence_tells_which_errors_drift(attitude_tau_s, position_tau_s):
    """Attitude and position errors (0.2 deg, 5 m) each Gauss-Markov with tau 20 s or white: the family of models
    with the same errors drifting as the data were drawn with has the largest summed likelihood (each problem's
    over the taus, then summed). The third family (a GNSS drift under a steady attitude) was missing from the
    candidates before 2026-11-24."""
    told = PAPER_SIGMA
    families = ((True, True), (True, False), (False, True))  # (attitude drifts, position drifts)
    total = np.zeros(len(families))
    for obs in correlated_problems(20, n=60, sigma=told, attitude_tau_s=attitude_tau_s,
                                   position_tau_s=position_tau_s, seed=7):
        st = Stacked.from_observations(obs)
        lls = learned_tau.learn_tau([st], obs.truth_m[None], told, None, False, 1e-4, 50)[0][2]
        for j, (a, p) in enumerate(families):
            ll = np.array([lls.get((t if a else None, told.attitude_deg, t if p else None), -np.inf)
                           for t in learned_tau.TAU_GRID_S])
            total[j] += logsumexp(ll)  # -inf where no model of the family was weighed
    assert np.isfinite(total.max())  # some family's models were weighed on every problem
    assert families[int(np.argmax(total))] == (attitude_tau_s is not None, position_tau_s is not None)


@pytest.mark.parametrize("attitude_tau_s,position_tau_s", [(TRUE_TAU_S, TRUE_TAU_S), (TRUE_TAU_S, None),
                                                            (None, TRUE_TAU_S)],
                         ids=["both-drifting", "attitude-drifting", "position-drifting"])
def test_the_answer_says_which_errors_it_learned_drift(attitude_tau_s, position_tau_s):
    """`solve("mle")` on drifting problems reports in its `error_model` extra which errors drift (their tau, s;
    None: white), as the data were drawn, and says so in words (`mle_outputs.notes`)."""
    from pipeline.solve import solve
    from pipeline.solve.mle_outputs import notes

    words = {(True, True): "attitude and position errors drifting", (True, False): "the attitude error drifting",
             (False, True): "the position (GNSS) error drifting"}
    for obs in correlated_problems(4, n=60, sigma=PAPER_SIGMA, attitude_tau_s=attitude_tau_s,
                                   position_tau_s=position_tau_s, seed=7):
        extras = solve("mle", obs).extras
        model = extras["error_model"]
        drifts = (model["attitude_tau_s"] is not None, model["position_tau_s"] is not None)
        assert drifts == (attitude_tau_s is not None, position_tau_s is not None)
        assert any(words[drifts] in line for line in notes(extras))


def test_the_candidates_fitted_in_parts_give_what_one_batch_gives(monkeypatch):
    """The candidates' fits are cut into parts of at most MODEL_ROWS_AT_ONCE rows (memory on long videos); each
    fit is independent of its neighbours, so one model per part gives the same answers as all at once, also for
    several problems side by side (redescending loss: its phases and scale guard included)."""
    told = Sigma(range_m=2.5, pixel_px=0.5)
    probs = correlated_problems(3, n=40, attitude_tau_s=TRUE_TAU_S, position_tau_s=TRUE_TAU_S, seed=8)
    sts = [Stacked.from_observations(dataclasses.replace(o, sigma=told)) for o in probs]
    X0 = np.array([o.truth_m + 3.0 for o in probs])

    def run():
        return learned_tau.learn_tau(sts, X0, told, "redescending", False, 1e-4, 50)

    whole = run()
    monkeypatch.setattr(learned_tau, "MODEL_ROWS_AT_ONCE", 1)
    parts = run()
    for a, b in zip(whole, parts, strict=True):
        assert a[0] == b[0] and a[1] == b[1]  # the same most likely model
        np.testing.assert_allclose(b[3][0], a[3][0], rtol=0, atol=1e-9)  # the mixture's estimate
        np.testing.assert_allclose(b[3][4], a[3][4], rtol=1e-9)  # and covariance
        assert b[3][1][0] == a[3][1][0]  # iterations
        for key in a[2]:
            assert abs(a[2][key] - b[2][key]) < 1e-8, key  # every model's log-likelihood


@pytest.mark.parametrize("tau_s", [TRUE_TAU_S, None], ids=["drifting", "white"])
def test_the_evidence_tells_drifting_errors_from_white_ones(tau_s):
    """The white models (no correlation time) are weighed with the drifting ones: on problems whose attitude and
    position errors are white, the evidence keeps the first (white) answer (`learn_tau` gives no drift fit) on
    nearly all; on problems drawn with tau 20 s it gives the drift model's answer on nearly all."""
    told = PAPER_SIGMA
    drift = []
    for obs in correlated_problems(12, n=60, sigma=told, attitude_tau_s=tau_s, position_tau_s=tau_s, seed=8):
        got = learned_tau.learn_tau([Stacked.from_observations(obs)], obs.truth_m[None], told, None, False, 1e-4,
                                    50)[0]
        drift.append(got[3] is not None)
    assert np.mean(drift) >= 0.9 if tau_s else np.mean(drift) <= 0.1


def test_a_model_that_explains_the_ranges_away_is_not_admitted():
    """A candidate whose fit needs the ranges' variance more than 9 x the stated one (3 x the sigma) is left out
    of the evidence, as one that needs the attitude error beyond 3 x the stated one or whose likelihood scales
    every variance beyond 9 x."""
    told = PAPER_SIGMA
    drifting = dataclasses.replace(told, attitude_tau_s=20.0, position_tau_s=20.0)
    assert learned_tau.admitted(told, drifting, 1.0, 8.9)
    assert not learned_tau.admitted(told, drifting, 1.0, 9.1)
    assert not learned_tau.admitted(told, drifting, 9.1, 1.0)
    # the likelihood's overall scale of the covariance, held to the same limit (unseen flight s11/u039)
    assert learned_tau.admitted(told, drifting, 1.0, 1.0, scale=8.9)
    assert not learned_tau.admitted(told, drifting, 1.0, 1.0, scale=9.1)
    assert learned_tau.admitted(dataclasses.replace(told, range_m=None), drifting, 1.0, 100.0)  # range unstated
    grid = dataclasses.replace(drifting, attitude_deg=1.0)  # attitude unstated: the grid's sigma, the pixel noise
    assert learned_tau.admitted(dataclasses.replace(told, attitude_deg=None), grid, 8.9, 1.0)
    assert not learned_tau.admitted(dataclasses.replace(told, attitude_deg=None), grid, 9.1, 1.0)


def test_the_evidence_counts_the_variance_factors_prior_as_the_helmert_step_does():
    """The evidence's prior on a group's variance factor lam is 0 at the stated variance and, with the rows'
    likelihood -1/2 (q / lam + red log lam), peaks where `mle.helmert` puts a factor the rows alone would shrink:
    (q + n0) / (red + n0) (checked there, below the stated variance, where helmert applies it; the evidence applies
    it on both sides). A group without the prior (sigma unstated) adds nothing at any lam."""
    from pipeline.solve.mle import helmert

    n0 = np.array([4.0, 4.0])
    assert learned_tau._variance_prior(np.array([1.0, 1.0]), n0) == 0.0
    assert learned_tau._variance_prior(np.array([26.0, 1.0]), n0) < -4.0  # s72/z036's ranges: about -4.6
    assert learned_tau._variance_prior(np.array([0.0, np.inf]), np.zeros(2)) == 0.0
    q, red = np.array([0.6, 2.0]), np.array([3.0, 2.5])  # both groups below their stated variance
    expected, _ = helmert(q[None], red[None], prior_dof=n0)
    for g, only in enumerate(np.eye(2)):

        def minus_total(log_lam, g=g, only=only):
            lam = np.where(only > 0, np.exp(log_lam), 1.0)
            return 0.5 * (q[g] / lam[g] + red[g] * log_lam) - learned_tau._variance_prior(lam, n0 * only)

        best = minimize_scalar(minus_total, bounds=(-5.0, 3.0), method="bounded", options={"xatol": 1e-10})
        assert np.exp(best.x) == pytest.approx(expected[0, g], rel=1e-6)


def test_a_group_without_rows_pays_no_prior_for_its_factor():
    """A flight without laser ranges whose sigma states the laser's: the range group's variance factor scales no
    row of C, and the evidence adds no prior for it (a model is not penalized for a factor nothing measured)."""
    obs = correlated_problems(1, n=40, attitude_tau_s=TRUE_TAU_S, position_tau_s=TRUE_TAU_S, seed=3)[0]
    obs = dataclasses.replace(obs, range_m=np.full_like(obs.range_m, np.nan), sigma=PAPER_SIGMA)
    st = Stacked.from_observations(obs)
    drifting = dataclasses.replace(PAPER_SIGMA, attitude_tau_s=TRUE_TAU_S, position_tau_s=TRUE_TAU_S)
    X = obs.truth_m[None] + 1.0
    at_one, at_thirty = (learned_tau.log_likelihoods(st, X, [drifting], [[1.0, vr]])[0][0] for vr in (1.0, 30.0))
    assert np.isfinite(at_one) and at_thirty == at_one
    with_pixels_off = learned_tau.log_likelihoods(st, X, [drifting], [[30.0, 1.0]])[0][0]
    assert with_pixels_off < at_one  # the pixel group has rows: its factor counts


def test_a_constant_attitude_error_is_taken_for_a_bias_when_the_bias_is_a_candidate():
    """An attitude error that stands still over the flight (Gauss-Markov with tau 1e9 s), position errors white:
    with the first answer's model (white errors and a boresight bias of the stated attitude sigma's prior) among
    the candidates the evidence is for it (the first answer stands) on nearly every problem; without it, a drift
    of the longest correlation time (a drift that stands still) takes nearly every problem."""
    told = PAPER_SIGMA
    white = {True: [], False: []}
    for obs in correlated_problems(12, n=60, sigma=told, attitude_tau_s=1e9, position_tau_s=None, seed=9):
        st = Stacked.from_observations(obs)
        for with_bias in (True, False):
            got = learned_tau.learn_tau([st], obs.truth_m[None], told, None, False, 1e-4, 50,
                                        told.attitude_deg if with_bias else None)[0]
            white[with_bias].append(got is not None and got[3] is None)
    assert np.mean(white[True]) >= 0.9
    assert np.mean(white[False]) <= 0.1


def test_a_bias_under_white_attitude_noise_is_taken_for_a_bias():
    """An attitude error that is part constant (0.87 of the stated sigma per axis) and part white (0.5 of it), as
    the zoo's bias family draws it: the white models with a bias on the first fit's whole grid of prior scales
    (`bias_mixture.PHI_GRID`) keep the first answer on nearly every problem. (With the scales 0.5 and 1 alone, the
    grid before 2026-11-24, a drift won 7 of 24: the likelihood is sharp in the bias's scale.)"""
    told = PAPER_SIGMA
    constant = dataclasses.replace(told, attitude_deg=0.87 * told.attitude_deg)
    white = []
    for obs in correlated_problems(24, n=60, sigma=constant, attitude_tau_s=1e9, position_tau_s=None, seed=12,
                                   attitude_white_deg=0.5 * told.attitude_deg):
        st = Stacked.from_observations(dataclasses.replace(obs, sigma=told))
        got = learned_tau.learn_tau([st], obs.truth_m[None], told, None, False, 1e-4, 50, told.attitude_deg)[0]
        white.append(got is not None and got[3] is None)
    assert np.mean(white) >= 0.9


def test_a_tracker_slip_is_found_where_the_pixels_are_off_by_one_offset():
    """`slip_segment` on standardized pixel residuals with one run of frames off by a constant (u, v) offset of
    1.5 sigma finds that run exactly (the zoo's mistracked runs sit at 1-5 sigma of the rows' sigma), with its
    offset's prior sigma 3 x the rows' median sigma, and the number of runs searched."""
    obs = correlated_problems(1, n=200, attitude_tau_s=None, position_tau_s=None, seed=3)[0]
    st = Stacked.from_observations(obs)
    rng = np.random.default_rng(4)
    E = rng.normal(size=(200, 3))
    E[120:150, :2] += [1.5, -1.5]
    slip = learned_tau.slip_segment(st, E, 2.0 * E)
    assert np.array_equal(np.flatnonzero(slip.mask), np.arange(120, 150))
    assert slip.prior_px == pytest.approx(6.0)
    assert slip.runs == sum(200 - L + 1 for L in range(2, 101))  # every start and length up to half the frames


def test_a_slip_searched_for_on_white_errors_is_not_chosen():
    """The slip candidate's run is the likeliest of all runs searched, so on errors with no slip it still fits a
    little better than the white model (2-4 log units on these problems); the evidence charges it the search (a
    uniform prior over the runs: log of their number) and keeps the white answer. Without that price it was
    chosen on 12 of 12."""
    from pipeline.solve import mle

    chosen = 0
    for obs in correlated_problems(12, n=300, attitude_tau_s=None, position_tau_s=None, seed=11):
        st = Stacked.from_observations(obs)
        ex = mle.mle(st, obs.truth_m[None], PAPER_SIGMA, None, False, 1e-4, 50)[5]  # the first fit's residuals
        slip = learned_tau.slip_segment(st, ex["residual_sigmas"][0], ex["residuals"][0])
        got = learned_tau.learn_tau([st], obs.truth_m[None], PAPER_SIGMA, None, False, 1e-4, 50, None, [slip])[0]
        chosen += got is not None and got[3] is not None and "tracker_slip" in got[3][5]
    assert chosen <= 1
