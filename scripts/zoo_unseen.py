"""Unseen families: observation-level flights with error sources and shapes the zoo (scripts/zoo.py) does not
have, to find where `mle` is a catastrophe or its ellipsoid lies (issue 19's "the MLE a surveyor can trust
blindly"; docs/zoo.md, "Unseen families").

An independent generator (it shares nothing with scripts/zoo.py or `pipeline/synth` but the solve API's
`Observations`; the running, NEES and catastrophe rule are scripts/zoo.py's): a platform on an arc or a straight
pass; a gimbal that points at the target and slews about it (a sum of sinusoids, 2-8 % of the image's short side,
periods 2-12 s, so the pointing moves between frames); a pinhole camera (fx, principal point near the centre, no
distortion, pixels outside the image not seen); video at 25 or 30 Hz, every k-th frame observed (30-250
observations); a laser on its own clock (1 Hz unless the family says otherwise), each pulse on the nearest observed
frame within half the frames' spacing. The base errors are white at what the operator states: pixel 0.3-1.5 px (not
stated on a third of the flights, except pixel_understated's, always stated), laser 1-5 m, position 1-5 m, attitude
0.05-0.3 deg (small yaw/pitch/roll of the camera). The told sigma has no correlation times. Every flight has one
family (or two, "mix"), cycling with its index:

    lag              pose (position and attitude) stamped 50-300 ms late against the pixels and ranges,
                     platform 25-90 m/s, gimbal slewing
    pixel_walk       the tracker slides: a pixel random walk reaching 3-8 px rms per axis at the end (correlated
                     pixels)
    pixel_offset     the tracker holds the target's corner: a constant 2-6 px offset
    pixel_understated  the pixel sigma stated as 0.5 px, the real one 1.5-5 px (3-10 x)
    laser_sigma      the laser sigma stated 4-6 x too small or 4-6 x too large
    gnss_step        a GNSS multipath jump of 3-10 m at 30-70 % of the flight, held to the end
    attitude_spike   one attitude glitch of 1-2 deg on one axis lasting 0.5 s
    lever_arm        the laser measures to a point 5-30 m beside the target (lever arm / boresight)
    range_quantised  ranges rounded to 1 m or 5 m (the stated laser sigma unchanged)
    laser_rate       the laser at 0.2 Hz or 10 Hz
    few_pixels       5-10 pixels only, ranges on every observation
    hover            an arc with little baseline: intersection angle 2-8 deg, 3-12 m/s
    long_lens        fx 15,000-30,000 px at 10-20 km slant
    oblique          elevation 5-10 deg
    nadir            elevation 80-89 deg
    mix              two of the error families above at once, or one of them and one geometric family
    control          the base errors only (white, at the stated sigmas): mle's own error model

Each flight runs every method with defaults (`solve(method, obs)`; a method that raises is left out; mle with every
`--solve-option KEY=VALUE`, e.g. `bias_prior_deg=0`) and applies the zoo's rules: a catastrophe is mle error > 2 x
median(other methods' errors) + 5 m; coverage is the share of flights with e^T C^-1 e <= chi2_3(0.95) = 7.815 for
mle's covariance (a calibrated one: 95 %, median 2.37). Printed per family and overall, with the median error of the
best other method per flight (a family where every method is wrong is no mle failure); each catastrophe and each
flight outside its ellipsoid is printed with mle's extras (status, chosen start, variance factors, chi-square / dof,
lag-1 autocorrelation of the pixel residuals, rejected rows, boresight bias, learned correlation time and attitude
sigma, the other estimators outside its 99.9 % ellipsoid, the fit message); `-v` prints every flight; `--save DIR`
writes the catastrophes (or with `--only`, the named flights) as observation files (`ridgeloc solve`) with the truth
and the family in "meta"; `--diagnose` solves each of those flights again with the boresight bias prior fixed at the
stated attitude sigma and with no bias. `control` is the base flight without any effect (mle's own error model).

    PYTHONPATH=. python scripts/zoo_unseen.py [--flights 170] [--seed 0[,1,2]] [--timeout 20] [--only u017,u042]
                                              [--family lag,hover] [--save DIR] [--json OUT] [-v]
                                              [--diagnose] [--solve-option bias_prior_deg=0]
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation
from zoo import _median, _nees, catastrophe, print_run, run_method, run_methods  # scripts/ is on sys.path

from pipeline.config_schema import load_dataclass
from pipeline.errors import ConfigError
from pipeline.observation_file import to_dict
from pipeline.solve.observations import Observations, Sigma
from pipeline.solve.uncertainty import CHI2_3_95
from pipeline.solve_options import METHOD_SCHEMAS

ERROR_FAMILIES = ("lag", "pixel_walk", "pixel_offset", "pixel_understated", "laser_sigma", "gnss_step",
                  "attitude_spike", "lever_arm", "range_quantised", "laser_rate", "few_pixels")
GEOMETRY_FAMILIES = ("hover", "long_lens", "oblique", "nadir")
FAMILIES = ("control", *ERROR_FAMILIES, *GEOMETRY_FAMILIES, "mix")
IMAGES = ((640, 480), (1280, 720), (1920, 1080))
UP = np.array([0.0, 0.0, 1.0])


@dataclass
class UnseenFlight:
    """One flight: its observations (told sigma), the family's effects and their parameters."""

    name: str
    family: str
    effects: tuple[str, ...]
    obs: Observations
    meta: dict = field(default_factory=dict)


