#!/usr/bin/env python
"""How far the learned correlation time's answer (`learned_tau.learn_tau`) moves when its start (the first,
independent-error fit's answer) moves by 1e-6 m (docs/solvers.md, "Three more rules of the first fit").

    OPENBLAS_NUM_THREADS=1 PYTHONPATH=. python scripts/learned_tau_stability.py z029 z073 z087
    OPENBLAS_NUM_THREADS=1 PYTHONPATH=. python scripts/learned_tau_stability.py z029 --candidates
    OPENBLAS_NUM_THREADS=1 PYTHONPATH=. python scripts/learned_tau_stability.py --zoo 210
    OPENBLAS_NUM_THREADS=1 PYTHONPATH=. python scripts/learned_tau_stability.py --told z001 z004 z029 z073
    OPENBLAS_NUM_THREADS=1 PYTHONPATH=. python scripts/learned_tau_stability.py --told-zoo 210
    OPENBLAS_NUM_THREADS=1 PYTHONPATH=. python scripts/learned_tau_stability.py --scenes

A name is a zoo flight (`scripts/zoo.py`: arc, straight, obsfile, z000, ...; s1/z019: z019 of seed 1) or an
observations file. Per flight: the mle error, the start's error, the learned answer's error, its largest standard
deviation and the largest move of the answer over --starts starts 1e-6 m from the first (random directions, seed
1). --candidates: per candidate model (the attitude error's tau or white, attitude sigma, boresight bias, the
position error's tau or white), its `correlated.gls` fit from those starts (every row at weight 1, the fit
`learn_tau` uses): error, restricted log-likelihood with the variance factors' prior, variance factors (pixel /
range; "not admitted" where they, or k of a drift, exceed `learned_tau.admitted`) and the likelihood's overall
scale k (C's variances are the stated ones x factor x k), largest move, iterations and status (0 converged, 1
iteration limit). --told: the configured-correlation-time path (the white fit, then the damped GLS fit
`correlated.gls` with the white fit's robust weights held, `methods._configured_tau`) told each zoo flight's true
correlation times, from the los answer and starts 1e-6 m from it: error, largest move, rows the white fit
rejected, iterations;
--told-zoo N: that on every flight of `zoo.py --flights N --seed 0` whose told sigma has a correlation time.
--scenes: the configured path's coverage of the 95 % ellipsoid and median error on the test scenes
(tests/support/scenes.py, docs/solvers.md "Time-correlated attitude and position errors"): Gauss-Markov attitude
and position (400 problems, squared, Huber and default loss), attitude only (300, default loss), and one range
3 km too long (40, default loss).
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from pipeline.errors import RidgelocError
from pipeline.observation_file import load
from pipeline.solve import learned_tau, methods, solve


def _observations(name: str):
    if name.endswith(".json"):
        return load(name)
    import zoo

    seed, _, base = name.rpartition("/")  # s1/z019: flight z019 of seed 1
    return zoo.flight(base, seed=int(seed[1:]) if seed else 0).obs


def _starts(X0: np.ndarray, count: int) -> list:
    rng = np.random.default_rng(1)
    out = [X0]
    for _ in range(count):
        d = rng.normal(size=3)
        out.append(X0 + 1e-6 * d / np.linalg.norm(d))
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("flights", nargs="*")
    ap.add_argument("--zoo", type=int, metavar="N", help="every flight of `zoo.py --flights N --seed 0` as well")
    ap.add_argument("--starts", type=int, default=7, help="starts 1e-6 m away (default 7)")
    ap.add_argument("--candidates", action="store_true", help="every candidate model's fit")
    ap.add_argument("--told", action="store_true",
                    help="zoo flights only: instead, mle told the flight's true correlation times (`zoo.py`'s told "
                         "sigma) with the default loss, from the los answer (else dlt's) and starts 1e-6 m away")
    ap.add_argument("--told-zoo", type=int, metavar="N", help="--told on every zoo flight told a correlation time")
    ap.add_argument("--scenes", action="store_true", help="the configured path on the test scenes (coverage)")
    ap.add_argument("--tau", type=float, metavar="S", help="--told: tell attitude and position correlation time S "
                    "(on the flight's stated sigma) instead of the true model")
    args = ap.parse_args(argv)
    if args.scenes:
        return _scenes()
    if args.told_zoo:
        import zoo

        told = [f.name for f in zoo.zoo(args.told_zoo, 0) if f.told_sigma.correlated]
        return _told(told + args.flights, args.starts, args.tau)
    if args.zoo:
        import zoo

        args.flights += [f.name for f in zoo.zoo(args.zoo, 0)]
    real = learned_tau.learn_tau
    calls = []
    largest = (0.0, None)

    def spy(*a):
        calls.append(a)
        return real(*a)

    methods._learned.learn_tau = spy
    if args.told:
        return _told(args.flights, args.starts, args.tau)
    for name in args.flights:
        obs = _observations(name)
        truth = obs.truth_m
        calls.clear()
        est = solve("mle", obs)
        err = float(np.linalg.norm(est.position_m - truth))
        if not calls:
            print(f"{name}: mle {err:.2f} m, learned step not called (no fit check called it)")
            continue
        sts, X0s, sigma, robust, vce, tol_m, itmax, bias_deg, slips = (*calls[0], None, None)[:9]
        starts = _starts(np.asarray(X0s, dtype=np.float64), args.starts)
        answers = [real(sts, X, sigma, robust, vce, tol_m, itmax, bias_deg, slips)[0] for X in starts]
        slip = est.extras.get("tracker_slip")
        if slip:
            print(f"{name}: mle {err:.2f} m; the tracker slip is the likeliest model (observations "
                  f"{slip['first_observation']}-{slip['last_observation']}): its fit is the answer")
        elif answers[0] is not None and answers[0][3] is not None and "error_model" not in est.extras:
            print(f"{name}: mle {err:.2f} m; a drift is the likeliest model but a misfit alone called the step: "
                  "the first answer stands")
        elif answers[0] is None or answers[0][3] is None:
            why = "no candidate answered" if answers[0] is None else "the evidence is for white errors"
            print(f"{name}: mle {err:.2f} m; {why} (the first answer stands)")
        else:
            X = np.array([a[3][0][0] if a is not None and a[3] is not None else np.full(3, np.nan) for a in answers])
            sd = float(np.sqrt(np.linalg.eigvalsh(answers[0][3][4][0]).max()))
            ex0 = answers[0][3][5]
            which = " and ".join(k for k in ("attitude", "position") if np.isfinite(ex0[f"error_model_{k}_tau_s"][0]))
            which += " drifting"
            move = float(np.linalg.norm(X[1:] - X[0], axis=1).max())
            largest = max(largest, (move, name), key=lambda m: m[0])
            print(f"{name}: mle {err:.2f} m; start {np.linalg.norm(starts[0][0] - truth):.2f} m; learned "
                  f"{np.linalg.norm(X[0] - truth):.2f} m (tau {answers[0][0]:g} s, {which}, largest sd {sd:.1f} m); "
                  f"largest move from {args.starts} starts 1e-6 m away {move:.1e} m")
        if not args.candidates:
            continue
        sigmas, biases = learned_tau.candidates(sigma, bias_deg)
        fits = []
        for X0 in starts:
            f = learned_tau.fits(sts, X0, sigmas, robust, vce, tol_m, itmax, biases)[0]
            fits.append([(f[0][k], int(f[1][k]), int(f[2][k])) for k in range(len(sigmas))])
            if X0 is starts[0]:
                ex = f[5]
                vfs = [(float(ex["variance_factor_pixel"][k]), float(ex["variance_factor_range"][k]))
                       for k in range(len(sigmas))]
                lls = learned_tau.log_likelihoods(sts[0], f[0], sigmas, vfs, biases)
        for k, s in enumerate(sigmas):
            Xk = np.array([fit[k][0] for fit in fits])
            mv = float(np.linalg.norm(Xk[1:] - Xk[0], axis=1).max())
            pos = "white" if s.position_tau_s is None else f"{s.position_tau_s:g} s"
            tau = "white" if s.attitude_tau_s is None else f"{s.attitude_tau_s:g} s"
            total = dataclasses.replace(s, attitude_deg=float(np.hypot(s.attitude_deg or 0.0, biases[k] or 0.0)))
            scale = max(lls[k][1] / lls[k][2], 1.0)  # C's overall scale k
            ok = learned_tau.admitted(sigma, total, *vfs[k], scale=1.0 if learned_tau.is_white(s) else scale)
            print(f"    attitude tau {tau:>6s}, attitude {s.attitude_deg or 0:.3g} deg, bias {biases[k] or 0:.3g} deg, "
                  f"position tau {pos:>6s}: {np.linalg.norm(Xk[0] - truth):8.2f} m, log L {lls[k][0]:9.1f}, "
                  f"variance factors {vfs[k][0]:.3g} / {vfs[k][1]:.3g}{'' if ok else ' (not admitted)'} "
                  f"x scale {scale:.3g}, "
                  f"largest move {mv:.1e} m, iterations {sorted({fit[k][1] for fit in fits})}, "
                  f"status {sorted({fit[k][2] for fit in fits})}")
    print(f"largest move: {largest[0]:.1e} m ({largest[1]})")
    return 0


def _told(names: list, count: int, tau: float | None = None) -> int:
    """The configured-correlation-time path's answers from starts 1e-6 m apart (`--told`)."""
    import zoo

    largest = (0.0, None)
    for name in names:
        f = zoo.flight(name)
        told = f.told_sigma if tau is None else dataclasses.replace(f.obs.sigma, attitude_tau_s=tau, position_tau_s=tau)
        obs = dataclasses.replace(f.obs, sigma=told)
        try:
            x0 = solve("los", obs).position_m
        except RidgelocError:  # no frame with both a pixel and a range: the dlt point
            x0 = solve("dlt", obs).position_m
        try:
            ests = [solve("mle", obs, initial_m=x) for x in _starts(x0[None], count)]
        except RidgelocError as e:
            print(f"{name} ({f.family}): no answer from some start: {e}")
            continue
        X = np.array([e.position_m for e in ests]).reshape(-1, 3)
        move = float(np.linalg.norm(X[1:] - X[0], axis=1).max())
        largest = max(largest, (move, name), key=lambda m: m[0])
        s = told
        print(f"{name} ({f.family}; told tau attitude {s.attitude_tau_s} s, position {s.position_tau_s} s): mle "
              f"{np.linalg.norm(X[0] - obs.truth_m):.2f} m, largest move from {count} starts 1e-6 m away "
              f"{move:.1e} m, rejected {len(ests[0].extras.get('rejected', []))}, iterations {ests[0].iterations}")
    print(f"largest move: {largest[0]:.1e} m ({largest[1]})")
    return 0


