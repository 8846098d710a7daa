"""Is the `mle` 95 % ellipsoid honest when nobody tells it the error model? Monte Carlo over error families
the estimator is not told about (docs/validation.md, "Calibration").

Every problem: a platform on an arc around the target (intersection angle 20-90 deg) or on a straight pass,
slant range 2-10 km, n = 5, 10, 20 or 50 frames over a 60 s segment, f = 1000 px. The estimator is told only
the sensors' nominal sigmas (pixel 0.5 px, range 5 m, position 2 m, attitude 0.2 deg), no correlation times.
The families (attitude errors are rotations in the world frame, so a constant one is not exactly the camera-
frame bias the estimator models):

    independent     attitude 0.2 deg and position 2 m white, frame to frame
    gauss_markov    attitude Gauss-Markov, 0.2 deg, tau 5-60 s
    bias            constant attitude bias 0.1-0.3 deg (random axis) plus 0.1 deg white
    random_walk     attitude random walk reaching 0.2 deg (rms) at the end of the segment
    gnss_drift      position Gauss-Markov 2 m, tau 60-300 s (drift), attitude white
    range_outliers  independent, plus 0-20 % of the ranges off by 100-500 m
    mistracked      independent, plus 1-3 pixels off by 10-50 px

Per family: coverage of the 95 % ellipsoid (e^T C^-1 e <= 7.81) and median error of
    default      solve_batch("mle") with its defaults (redescending loss, bias, fit checks)
    independent  the previous default: Huber loss, no bias, no fit checks (the unmodelled-independent MLE)
    reference    the correctly-specified MLE, where ridgeloc can express the model: independent: squared loss;
                 gauss_markov, random_walk (as tau 300 s), gnss_drift: generalized least squares with the true
                 correlation time (`solve` per problem); bias: squared loss with the bias prior set to the bias
                 rms and the white attitude sigma; outliers / mistracked: squared loss without the bad rows.

    python scripts/calibration.py [--trials 100] [--seed 0] [--families a,b] [--by-n] [--understated K]
                                  [--per-problem]                              (a few minutes)

The table measures `solve_batch` (no timestamps: the bias model). `--per-problem` adds the coverage and median
error of `solve("mle", obs)` per problem with the frames' timestamps, which learns a correlation time where the
residuals drift (slow: up to seven generalized least squares fits per problem).
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import time
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT), str(ROOT / "tests")]  # this checkout's pipeline; test support (support.scenes)

from pipeline.geometry.camera import look_at_rotation, project, projection_matrix  # noqa: E402
from pipeline.solve import solve, solve_batch  # noqa: E402
from pipeline.solve.observations import ObservationBatch, Observations, Sigma  # noqa: E402
from pipeline.solve.uncertainty import CHI2_3_95  # noqa: E402
from support.scenes import PAPER_K, arc_platforms_m, gauss_markov  # noqa: E402

TOLD = Sigma(pixel_px=0.5, range_m=5.0, position_m=2.0, attitude_deg=0.2)
FAMILIES = ("independent", "gauss_markov", "bias", "random_walk", "gnss_drift", "range_outliers", "mistracked")
DURATION_S = 60.0
NS = (5, 10, 20, 50)
GEOMETRIES = ("arc", "straight")


def platforms(rng, B: int, n: int, geometry: str):
    """(B,n,3) true platform positions, target at the origin."""
    slant = rng.uniform(2000.0, 10000.0, B)
    height = slant * rng.uniform(0.25, 0.6, B)
    out = np.empty((B, n, 3))
    for b in range(B):
        if geometry == "arc":
            out[b] = arc_platforms_m(n, rng.uniform(20.0, 90.0), height[b], slant[b])
        else:  # a straight pass abeam of the target, 1-3 km long
            horiz = np.sqrt(slant[b] ** 2 - height[b] ** 2)
            along = np.linspace(-0.5, 0.5, n) * rng.uniform(1000.0, 3000.0)
            out[b] = np.stack([along, np.full(n, horiz), np.full(n, height[b])], axis=1)
    return out


def make_family(rng, family: str, B: int, n: int, geometry: str, scale: float = 1.0):
    """(ObservationBatch told TOLD, bad-row masks (pix (B,n), rng (B,n)), reference sigma, tau dict); the
    attitude and position errors are scale times what TOLD says (the reference is told the truth)."""
    t_s = np.linspace(0.0, DURATION_S, n)
    true_pos = platforms(rng, B, n, geometry)
    target = np.zeros(3)
    att = np.deg2rad(TOLD.attitude_deg) * scale
    pos_sigma = TOLD.position_m * scale
    pos_err = rng.normal(0.0, pos_sigma, (B, n, 3))
    ref_sigma = dataclasses.replace(TOLD, attitude_deg=TOLD.attitude_deg * scale, position_m=pos_sigma)
    taus = {}
    if family == "gauss_markov":
        tau = rng.uniform(5.0, 60.0)
        rot = gauss_markov(rng, (B, 3), t_s, att, tau).transpose(0, 2, 1)
        taus = {"attitude_tau_s": tau}
    elif family == "bias":
        axis = rng.normal(size=(B, 1, 3))
        axis /= np.linalg.norm(axis, axis=-1, keepdims=True)
        mag = np.deg2rad(rng.uniform(0.1, 0.3, (B, 1, 1))) * scale
        rot = axis * mag + rng.normal(0.0, np.deg2rad(0.1) * scale, (B, n, 3))
        ref_sigma = dataclasses.replace(ref_sigma, attitude_deg=0.1 * scale)
        taus = {"bias_prior_deg": scale * float(np.sqrt(np.mean(np.linspace(0.1, 0.3, 101) ** 2)))}
    elif family == "random_walk":
        steps = rng.normal(0.0, att / np.sqrt(n), (B, n, 3))
        rot = np.cumsum(steps, axis=1)
        taus = {"attitude_tau_s": 300.0}
    else:
        rot = rng.normal(0.0, att, (B, n, 3))
    if family == "gnss_drift":
        tau = rng.uniform(60.0, 300.0)
        pos_err = gauss_markov(rng, (B, 3), t_s, pos_sigma, tau).transpose(0, 2, 1)
        taus = {"position_tau_s": tau}
    R_true = look_at_rotation(true_pos, target)
    R_err = Rotation.from_rotvec(rot.reshape(-1, 3)).as_matrix().reshape(B, n, 3, 3)
    P = projection_matrix(PAPER_K, R_true @ R_err, true_pos + pos_err)  # the world-frame error
    pixel = project(projection_matrix(PAPER_K, R_true, true_pos), np.broadcast_to(target, (B, n, 3)))
    pixel = pixel + rng.normal(0.0, TOLD.pixel_px, pixel.shape)
    rng_m = np.linalg.norm(true_pos, axis=-1) + rng.normal(0.0, TOLD.range_m, (B, n))
    bad_pix = np.zeros((B, n), dtype=bool)
    bad_rng = np.zeros((B, n), dtype=bool)
    if family == "range_outliers":
        frac = rng.uniform(0.0, 0.2, (B, 1))
        bad_rng = rng.random((B, n)) < frac
        rng_m = rng_m + bad_rng * rng.choice([-1.0, 1.0], (B, n)) * rng.uniform(100.0, 500.0, (B, n))
    elif family == "mistracked":
        k = rng.integers(1, 4, B)
        for b in range(B):
            bad_pix[b, rng.choice(n, size=min(k[b], n - 2), replace=False)] = True
        ang = rng.uniform(0.0, 2 * np.pi, (B, n))
        size = rng.uniform(10.0, 50.0, (B, n))
        pixel = pixel + bad_pix[..., None] * np.stack([np.cos(ang), np.sin(ang)], axis=-1) * size[..., None]
    batch = ObservationBatch(P=P, pixel=pixel, platform_m=true_pos + pos_err, range_m=rng_m, sigma=TOLD,
                             truth_m=np.zeros((B, 3)))
    return batch, bad_pix, bad_rng, ref_sigma, taus, t_s


def nees(pos, cov, truth):
    e = pos - truth
    out = np.full(len(e), np.inf)
    ok = np.isfinite(e).all(axis=1) & np.isfinite(cov).all(axis=(1, 2))
    out[ok] = np.einsum("bi,bi->b", e[ok], np.linalg.solve(cov[ok], e[ok][..., None])[..., 0])
    return out


def reference(family, batch, bad_pix, bad_rng, ref_sigma, taus, t_s):
    """(positions (B,3), covariances (B,3,3)) of the correctly-specified MLE."""
    if family in ("gauss_markov", "random_walk", "gnss_drift"):
        sigma = dataclasses.replace(ref_sigma, **taus)
        pos = np.full((batch.size, 3), np.nan)
        cov = np.full((batch.size, 3, 3), np.nan)
        t_ns = np.round(t_s * 1e9).astype(np.int64)
        for b in range(batch.size):
            o = batch.problem(b)
            obs = Observations(P=o.P, pixel=o.pixel, platform_m=o.platform_m, range_m=o.range_m, t_ns=t_ns,
                               sigma=sigma)
            try:
                est = solve("mle", obs, robust=None)
            except Exception:  # a failed reference solve counts as a miss
                continue
            pos[b], cov[b] = est.position_m, est.covariance_m2
        return pos, cov
    pixel = np.where(bad_pix[..., None], np.nan, batch.pixel)
    rng_m = np.where(bad_rng, np.nan, batch.range_m)
    clean = dataclasses.replace(batch, pixel=pixel, range_m=rng_m, sigma=ref_sigma)
    est = solve_batch("mle", clean, robust=None, bias_prior_deg=taus.get("bias_prior_deg", 0.0))
    return est.position_m, est.covariance_m2


def per_problem(batch, t_s):
    """(positions (B,3), covariances (B,3,3)) of solve("mle", obs) with the default options and timestamps."""
    t_ns = np.round(t_s * 1e9).astype(np.int64)
    pos = np.full((batch.size, 3), np.nan)
    cov = np.full((batch.size, 3, 3), np.nan)
    for b in range(batch.size):
        o = batch.problem(b)
        obs = Observations(P=o.P, pixel=o.pixel, platform_m=o.platform_m, range_m=o.range_m, t_ns=t_ns,
                           sigma=batch.sigma)
        try:
            est = solve("mle", obs)
        except Exception:  # a failed solve counts as a miss
            continue
        pos[b], cov[b] = est.position_m, est.covariance_m2
    return pos, cov


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--trials", type=int, default=100, help="problems per family, geometry and n (default 100)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--families", default=",".join(FAMILIES))
    ap.add_argument("--per-problem", action="store_true", help="also solve() per problem with timestamps")
    ap.add_argument("--by-n", action="store_true", help="also a row per geometry and n (coverage, median ratio)")
    ap.add_argument("--understated", type=float, default=1.0, metavar="K",
                    help="the attitude and position errors are K times the told sigmas (default 1)")
    args = ap.parse_args(argv)
    rng = np.random.default_rng(args.seed)
    t0 = time.perf_counter()
    print(f"{args.trials} problems per family x geometry ({', '.join(GEOMETRIES)}) x n ({', '.join(map(str, NS))});"
          f" told {TOLD.to_dict()}; attitude and position errors x{args.understated:g}\n")
    print("| family | coverage default | coverage independent | coverage reference | median error default m | "
          "independent m | reference m | default / reference | rejected rows (bad rows) | misfit flagged |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|---|---:|")
    for family in args.families.split(","):
        d_all, i_all, r_all = [], [], []
        e_d, e_i, e_r = [], [], []
        rej = [0, 0, 0]
        flagged = []
        p_all, e_p = [], []
        by_n = []
        for geometry in GEOMETRIES:
            for n in NS:
                batch, bad_pix, bad_rng, ref_sigma, taus, t_s = make_family(rng, family, args.trials, n, geometry,
                                                                            args.understated)
                d = solve_batch("mle", batch)
                i = solve_batch("mle", batch, robust="huber", bias_prior_deg=0.0)
                rp, rc = reference(family, batch, bad_pix, bad_rng, ref_sigma, taus, t_s)
                truth = batch.truth_m
                d_all.append(nees(d.position_m, d.covariance_m2, truth))
                i_all.append(nees(i.position_m, i.covariance_m2, truth))
                r_all.append(nees(rp, rc, truth))
                e_d.append(d.errors_m(truth))
                e_i.append(i.errors_m(truth))
                e_r.append(np.linalg.norm(rp - truth, axis=1))
                by_n.append(f"|   {family}, {geometry}, n = {n} | {np.mean(d_all[-1] <= CHI2_3_95):.1%} | | "
                            f"{np.mean(r_all[-1] <= CHI2_3_95):.1%} | {np.nanmedian(e_d[-1]):.2f} | | "
                            f"{np.nanmedian(e_r[-1]):.2f} | {np.nanmedian(e_d[-1]) / np.nanmedian(e_r[-1]):.2f} | | |")
                if args.per_problem:
                    p_all.append(per_problem(batch, t_s))
                    e_p.append(np.linalg.norm(p_all[-1][0] - truth, axis=1))
                    p_all[-1] = nees(p_all[-1][0], p_all[-1][1], truth)
                flagged.append(~d.extras["consistent"])
                r = d.extras["rejected"]
                bad = np.concatenate([np.stack([bad_pix, bad_pix, bad_rng], axis=-1)])
                rej[0] += int(r.sum())
                rej[1] += int((r & bad).sum())
                rej[2] += int(bad.sum())
        cov = [float(np.mean(np.concatenate(x) <= CHI2_3_95)) for x in (d_all, i_all, r_all)]
        med = [float(np.nanmedian(np.concatenate(x))) for x in (e_d, e_i, e_r)]
        print(f"| {family} | {cov[0]:.1%} | {cov[1]:.1%} | {cov[2]:.1%} | {med[0]:.2f} | {med[1]:.2f} | {med[2]:.2f} "
              f"| {med[0] / med[2]:.2f} | {rej[0]} ({rej[1]} of {rej[2]} bad) "
              f"| {np.mean(np.concatenate(flagged)):.0%} |", flush=True)
        if args.by_n:
            print("\n".join(by_n), flush=True)
        if args.per_problem:
            print(f"|   {family}, solve() per problem with timestamps | "
                  f"{np.mean(np.concatenate(p_all) <= CHI2_3_95):.1%} | | | "
                  f"{np.nanmedian(np.concatenate(e_p)):.2f} | | | {np.nanmedian(np.concatenate(e_p)) / med[2]:.2f} | |",
                  flush=True)
    print(f"\n{time.perf_counter() - t0:.0f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