# ---- geometry and camera -----------------------------------------------------------------------------------

def _lookat_world_to_cam(pos_m: np.ndarray, point_m: np.ndarray) -> np.ndarray:
    """(n,3,3) rotations world -> camera (x right, y down, z along the line of sight) for cameras at pos_m (n,3)
    looking at point_m (n,3), image x level with the horizon."""
    z = point_m - pos_m
    z /= np.linalg.norm(z, axis=1, keepdims=True)
    x = np.cross(z, UP)
    x /= np.linalg.norm(x, axis=1, keepdims=True)
    return np.stack([x, np.cross(z, x), z], axis=1)


def _small_rotation(ypr_rad: np.ndarray) -> np.ndarray:
    """(n,3,3) camera-frame rotations R_z(roll) R_x(pitch) R_y(yaw) from small yaw (about y), pitch (about x) and
    roll (about z) angles (n,3) rad."""
    return Rotation.from_euler("ZXY", ypr_rad[:, ::-1]).as_matrix()


class _Trajectory:
    """The platform's true position at any time (s): an arc around the target at fixed height or a straight pass
    abeam; and the gimbal's slew about the target as a sum of sinusoids (rad in the camera's x and y)."""

    def __init__(self, rng, kind, target, el_deg, slant_m, gamma_deg, speed_mps, slew_rad, slew_period_s):
        self.kind, self.target, self.speed = kind, target, speed_mps
        el = math.radians(el_deg)
        self.h, self.r = slant_m * math.sin(el), slant_m * math.cos(el)
        self.az0 = rng.uniform(0, 2 * math.pi)
        self.sign = rng.choice([-1.0, 1.0])
        g = math.radians(gamma_deg)
        if kind == "arc":
            # constant elevation: cos(gamma) = sin^2 el + cos^2 el cos(daz)
            c = (math.cos(g) - math.sin(el) ** 2) / max(math.cos(el) ** 2, 1e-9)
            self.span = math.acos(float(np.clip(c, -1.0, 1.0)))
            self.length = self.r * self.span
        else:
            self.half = self.r * math.tan(g / 2)
            self.length = 2 * self.half
        self.duration = self.length / speed_mps
        self.slew_amp = slew_rad * rng.uniform(0.5, 1.0, (2, 3))
        self.slew_w = 2 * math.pi / rng.uniform(*slew_period_s, (2, 3))
        self.slew_ph = rng.uniform(0, 2 * math.pi, (2, 3))

    def position(self, t_s):
        s = np.clip(np.asarray(t_s) / self.duration, -0.2, 1.2) - 0.5
        if self.kind == "arc":
            az = self.az0 + self.sign * s * self.span
            off = np.stack([self.r * np.cos(az), self.r * np.sin(az), np.full_like(az, self.h)], -1)
        else:
            foot = np.array([self.r * math.cos(self.az0), self.r * math.sin(self.az0), self.h])
            head = self.sign * np.array([-math.sin(self.az0), math.cos(self.az0), 0.0])
            off = foot + (s * self.length)[:, None] * head
        return self.target + off

    def slew(self, t_s):
        """(n,2) pointing offsets (rad) of the optical axis from the target, camera x and y."""
        t = np.asarray(t_s)[:, None, None]
        return (self.slew_amp * np.sin(self.slew_w * t + self.slew_ph)).sum(-1)

    def world_to_cam(self, t_s):
        pos = self.position(t_s)
        R0 = _lookat_world_to_cam(pos, np.broadcast_to(self.target, pos.shape))
        d = np.linalg.norm(self.target - pos, axis=1)[:, None]
        sl = self.slew(t_s)
        aim = self.target + (R0[:, 0] * sl[:, :1] + R0[:, 1] * sl[:, 1:]) * d
        return pos, _lookat_world_to_cam(pos, aim)