def _scenes() -> int:
    """`--scenes`."""
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
    from pipeline.solve.uncertainty import CHI2_3_95
    from support.scenes import PAPER_SIGMA, correlated_problems

    corr = dataclasses.replace(PAPER_SIGMA, attitude_tau_s=20.0, position_tau_s=60.0)

    def run(probs, sigma, **kw):
        d2, err, conv = [], [], 0
        for obs in probs:
            est = solve("mle", obs, sigma=sigma, **kw)
            e = est.position_m - obs.truth_m
            d2.append(e @ np.linalg.solve(est.covariance_m2, e))
            err.append(np.linalg.norm(e))
            conv += est.converged
        return (f"coverage {100 * np.mean(np.array(d2) <= CHI2_3_95):.1f} %, median error {np.median(err):.2f} m, "
                f"converged {conv} of {len(probs)}")

    gm = correlated_problems(400, seed=11)
    for label, kw in (("squared", {"robust": None}), ("huber", {"robust": "huber"}), ("default loss", {})):
        print(f"Gauss-Markov attitude and position, 400 problems, {label}: {run(gm, corr, **kw)}")
    att = correlated_problems(300, seed=12, position_tau_s=None)
    print(f"attitude only, 300 problems, default loss: "
          f"{run(att, dataclasses.replace(PAPER_SIGMA, attitude_tau_s=20.0))}")
    gross = []
    for obs in correlated_problems(40, seed=21):
        rng = obs.range_m.copy()
        rng[4] += 3000.0
        gross.append(dataclasses.replace(obs, range_m=rng))
    print(f"one range 3 km too long, 40 problems, default loss: {run(gross, corr)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
