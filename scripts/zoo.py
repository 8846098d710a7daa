"""The zoo: observation-level flights shaped unlike the sample ones, on which `mle` must never be the worst
method (issue 19; docs/zoo.md).

The flights come from this file's own generator, written independently of `pipeline/synth` and of the solvers'
error model: its own cameras (pinhole, square-ish pixels, a gimbal that tracks the target with a lag, a roll
about the optical axis, pixels outside the image are not seen), its own timing (video frames at 25-30 Hz, the
observations every k-th frame or in bursts of consecutive frames, a laser at 1 Hz on its own clock that hits the
nearest observed frame or nothing, drop-outs, cloud occlusions) and its own telemetry errors (rotations in the
camera frame; Gauss-Markov, random-walk, bias and GNSS-drift processes sampled exactly at the frames' times).
Every flight:

    shape       arc (a circular arc at one height), straight (a straight pass), bursts (2-5 bursts of
                consecutive frames along an arc or a straight line)
    geometry    intersection angle 10-80 deg (first vs last line of sight), slant range 2-10 km at the
                middle of the flight, elevation 15-60 deg, platform speed 25-90 m/s
    camera      fx 1,000-12,000 px (log-uniform), image 600x400 .. 1920x1080, frame rate 25, 29.97 or 30 Hz
    observations 50-600 (log-uniform), laser at 1 Hz (NaN ranges between), 70-100 % of laser returns
    told        what an operator knows (the flight's `sigma`): the nominal pixel sigma (not stated on a third of
                the flights), laser, position and attitude sigmas, no correlation times
    family      as in scripts/calibration.py, with the attitude sigma s_att and position sigma s_pos told:
                independent     attitude s_att and position s_pos white, frame to frame
                gauss_markov    attitude Gauss-Markov s_att, tau 5-60 s; position white
                bias            constant attitude bias per camera axis N(0, b^2), b = 0.5-1 s_att, plus white
                                0.5 s_att (the told sigma is the total)
                random_walk     attitude random walk reaching s_att (rms per axis) at the end of the flight
                gnss_drift      position Gauss-Markov s_pos, tau 60-300 s; attitude white
                range_outliers  independent, plus 1-3 ranges off by 100-500 m
                mistracked      independent, plus a run of consecutive frames (2-10 % of the pixels) on a
                                wrong feature 10-60 px away (the tracker's slip)

On every flight every method runs (`solve(method, obs)`, defaults; a method that cannot solve is left out), and
`told`: `solve("mle", ...)` told the true error model, where ridgeloc can express it (as scripts/calibration.py):
the true sigmas (pixel sigma included) and the squared loss; gauss_markov / gnss_drift: the true correlation time
(generalized least squares); random_walk: tau = max(300 s, 5 x the flight's length), an approximation; bias: the
bias prior set to b and the white attitude sigma; range_outliers / mistracked: without the bad rows; no bias
elsewhere.

Printed per family and overall: flights, catastrophes (mle error > 2 x median(other methods' errors) + 5 m,
listed), median mle / told / others' median errors, median(mle) / median(told) and whether median(mle) <=
1.25 median(told) + 1 m, the 95 % ellipsoid coverage (e^T C^-1 e <= chi2_3(0.95) = 7.815) of mle and told, mle
wall time (median, max, timeouts). The named cases of issue 19 come first ("arc", "straight", "obsfile").

    PYTHONPATH=. python scripts/zoo.py [--flights 210] [--seed 0] [--timeout 120] [--json OUT.json]
                                       [--save DIR] [--only NAME,...] [--list]
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import signal
import statistics
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from pipeline.observation_file import to_dict
from pipeline.solve import solve
from pipeline.solve.observations import Observations, Sigma
from pipeline.solve.uncertainty import CHI2_3_95
from pipeline.solve_options import METHODS

FAMILIES = ("independent", "gauss_markov", "bias", "random_walk", "gnss_drift", "range_outliers", "mistracked")
SHAPES = ("arc", "straight", "bursts")
IMAGES = ((600, 400), (640, 480), (960, 540), (1280, 720), (1920, 1080))
FPS = (25.0, 29.97, 30.0)


@dataclass
class Flight:
    """One zoo flight: the observations (told sigma), what `told` is given, the bad rows and a description."""

    name: str
    family: str
    shape: str
    obs: Observations
    told_sigma: Sigma
    told_options: dict
    bad_pixel: np.ndarray  # (n,) bool: mistracked frames
    bad_range: np.ndarray  # (n,) bool: range outliers
    meta: dict = field(default_factory=dict)


# ---- geometry ---------------------------------------------------------------------------------------------

def _unit(v):
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def _cam_from_world(centre, look_at, roll_rad):
    """(n,3,3) rotations world -> camera (x right, y down, z forward) of cameras at centre (n,3) looking at
    look_at (n,3), rolled by roll_rad (n,) about their optical axes."""
    z = _unit(look_at - centre)
    x = _unit(np.cross(z, [0.0, 0.0, 1.0]))
    y = np.cross(z, x)
    R = np.stack([x, y, z], axis=1)
    c, s = np.cos(roll_rad), np.sin(roll_rad)
    roll = np.zeros((len(c), 3, 3))
    roll[:, 0, 0], roll[:, 0, 1], roll[:, 1, 0], roll[:, 1, 1], roll[:, 2, 2] = c, s, -s, c, 1.0
    return roll @ R


def _los_angle_deg(a, b, target):
    u, v = _unit(a - target), _unit(b - target)
    return math.degrees(math.acos(float(np.clip(u @ v, -1.0, 1.0))))


def _path(rng, shape_path: str, gamma_deg: float, slant_m: float, height_m: float, target):
    """A function s -> (k,3) positions for s in [0, 1] along the path, and the path's length (m). The lines of
    sight from the first and last points make gamma_deg; the middle point is slant_m from the target."""
    horiz = math.sqrt(slant_m ** 2 - height_m ** 2)
    az0 = rng.uniform(0.0, 2 * math.pi)
    if shape_path == "arc":
        cos_a = (math.cos(math.radians(gamma_deg)) * slant_m ** 2 - height_m ** 2) / horiz ** 2
        span = math.acos(float(np.clip(cos_a, -1.0, 1.0)))
        sign = rng.choice([-1.0, 1.0])

        def at(s):
            az = az0 + sign * (np.asarray(s) - 0.5) * span
            return target + np.stack([horiz * np.cos(az), horiz * np.sin(az), np.full(np.shape(az), height_m)], -1)

        return at, horiz * span
    # straight: a pass abeam at horizontal distance `horiz`, heading perpendicular to the line of sight, the
    # closest point off-centre by up to a quarter of the pass; length set by bisection to give gamma_deg
    foot = target + np.array([horiz * math.cos(az0), horiz * math.sin(az0), height_m])
    heading = np.array([-math.sin(az0), math.cos(az0), 0.0]) * rng.choice([-1.0, 1.0])
    off = rng.uniform(-0.25, 0.25)

    def make(length):
        def at(s):
            a = (np.asarray(s)[..., None] - 0.5 + off) * length
            return foot + a * heading
        return at

    lo, hi = 1.0, 50.0 * slant_m
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        at = make(mid)
        lo, hi = (mid, hi) if _los_angle_deg(at(0.0), at(1.0), target) < gamma_deg else (lo, mid)
    return make(hi), hi


def _gauss_markov(rng, t_s, sigma, tau_s, dim=3):
    """(n, dim) stationary first-order Gauss-Markov samples at times t_s (exact discretization)."""
    x = np.empty((t_s.size, dim))
    x[0] = rng.normal(0.0, sigma, dim)
    a = np.exp(-np.diff(t_s) / tau_s)
    w = rng.normal(0.0, sigma, (t_s.size - 1, dim))
    for k in range(1, t_s.size):
        x[k] = a[k - 1] * x[k - 1] + math.sqrt(1.0 - a[k - 1] ** 2) * w[k - 1]
    return x


def _loguniform(rng, lo, hi):
    return float(math.exp(rng.uniform(math.log(lo), math.log(hi))))


# ---- one flight -------------------------------------------------------------------------------------------

def make_flight(rng: np.random.Generator, name: str, family: str, shape: str, *, gamma_deg=None, slant_m=None,
                height_m=None, fx=None, image=None, fps=None, n_obs=None, speed_mps=None, laser_returns=None,
                occlusion_s=None, pixel_sigma_px=None, pixel_stated=None, told=None, stride=None,
                path=None, laser_keep=None) -> Flight:
    """A flight drawn from rng; keyword arguments fix any of its parameters (the named cases). family may also
    be "drift" (not in the zoo's cycle; the scale benchmark's): attitude Gauss-Markov tau 20 s and position
    Gauss-Markov tau 120 s."""
    gamma_deg = rng.uniform(10.0, 80.0) if gamma_deg is None else gamma_deg
    slant_m = rng.uniform(2000.0, 10000.0) if slant_m is None else slant_m
    height_m = slant_m * math.sin(math.radians(rng.uniform(15.0, 60.0))) if height_m is None else height_m
    fx = _loguniform(rng, 1000.0, 12000.0) if fx is None else fx
    W, H = IMAGES[rng.integers(len(IMAGES))] if image is None else image
    fps = FPS[rng.integers(len(FPS))] if fps is None else fps
    n_obs = round(_loguniform(rng, 50.0, 600.0)) if n_obs is None else n_obs
    speed_mps = rng.uniform(25.0, 90.0) if speed_mps is None else speed_mps
    if told is None:
        told = Sigma(pixel_px=None, range_m=rng.uniform(1.0, 5.0), position_m=rng.uniform(1.0, 5.0),
                     attitude_deg=_loguniform(rng, 0.05, 0.3))
    pixel_sigma_px = rng.uniform(0.3, 2.0) if pixel_sigma_px is None else pixel_sigma_px
    pixel_stated = rng.random() < 2 / 3 if pixel_stated is None else pixel_stated
    target = np.array([rng.uniform(-800, 800), rng.uniform(-800, 800), rng.uniform(0.0, 400.0)])
    path = (shape if shape != "bursts" else rng.choice(["arc", "straight"])) if path is None else path
    at, length_m = _path(rng, path, gamma_deg, slant_m, height_m, target)

    # timing: video frames at fps over the path; the observed frames every `stride`-th, or in bursts
    duration_s = length_m / speed_mps
    frames = max(int(duration_s * fps), 60)  # a slow platform on a short path: at least 60 frames
    duration_s = frames / fps
    if shape == "bursts":
        k = int(rng.integers(2, 6))
        m = max(n_obs // k, 8)
        starts = np.linspace(0, frames - m, k).astype(int)
        idx = np.unique(np.concatenate([s + np.arange(m) for s in starts]))
    else:
        stride = max(1, round(frames / n_obs)) if stride is None else stride
        idx = np.arange(0, frames, stride)[:n_obs]
    t_s = idx / fps
    s = t_s / duration_s
    true_pos = at(s)
    n = idx.size

    # the laser: 1 Hz on its own clock, each pulse to the nearest observed frame within half the observations'
    # spacing (none in a gap between bursts)
    rate = 1.0
    pulses = rng.uniform(0.0, 1.0 / rate) + np.arange(0.0, duration_s, 1.0 / rate)
    near = np.clip(np.searchsorted(t_s, pulses), 1, n - 1)
    near = np.where(np.abs(t_s[near - 1] - pulses) < np.abs(t_s[near] - pulses), near - 1, near)
    hit = np.abs(t_s[near] - pulses) <= 0.5 * float(np.median(np.diff(t_s))) + 1e-9
    keep_frac = rng.uniform(0.7, 1.0) if laser_keep is None else laser_keep
    hit &= rng.random(pulses.size) < keep_frac
    has_range = np.zeros(n, dtype=bool)
    has_range[near[hit]] = True
    if laser_returns is not None:  # the named straight pass: only so many returns
        on = np.flatnonzero(has_range)
        pick = on[np.linspace(0, on.size - 1, laser_returns).round().astype(int)] if on.size else on
        has_range[:] = False
        has_range[pick] = True

    # the camera: the gimbal tracks the target with a slowly wandering lag, a roll about the optical axis
    K = np.array([[fx, 0.0, W / 2 + rng.uniform(-10, 10)], [0.0, fx * rng.uniform(0.995, 1.005), H / 2 +
                                                            rng.uniform(-10, 10)], [0.0, 0.0, 1.0]])
    lag_px = _gauss_markov(rng, t_s, 0.12 * min(W, H), rng.uniform(1.0, 5.0), dim=2)
    dist = np.linalg.norm(target - true_pos, axis=1)
    R0 = _cam_from_world(true_pos, np.broadcast_to(target, true_pos.shape), np.zeros(n))
    # aim the optical axis away from the target by the lag (small angles: lag / fx radians)
    aim = target + (R0[:, 0] * lag_px[:, :1] + R0[:, 1] * lag_px[:, 1:]) * (dist / fx)[:, None]
    roll = np.deg2rad(rng.uniform(-15.0, 15.0)) + _gauss_markov(rng, t_s, np.deg2rad(2.0), 10.0, dim=1)[:, 0]
    R_true = _cam_from_world(true_pos, aim, roll)
    cam = np.einsum("nij,nj->ni", R_true, target - true_pos)
    pixel = (cam[:, :2] / cam[:, 2:]) * [K[0, 0], K[1, 1]] + K[:2, 2]
    pixel = pixel + rng.normal(0.0, pixel_sigma_px, pixel.shape)
    seen = (pixel[:, 0] >= 0) & (pixel[:, 0] < W) & (pixel[:, 1] >= 0) & (pixel[:, 1] < H)

    # telemetry errors
    s_att = math.radians(told.attitude_deg)
    s_pos = told.position_m
    white_att = rng.normal(0.0, s_att, (n, 3))
    pos_err = rng.normal(0.0, s_pos, (n, 3))
    told_sigma = dataclasses.replace(told, pixel_px=pixel_sigma_px)
    told_options: dict = {"robust": None, "bias_prior_deg": 0.0}
    meta: dict = {}
    if family == "drift":
        att_err = _gauss_markov(rng, t_s, s_att, 20.0)
        pos_err = _gauss_markov(rng, t_s, s_pos, 120.0)
        told_sigma = dataclasses.replace(told_sigma, attitude_tau_s=20.0, position_tau_s=120.0)
        told_options = {"robust": None}
    elif family == "gauss_markov":
        tau = rng.uniform(5.0, 60.0)
        att_err = _gauss_markov(rng, t_s, s_att, tau)
        told_sigma = dataclasses.replace(told_sigma, attitude_tau_s=tau)
        told_options = {"robust": None}
        meta["tau_s"] = tau
    elif family == "bias":
        b = rng.uniform(0.5, 1.0) * s_att
        att_err = rng.normal(0.0, b, 3) + white_att * 0.5
        told_sigma = dataclasses.replace(told_sigma, attitude_deg=0.5 * told.attitude_deg)
        told_options = {"robust": None, "bias_prior_deg": math.degrees(b)}
        meta["bias_sigma_deg"] = math.degrees(b)
    elif family == "random_walk":
        steps = rng.normal(0.0, 1.0, (n, 3)) * np.sqrt(np.diff(t_s, prepend=t_s[0] - 1.0 / fps))[:, None]
        att_err = np.cumsum(steps, axis=0) * s_att / math.sqrt(t_s[-1] - t_s[0] + 1.0 / fps)
        told_sigma = dataclasses.replace(told_sigma, attitude_tau_s=max(300.0, 5.0 * duration_s))
        told_options = {"robust": None}
    else:
        att_err = white_att
    if family == "gnss_drift":
        tau = rng.uniform(60.0, 300.0)
        pos_err = _gauss_markov(rng, t_s, s_pos, tau)
        told_sigma = dataclasses.replace(told_sigma, position_tau_s=tau)
        told_options = {"robust": None}
        meta["tau_s"] = tau

    bad_pixel = np.zeros(n, dtype=bool)
    bad_range = np.zeros(n, dtype=bool)
    if family == "mistracked":
        run = max(1, round(rng.uniform(0.02, 0.10) * seen.sum()))
        start = int(rng.integers(0, max(n - run, 1)))
        bad_pixel[start:start + run] = True
        bad_pixel &= seen
        ang = rng.uniform(0.0, 2 * math.pi)
        off = rng.uniform(10.0, 60.0) * np.array([math.cos(ang), math.sin(ang)])
        pixel = pixel + bad_pixel[:, None] * (off + rng.normal(0.0, 1.0, (n, 2)))

    # measured attitude: the true rotation followed by a small camera-frame error rotation
    R_meas = Rotation.from_rotvec(att_err).as_matrix() @ R_true
    meas_pos = true_pos + pos_err
    P = K @ np.concatenate([R_meas, -np.einsum("nij,nj->ni", R_meas, meas_pos)[:, :, None]], axis=2)
    range_m = np.linalg.norm(target - true_pos, axis=1) + rng.normal(0.0, told.range_m, n)
    if family == "range_outliers":
        on = np.flatnonzero(has_range)
        k = min(int(rng.integers(1, 4)), max(on.size - 3, 0))
        if k:
            bad_range[rng.choice(on, k, replace=False)] = True
            range_m = range_m + bad_range * rng.choice([-1.0, 1.0], n) * rng.uniform(100.0, 500.0, n)

    # cloud occlusion: no pixel and no range for occlusion_s (those observations are dropped)
    keep = np.ones(n, dtype=bool)
    occl = (rng.uniform(0.5, 3.0) if rng.random() < 0.3 else 0.0) if occlusion_s is None else occlusion_s
    if occl > 0:
        t0 = rng.uniform(0.2, 0.8) * duration_s
        keep &= ~((t_s >= t0) & (t_s < t0 + occl))
    pixel = np.where(seen[:, None], pixel, np.nan)
    range_m = np.where(has_range, range_m, np.nan)
    keep &= seen | has_range
    t_ns = np.round(t_s * 1e9).astype(np.int64)
    sigma = dataclasses.replace(told, pixel_px=pixel_sigma_px if pixel_stated else None)
    obs = Observations(P=P[keep], pixel=pixel[keep], platform_m=meas_pos[keep], range_m=range_m[keep],
                       t_ns=t_ns[keep], sigma=sigma, truth_m=target)
    meta.update({"gamma_deg": round(gamma_deg, 2), "slant_m": round(slant_m, 1), "height_m": round(height_m, 1),
                 "fx_px": round(fx, 1), "image": [W, H], "fps": fps, "path": path, "n": int(keep.sum()),
                 "pixels": int(obs.has_pixel.sum()), "ranges": int(obs.has_range.sum()),
                 "duration_s": round(float(t_s[keep][-1] - t_s[keep][0]), 2), "speed_mps": round(speed_mps, 1),
                 "pixel_sigma_px": round(pixel_sigma_px, 3), "pixel_stated": bool(pixel_stated),
                 "occlusion_s": round(occl, 2), "bad_pixels": int(bad_pixel[keep].sum()),
                 "bad_ranges": int(bad_range[keep].sum())})
    return Flight(name, family, shape, obs, told_sigma, told_options, bad_pixel[keep], bad_range[keep], meta)


def named_flights(seed: int) -> list[Flight]:
    """The flights issue 19 names, each with fixed shape and camera; their noise drawn from seed."""
    rng = np.random.default_rng([seed, 19, 0])
    paper = Sigma(pixel_px=0.1, range_m=2.5, position_m=5.0, attitude_deg=0.2)  # the paper's noise
    operator = Sigma(range_m=2.0, position_m=3.0, attitude_deg=0.2)
    arc = make_flight(rng, "arc", "gauss_markov", "arc", gamma_deg=35.0, slant_m=5000.0, height_m=2000.0,
                      fx=10000.0, image=(600, 400), fps=25.0, n_obs=58, speed_mps=49.0, pixel_sigma_px=0.5,
                      pixel_stated=False, told=operator, occlusion_s=0.0, laser_keep=1.0)
    straight = make_flight(rng, "straight", "gnss_drift", "straight", slant_m=3000.0,
                           height_m=1500.0, fx=4500.0, image=(960, 540), fps=30.0, n_obs=300, speed_mps=30.0,
                           laser_returns=2, occlusion_s=1.5, pixel_sigma_px=1.0, pixel_stated=True,
                           told=operator, stride=1, path="straight", **_straight_300m(3000.0, 1500.0))
    obsfile = make_flight(rng, "obsfile", "independent", "arc", gamma_deg=75.0, slant_m=5000.0, height_m=2000.0,
                          fx=1000.0, image=(600, 400), fps=25.0, n_obs=10, speed_mps=90.0, pixel_sigma_px=0.1,
                          pixel_stated=True, told=paper, occlusion_s=0.0)
    return [arc, straight, obsfile]


def _straight_300m(slant_m: float, height_m: float) -> dict:
    """The intersection angle of a 300 m pass abeam at slant_m (the named straight pass is 300 m long)."""
    return {"gamma_deg": math.degrees(2 * math.atan(150.0 / slant_m))}


def random_flight(seed: int, i: int) -> Flight:
    """The zoo's i-th random flight ("z{i:03d}"): family and shape cycling with i, everything else drawn."""
    family = FAMILIES[i % len(FAMILIES)]
    shape = SHAPES[(i // len(FAMILIES)) % len(SHAPES)]
    return make_flight(np.random.default_rng([seed, i]), f"z{i:03d}", family, shape)


def flight(name: str, seed: int = 0) -> Flight:
    """One zoo flight by name: "arc", "straight", "obsfile" or "zNNN"."""
    if name.startswith("z") and name[1:].isdigit():
        return random_flight(seed, int(name[1:]))
    named = {f.name: f for f in named_flights(seed)}
    if name not in named:
        raise KeyError(f"no zoo flight {name!r} (named: {', '.join(named)}; random: z000, z001, ...)")
    return named[name]


def zoo(flights: int, seed: int) -> list[Flight]:
    """The named flights, then random ones up to `flights`."""
    out = named_flights(seed)
    out += [random_flight(seed, i) for i in range(max(flights - len(out), 0))]
    return out


# ---- running ---------------------------------------------------------------------------------------------

class _Timeout(Exception):
    pass


def _on_alarm(signum, frame):
    raise _Timeout()


def run_method(method: str, obs: Observations, timeout_s: float, **options) -> dict:
    """{'position', 'cov', 'estimate', 'wall_s', 'error'} of solve(method, obs, **options); 'estimate' is the
    Estimate (None on a failure), 'error' the failure's one-line text."""
    t0 = time.perf_counter()
    signal.signal(signal.SIGALRM, _on_alarm)
    signal.setitimer(signal.ITIMER_REAL, timeout_s)
    try:
        est = solve(method, obs, **options)
        out = {"position": est.position_m, "cov": est.covariance_m2, "estimate": est, "error": None}
    except _Timeout:
        out = {"position": None, "cov": None, "estimate": None, "error": f"did not finish in {timeout_s:g} s"}
    except Exception as exc:  # a method that cannot solve this flight is left out (its reason kept)
        out = {"position": None, "cov": None, "estimate": None,
               "error": f"{type(exc).__name__}: {str(exc).splitlines()[0][:120]}"}
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
    out["wall_s"] = time.perf_counter() - t0
    return out


def _nees(res: dict, truth) -> float | None:
    if res["position"] is None or res["cov"] is None or not np.isfinite(res["cov"]).all():
        return None
    e = res["position"] - truth
    try:
        return float(e @ np.linalg.solve(res["cov"], e))
    except np.linalg.LinAlgError:
        return None


def catastrophe(errors_m: dict[str, float]) -> tuple[float | None, float | None, bool]:
    """(median of the other methods' errors m, bound = 2 x it + 5 m, catastrophe) from {method: error m} of the
    methods that solved a flight: a catastrophe is mle unsolved or beyond the bound (no bound without others)."""
    others = [e for m, e in errors_m.items() if m != "mle"]
    median = statistics.median(others) if others else None
    bound = None if median is None else 2 * median + 5.0
    mle = errors_m.get("mle")
    return median, bound, bool(mle is None or (bound is not None and mle > bound))


def run_methods(obs: Observations, timeout_s: float, mle_options: dict | None = None):
    """Every method on obs (mle with mle_options): ({method: error m} of those that solved, {method: why not} of
    the others, mle's `run_method` result)."""
    errors, failed, mle = {}, {}, None
    for m in METHODS:
        r = run_method(m, obs, timeout_s, **((mle_options or {}) if m == "mle" else {}))
        mle = r if m == "mle" else mle
        if r["position"] is None or not np.isfinite(r["position"]).all():
            failed[m] = r["error"] or "non-finite estimate"
        else:
            errors[m] = float(np.linalg.norm(r["position"] - obs.truth_m))
    return errors, failed, mle


def evaluate(f: Flight, timeout_s: float) -> dict:
    """Every method and `told` on flight f: errors (m), NEES, wall times, the catastrophe verdict."""
    truth = f.obs.truth_m
    errors, failed, r = run_methods(f.obs, timeout_s)
    row = {"name": f.name, "family": f.family, "shape": f.shape, **f.meta, "errors_m": errors, "failed": failed,
           "mle_wall_s": r["wall_s"], "mle_nees": _nees(r, truth)}
    keep = ~(f.bad_pixel | f.bad_range)
    told_obs = dataclasses.replace(f.obs.subset(keep), sigma=f.told_sigma)
    r = run_method("mle", told_obs, timeout_s, **f.told_options)
    row["told_error_m"] = None if r["position"] is None else float(np.linalg.norm(r["position"] - truth))
    row["told_nees"] = _nees(r, truth)
    if r["error"]:
        row["failed"]["told"] = r["error"]
    row["others_median_m"], row["bound_m"], row["catastrophe"] = catastrophe(row["errors_m"])
    return row


def _median(xs):
    xs = [x for x in xs if x is not None]
    return statistics.median(xs) if xs else float("nan")


def summarize(rows: list[dict], label: str) -> dict:
    mle = [r["errors_m"].get("mle") for r in rows]
    told = [r["told_error_m"] for r in rows]
    med_mle, med_told = _median(mle), _median(told)
    nees = [r["mle_nees"] for r in rows]
    told_nees = [r["told_nees"] for r in rows]
    walls = [r["mle_wall_s"] for r in rows]
    return {"group": label, "flights": len(rows), "catastrophes": sum(r["catastrophe"] for r in rows),
            "median_mle_m": med_mle, "median_told_m": med_told,
            "median_others_m": _median([r["others_median_m"] for r in rows]),
            "ratio": med_mle / med_told if med_told else float("nan"),
            "median_rule": bool(med_mle <= 1.25 * med_told + 1.0),
            "coverage_mle": sum(x is not None and x <= CHI2_3_95 for x in nees) / len(rows),
            "coverage_told": sum(x is not None and x <= CHI2_3_95 for x in told_nees) / len(rows),
            "mle_wall_median_s": _median(walls), "mle_wall_max_s": max(walls),
            "mle_unsolved": sum("mle" in r["failed"] for r in rows),
            "mle_timeouts": sum("did not finish" in r["failed"].get("mle", "") for r in rows),
            "told_unsolved": sum("told" in r["failed"] for r in rows)}


def _table(summaries: list[dict]) -> str:
    lines = ["| group | flights | catastrophes | median mle / told / others m | mle / told | <= 1.25 told + 1 m | "
             "coverage mle / told | mle wall median / max s | mle unsolved (timeouts) |",
             "|---|---:|---:|---|---:|---|---|---|---:|"]
    for s in summaries:
        lines.append(f"| {s['group']} | {s['flights']} | {s['catastrophes']} | {s['median_mle_m']:.2f} / "
                     f"{s['median_told_m']:.2f} / {s['median_others_m']:.2f} | {s['ratio']:.2f} | "
                     f"{'yes' if s['median_rule'] else 'NO'} | {s['coverage_mle']:.1%} / {s['coverage_told']:.1%} | "
                     f"{s['mle_wall_median_s']:.2f} / {s['mle_wall_max_s']:.1f} | "
                     f"{s['mle_unsolved']} ({s['mle_timeouts']}) |")
    return "\n".join(lines)


def _fmt_row(r: dict) -> str:
    errs = " ".join(f"{m}={e:.1f}" for m, e in r["errors_m"].items())
    told = "-" if r["told_error_m"] is None else f"{r['told_error_m']:.1f}"
    fail = "; ".join(f"{m}: {why}" for m, why in r["failed"].items())
    return (f"{r['name']} {r['family']}/{r['shape']}({r['path']}) n={r['n']} pix={r['pixels']} rng={r['ranges']} "
            f"gamma={r['gamma_deg']:.0f} slant={r['slant_m']:.0f} fx={r['fx_px']:.0f}: {errs} told={told} "
            f"bound={r['bound_m'] if r['bound_m'] is None else round(r['bound_m'], 1)}"
            + (f" [{fail}]" if fail else ""))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--flights", type=int, default=210, help="flights, the 3 named ones included (default 210)")
    ap.add_argument("--seed", default="0", help="a seed, or several comma-separated (flights named s1/z019): mle was "
                    "developed on seed 0, the evidence step on seeds 1-7 (docs/validation.md)")
    ap.add_argument("--timeout", type=float, default=120.0, help="seconds per solve before it counts as unsolved "
                    "(an unsolved mle counts as a catastrophe; timeouts are also counted apart, they depend on the "
                    "machine's load)")
    ap.add_argument("--only", help="comma-separated flight names (e.g. arc,straight,z004)")
    ap.add_argument("--json", metavar="OUT", help="write every flight's figures and the summaries as JSON")
    ap.add_argument("--save", metavar="DIR", help="write every flight as an observations file (truth_m included)")
    ap.add_argument("--list", action="store_true", help="list the flights' parameters and stop")
    ap.add_argument("--verbose", "-v", action="store_true", help="one line per flight")
    args = ap.parse_args(argv)
    seeds = [int(x) for x in args.seed.split(",")]
    flights = []
    for seed in seeds:
        for f in zoo(args.flights, seed):
            if len(seeds) > 1:
                f.name = f"s{seed}/{f.name}"
            flights.append(f)
    if args.only:
        wanted = set(args.only.split(","))
        flights = [f for f in flights if f.name in wanted]
    if args.save:
        out = Path(args.save)
        out.mkdir(parents=True, exist_ok=True)
        for f in flights:
            doc = to_dict(f.obs)
            doc["meta"] = {"family": f.family, "shape": f.shape, **f.meta,
                           "told_sigma": f.told_sigma.to_dict(), "told_options": f.told_options}
            (out / f"{f.name}.json").parent.mkdir(parents=True, exist_ok=True)
            (out / f"{f.name}.json").write_text(json.dumps(doc))
    if args.list:
        for f in flights:
            print(f.name, f.family, f.shape, json.dumps(f.meta))
        return 0
    t0 = time.perf_counter()
    rows = []
    for f in flights:
        rows.append(evaluate(f, args.timeout))
        if args.verbose or rows[-1]["catastrophe"] or f.name.split("/")[-1] in ("arc", "straight", "obsfile"):
            print(("CATASTROPHE " if rows[-1]["catastrophe"] else "") + _fmt_row(rows[-1]), flush=True)
    groups = [summarize([r for r in rows if r["family"] == fam], fam) for fam in FAMILIES
              if any(r["family"] == fam for r in rows)]
    groups += [summarize([r for r in rows if r["shape"] == sh], f"shape {sh}") for sh in SHAPES
               if any(r["shape"] == sh for r in rows)]
    print_run(rows, groups, summarize(rows, "all"), _table, args.seed, t0, args.json, float)
    return 0


def print_run(rows: list[dict], groups: list[dict], overall: dict, table, seed, t0: float, json_path: str | None,
              json_default) -> None:
    """The end of a zoo run (this script's and zoo_unseen.py's): the table (`table` of the group summaries and
    the overall one), the catastrophes by name, the count and time, and the JSON file where asked for."""
    print()
    print(table([*groups, overall]))
    cats = [r["name"] for r in rows if r["catastrophe"]]
    print(f"\ncatastrophes ({len(cats)}): {', '.join(cats) or 'none'}")
    print(f"{len(rows)} flights, seed {seed}, {time.perf_counter() - t0:.0f} s")
    if json_path:
        Path(json_path).write_text(json.dumps({"seed": seed, "flights": rows, "groups": groups, "overall": overall},
                                              indent=1, default=json_default))


if __name__ == "__main__":
    sys.exit(main())