def _intersection_deg(pos_m, target_m):
    u = pos_m[0] - target_m
    v = pos_m[-1] - target_m
    return math.degrees(math.acos(float(np.clip(u @ v / np.linalg.norm(u) / np.linalg.norm(v), -1, 1))))


# ---- one flight ---------------------------------------------------------------------------------------------

def _effects(rng, family: str) -> tuple[str, ...]:
    if family == "mix":  # two error families, or one error family and one geometry
        if rng.random() < 0.5:
            a, b = rng.choice(len(ERROR_FAMILIES), 2, replace=False)
            return (ERROR_FAMILIES[a], ERROR_FAMILIES[b])
        return (str(rng.choice(ERROR_FAMILIES)), str(rng.choice(GEOMETRY_FAMILIES)))
    return () if family == "control" else (family,)


def make_flight(seed: int, i: int) -> UnseenFlight:
    """The i-th flight ("u{i:03d}") of seed: family FAMILIES[i % len(FAMILIES)], everything else drawn."""
    rng = np.random.default_rng([seed, 20, i])
    family = FAMILIES[i % len(FAMILIES)]
    eff = _effects(rng, family)
    meta: dict = {}

    # geometry
    el_deg = rng.uniform(15.0, 60.0)
    slant_m = rng.uniform(2000.0, 8000.0)
    gamma_deg = rng.uniform(15.0, 70.0)
    speed = rng.uniform(25.0, 90.0)
    fx = math.exp(rng.uniform(math.log(1500.0), math.log(10000.0)))
    kind = str(rng.choice(["arc", "straight"]))
    if "hover" in eff:
        kind, gamma_deg, speed = "arc", rng.uniform(2.0, 8.0), rng.uniform(3.0, 12.0)
    if "long_lens" in eff:
        fx, slant_m = rng.uniform(15000.0, 30000.0), rng.uniform(10000.0, 20000.0)
    if "oblique" in eff:
        el_deg = rng.uniform(5.0, 10.0)
    if "nadir" in eff:
        el_deg = rng.uniform(80.0, 89.0)
        # an arc at constant elevation can only reach 2 x (90 - el) deg
        gamma_deg = min(gamma_deg, 1.8 * (90.0 - el_deg)) if kind == "arc" else gamma_deg
    W, H = IMAGES[rng.integers(len(IMAGES))]
    fps = float(rng.choice([25.0, 30.0]))
    K = np.array([[fx, 0.0, W / 2 + rng.uniform(-8, 8)], [0.0, fx, H / 2 + rng.uniform(-8, 8)], [0.0, 0.0, 1.0]])
    target = np.array([rng.uniform(-500, 500), rng.uniform(-500, 500), rng.uniform(0.0, 300.0)])
    slew_rad = rng.uniform(0.02, 0.08) * min(W, H) / fx
    slew_period_s = (2.0, 12.0)
    if "lag" in eff:  # the gimbal slews: the target wanders 15-35 % of the image's short side, periods 3-8 s
        slew_rad, slew_period_s = rng.uniform(0.15, 0.35) * min(W, H) / fx, (3.0, 8.0)
    traj = _Trajectory(rng, kind, target, el_deg, slant_m, gamma_deg, speed, slew_rad, slew_period_s)

    # timing: frames at fps, every k-th observed
    n_obs = round(math.exp(rng.uniform(math.log(30.0), math.log(250.0))))
    frames = max(int(traj.duration * fps), n_obs)
    k = max(1, frames // n_obs)
    t_s = np.arange(0, frames, k)[:n_obs] / fps
    n = t_s.size

    # what the operator states, and the base (white) errors at those sigmas
    told = Sigma(pixel_px=rng.uniform(0.3, 1.5), range_m=rng.uniform(1.0, 5.0), position_m=rng.uniform(1.0, 5.0),
                 attitude_deg=math.exp(rng.uniform(math.log(0.05), math.log(0.3))))
    pix_sd, rng_sd = told.pixel_px, told.range_m
    pixel_stated = rng.random() < 2 / 3
    if "pixel_understated" in eff:
        told = dataclasses.replace(told, pixel_px=0.5)
        pix_sd = 0.5 * rng.uniform(3.0, 10.0)
        pixel_stated = True
        meta["pixel_sd_true_px"] = round(pix_sd, 2)
    if "laser_sigma" in eff:
        f = rng.uniform(4.0, 6.0) ** rng.choice([-1.0, 1.0])
        rng_sd = told.range_m * f
        meta["range_sd_true_over_told"] = round(f, 2)

    # the laser: pulses at its rate on its own clock, each on the nearest observed frame
    rate = 1.0
    if "laser_rate" in eff:
        rate = float(rng.choice([0.2, 10.0]))
        meta["laser_hz"] = rate
    pulses = rng.uniform(0, 1 / rate) + np.arange(0.0, t_s[-1] + 0.5 / rate, 1 / rate)
    j = np.clip(np.searchsorted(t_s, pulses), 0, n - 1)
    jm = np.clip(j - 1, 0, n - 1)
    j = np.where(np.abs(t_s[jm] - pulses) < np.abs(t_s[j] - pulses), jm, j)
    spacing = k / fps
    has_range = np.zeros(n, dtype=bool)
    has_range[j[np.abs(t_s[j] - pulses) <= 0.5 * spacing + 1e-9]] = True
    has_pixel = np.ones(n, dtype=bool)
    if "few_pixels" in eff:
        has_range[:] = True
        has_pixel[:] = False
        has_pixel[rng.choice(n, int(rng.integers(5, 11)), replace=False)] = True

    # the truth at the pixels' times; pixels from the true camera
    pos, R = traj.world_to_cam(t_s)
    cam = np.einsum("nij,nj->ni", R, target - pos)
    pixel = cam[:, :2] / cam[:, 2:] * fx + K[:2, 2]
    pixel += rng.normal(0.0, pix_sd, (n, 2))
    if "pixel_walk" in eff:
        end = rng.uniform(3.0, 8.0)
        walk = np.cumsum(rng.normal(0.0, 1.0, (n, 2)), axis=0)
        pixel += walk * end / math.sqrt(n)
        meta["pixel_walk_end_rms_px"] = round(end, 2)
    if "pixel_offset" in eff:
        a, m = rng.uniform(0, 2 * math.pi), rng.uniform(2.0, 6.0)
        pixel += m * np.array([math.cos(a), math.sin(a)])
        meta["pixel_offset_px"] = round(m, 2)
    seen = has_pixel & (pixel[:, 0] >= 0) & (pixel[:, 0] < W) & (pixel[:, 1] >= 0) & (pixel[:, 1] < H)

    aim_point = target.copy()
    if "lever_arm" in eff:
        a, m = rng.uniform(0, 2 * math.pi), rng.uniform(5.0, 30.0)
        aim_point = target + m * np.array([math.cos(a), math.sin(a), rng.uniform(-0.3, 0.3)])
        meta["lever_arm_m"] = round(m, 1)
    range_m = np.linalg.norm(aim_point - pos, axis=1) + rng.normal(0.0, rng_sd, n)
    if "range_quantised" in eff:
        q = float(rng.choice([1.0, 5.0]))
        range_m = np.round(range_m / q) * q
        meta["range_step_m"] = q

    # telemetry: the pose at the stamped time (late by the lag), plus white errors, steps and spikes
    t_pose = t_s
    if "lag" in eff:
        lag = rng.uniform(0.05, 0.30)
        t_pose = t_s - lag
        meta["lag_ms"] = round(1000 * lag)
    pos_tel, R_tel = traj.world_to_cam(t_pose) if t_pose is not t_s else (pos, R)
    pos_tel = pos_tel + rng.normal(0.0, told.position_m, (n, 3))
    att = rng.normal(0.0, math.radians(told.attitude_deg), (n, 3))
    if "gnss_step" in eff:
        t0 = rng.uniform(0.3, 0.7) * t_s[-1]
        step = rng.normal(0.0, 1.0, 3)
        step *= rng.uniform(3.0, 10.0) / np.linalg.norm(step)
        pos_tel += (t_s >= t0)[:, None] * step
        meta["gnss_step_m"] = round(float(np.linalg.norm(step)), 2)
    if "attitude_spike" in eff:
        t0 = rng.uniform(0.2, 0.8) * t_s[-1]
        on = (t_s >= t0) & (t_s < t0 + 0.5)
        if not on.any():  # sparse frames: the glitch hits the nearest one
            on[np.argmin(np.abs(t_s - t0))] = True
        ax = int(rng.integers(3))
        att[on, ax] += math.radians(rng.uniform(1.0, 2.0)) * rng.choice([-1.0, 1.0])
        meta["spike_frames"] = int(on.sum())
    R_tel = _small_rotation(att) @ R_tel
    P = K @ np.concatenate([R_tel, -np.einsum("nij,nj->ni", R_tel, pos_tel)[:, :, None]], axis=2)

    keep = seen | has_range
    sigma = told if pixel_stated else dataclasses.replace(told, pixel_px=None)
    obs = Observations(P=P[keep], pixel=np.where(seen[:, None], pixel, np.nan)[keep], platform_m=pos_tel[keep],
                       range_m=np.where(has_range, range_m, np.nan)[keep],
                       t_ns=np.round(t_s[keep] * 1e9).astype(np.int64), sigma=sigma, truth_m=target)
    meta.update({"kind": kind, "el_deg": round(el_deg, 1), "slant_m": round(slant_m), "fx_px": round(fx),
                 "gamma_deg": round(_intersection_deg(pos, target), 1), "speed_mps": round(speed, 1),
                 "fps": fps, "n": int(keep.sum()), "pixels": int(seen[keep].sum()),
                 "ranges": int(has_range[keep].sum()), "duration_s": round(float(t_s[-1]), 1),
                 "pixel_stated": bool(pixel_stated), "told": told.to_dict()})
    return UnseenFlight(f"u{i:03d}", family, eff, obs, meta)


# ---- running ------------------------------------------------------------------------------------------------

def _mle_extras(est) -> dict:
    ex = est.extras
    fit = ex.get("fit", {})
    starts = ex.get("starts", {}) or {}
    bias = ex.get("boresight_bias") or {}
    return {"status": est.status.name.lower(), "message": fit.get("message"), "consistent": fit.get("consistent"),
            "chi2": fit.get("chi2"), "chi2_dof": fit.get("dof"), "chi2_p": fit.get("p_value"),
            "autocorrelation_pixel": fit.get("autocorrelation_pixel"),
            "variance_factors": ex.get("variance_factors"), "sigma0_sq": ex.get("sigma0_sq"),
            "rejected": len(ex.get("rejected", [])), "robust": ex.get("robust"),
            "start": starts.get("chosen"), "not_determined": starts.get("not_determined"),
            "cov_inflation": fit.get("covariance_inflation"), "disagree": starts.get("disagree"),
            "bias_deg": [round(bias[k], 3) for k in ("u_deg", "v_deg", "u_prior_deg")] if bias else None,
            "learned_tau_s": _learned(ex.get("error_model"))[0], "learned_drifts": _learned(ex.get("error_model"))[1],
            "learned_attitude_deg": (ex.get("error_model") or {}).get("attitude_deg")}


def _learned(model: dict | None) -> tuple:
    """The learned drift model's correlation time (s) and which errors drift ("a": attitude, "p": position, "ap"),
    or (None, None)."""
    if not model:
        return None, None
    a, p = model.get("attitude_tau_s"), model.get("position_tau_s")
    return (a if a is not None else p), ("a" if a is not None else "") + ("p" if p is not None else "")


def evaluate(f: UnseenFlight, timeout_s: float, mle_options: dict | None = None) -> dict:
    """Every method on flight f (mle with mle_options): errors (m), mle's NEES and extras, the catastrophe verdict
    (scripts/zoo.py's rule)."""
    errors, failed, r = run_methods(f.obs, timeout_s, mle_options)
    row = {"name": f.name, "family": f.family, "effects": list(f.effects), **f.meta, "errors_m": errors,
           "failed": failed, "mle_wall_s": r["wall_s"],
           "mle_nees": _nees(r, f.obs.truth_m) if "mle" in errors else None}
    if "mle" in errors:
        row["mle"] = _mle_extras(r["estimate"])
    row["others_median_m"], row["bound_m"], row["catastrophe"] = catastrophe(row["errors_m"])
    row["inside"] = row["mle_nees"] is not None and row["mle_nees"] <= CHI2_3_95
    return row


def summarize(rows: list[dict], label: str) -> dict:
    return {"group": label, "flights": len(rows), "catastrophes": sum(r["catastrophe"] for r in rows),
            "median_mle_m": _median([r["errors_m"].get("mle") for r in rows]),
            "median_others_m": _median([r["others_median_m"] for r in rows]),
            "median_best_other_m": _median([min((e for m, e in r["errors_m"].items() if m != "mle"), default=None)
                                            for r in rows]),
            "coverage_mle": sum(r["inside"] for r in rows) / len(rows),
            "median_nees": _median([r["mle_nees"] for r in rows]),
            "mle_wall_median_s": _median([r["mle_wall_s"] for r in rows]),
            "mle_wall_max_s": max(r["mle_wall_s"] for r in rows),
            "mle_unsolved": sum("mle" in r["failed"] for r in rows)}


def _table(summaries: list[dict]) -> str:
    lines = ["| family | flights | catastrophes | median error mle / others / best other m | 95 % coverage mle | "
             "median e^T C^-1 e | mle wall median / max s | mle unsolved |",
             "|---|---:|---:|---|---:|---:|---|---:|"]
    for s in summaries:
        lines.append(f"| {s['group']} | {s['flights']} | {s['catastrophes']} | {s['median_mle_m']:.2f} / "
                     f"{s['median_others_m']:.2f} / {s['median_best_other_m']:.2f} | {s['coverage_mle']:.1%} | "
                     f"{s['median_nees']:.2f} | {s['mle_wall_median_s']:.2f} / {s['mle_wall_max_s']:.1f} | "
                     f"{s['mle_unsolved']} |")
    return "\n".join(lines)


def _fmt_row(r: dict) -> str:
    errs = " ".join(f"{m}={e:.1f}" for m, e in r["errors_m"].items())
    nees = "-" if r["mle_nees"] is None else f"{r['mle_nees']:.1f}"
    mx = r.get("mle", {})
    vf = mx.get("variance_factors") or {}
    chi2 = "-" if mx.get("chi2") is None else f"{mx['chi2']:.0f}/{mx['chi2_dof']:.0f} p={mx['chi2_p']:.2g}"
    tau = ("-" if mx.get("learned_tau_s") is None else
           f"{mx['learned_tau_s']:g}s({mx['learned_drifts']})/{mx['learned_attitude_deg']:.2f}deg")
    acf = "-" if mx.get("autocorrelation_pixel") is None else f"{mx['autocorrelation_pixel']:.2f}"
    extra = (f" [{mx.get('status')} start={mx.get('start')} vf={vf.get('pixel', 1):.3g}/{vf.get('range', 1):.3g} "
             f"chi2/dof={chi2} acf_pix={acf} rej={mx.get('rejected')} bias(u,v,prior)={mx.get('bias_deg')} "
             f"tau={tau} "
             f"disagree={mx.get('disagree')} msg={mx.get('message')!r}]") if mx else ""
    fail = "; ".join(f"{m}: {why}" for m, why in r["failed"].items())
    return (f"{r['name']} {'+'.join(r['effects'])} {r['kind']} n={r['n']} pix={r['pixels']} rng={r['ranges']} "
            f"gamma={r['gamma_deg']} el={r['el_deg']} slant={r['slant_m']} fx={r['fx_px']}: {errs} "
            f"bound={r['bound_m'] if r['bound_m'] is None else round(r['bound_m'], 1)} nees={nees}{extra}"
            + (f" (failed {fail})" if fail else ""))


def diagnose(f: UnseenFlight, row: dict, timeout_s: float, mle_options: dict | None = None) -> None:
    """mle again with the boresight bias prior fixed at the stated attitude sigma (no size learned, no learned
    drift model) and with no bias (`bias_prior_deg` 0): row["diagnosis"] = {variant: [error m, NEES or None] or
    None where it did not solve}."""
    out = {}
    for label, b in (("bias_at_stated", f.obs.sigma.attitude_deg), ("no_bias", 0.0)):
        r = run_method("mle", f.obs, timeout_s, **{**(mle_options or {}), "bias_prior_deg": b})
        ok = r["position"] is not None and np.isfinite(r["position"]).all()
        out[label] = [float(np.linalg.norm(r["position"] - f.obs.truth_m)), _nees(r, f.obs.truth_m)] if ok else None
    row["diagnosis"] = out


def _save(f: UnseenFlight, out: Path) -> None:
    doc = to_dict(f.obs)
    doc["meta"] = {"generator": "scripts/zoo_unseen.py", "family": f.family, "effects": list(f.effects), **f.meta}
    out.mkdir(parents=True, exist_ok=True)
    (out / f"{f.name.replace('/', '_')}.json").write_text(json.dumps(doc))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--flights", type=int, default=170, help="flights (default 170: 10 per family)")
    ap.add_argument("--seed", default="0", help="a seed, or several comma-separated (flights named s1/u018)")
    ap.add_argument("--timeout", type=float, default=20.0, help="seconds per solve (an unsolved mle counts as a "
                    "catastrophe)")
    ap.add_argument("--only", help="comma-separated flight names (u000, u017, ...)")
    ap.add_argument("--family", help="comma-separated families to run")
    ap.add_argument("--save", metavar="DIR", help="write catastrophes (or every --only flight) as observation files")
    ap.add_argument("--json", metavar="OUT", help="every flight's figures and the summaries as JSON")
    ap.add_argument("--verbose", "-v", action="store_true", help="one line per flight")
    ap.add_argument("--diagnose", action="store_true", help="on each catastrophe and flight outside its ellipsoid, "
                    "mle again with the bias prior fixed at the stated attitude sigma and with no bias")
    ap.add_argument("--solve-option", action="append", default=[], metavar="KEY=VALUE",
                    help="an option of every flight's mle (repeatable; VALUE as JSON, else a string), e.g. "
                    "bias_prior_deg=0")
    args = ap.parse_args(argv)
    mle_options = {}
    for kv in args.solve_option:
        key, sep, value = kv.partition("=")
        if not sep:
            ap.error(f"--solve-option {kv!r}: expected KEY=VALUE")
        try:
            mle_options[key] = json.loads(value)
        except json.JSONDecodeError:
            mle_options[key] = value
    try:  # the flight config's own checks of mle's options (names and values)
        mle_options = load_dataclass(METHOD_SCHEMAS["mle"], mle_options, source="--solve-option").given()
    except ConfigError as exc:
        ap.error(str(exc))
    names = set(args.only.split(",")) if args.only else None
    fams = set(args.family.split(",")) if args.family else None
    seeds = [int(x) for x in args.seed.split(",")]
    flights = []
    for seed in seeds:
        for i in range(args.flights):
            if (names is None or f"u{i:03d}" in names) and (fams is None or FAMILIES[i % len(FAMILIES)] in fams):
                f = make_flight(seed, i)
                if len(seeds) > 1:
                    f.name = f"s{seed}/{f.name}"
                flights.append(f)
    t0 = time.perf_counter()
    rows = []
    for f in flights:
        r = evaluate(f, args.timeout, mle_options)
        rows.append(r)
        if args.diagnose and (r["catastrophe"] or not r["inside"]):
            diagnose(f, r, args.timeout, mle_options)
        if args.verbose or r["catastrophe"] or not r["inside"]:
            flag = "CATASTROPHE " if r["catastrophe"] else ("" if r["inside"] else "OUTSIDE ")
            dg = "".join(f" {k}: " + ("failed" if v is None else f"{v[0]:.1f} m (nees "
                                                    + ("-" if v[1] is None else f"{v[1]:.1f}") + ")")
                         for k, v in r.get("diagnosis", {}).items())
            print(flag + _fmt_row(r) + (f" | mle again:{dg}" if dg else ""), flush=True)
        if args.save and (r["catastrophe"] or names):
            _save(f, Path(args.save))
    groups = [summarize([r for r in rows if r["family"] == fam], fam) for fam in FAMILIES
              if any(r["family"] == fam for r in rows)]
    print_run(rows, groups, summarize(rows, "all"), _table, args.seed, t0, args.json, str)
    return 0


if __name__ == "__main__":
    sys.exit(main())
