"""How precisely a method's own algorithm fixes the target on a flight: its answer's covariance under the flight's
stated sensor errors, propagated through the method by finite differences.

The paper's methods give a point and no covariance. To say whether the flight determines a method's answer, and how
well, each error source is applied at one standard deviation to the observations and the method is run again (all
perturbed copies as one batch, `solve_batch`); the answers' differences from the unperturbed answer are the columns
of J sigma, and the covariance is their sum of outer products:

- every pixel coordinate (u and v of each frame), independent, `pixel_px`;
- every laser range, independent, `range_m`;
- a pointing error shared by the frames: constant (a boresight or compass bias) and a linear drift from -sigma at
  the first frame to +sigma at the last (a slowly varying attitude error), each in pan and tilt, applied as the
  pixel shift f * angle it makes; a pointing error independent from frame to frame adds to the pixel's;
- an offset of the cameras' positions shared by the frames (GNSS): it moves every method's answer by itself, so its
  covariance is added as it is.
Where a method's own residuals are larger than the stated sigmas say (robust scale, a misfit; the pixels' after
removing the shared pointing error's constant and drift), its independent pixel or range terms are scaled by that
ratio: the stated model understates its errors there. With more than EXACT_FRAMES frames
the independent terms come from RANDOM_DRAWS draws of all of them at once (a fixed seed) instead of one column per
observation, and a flight of more than MAX_FRAMES frames is thinned evenly to that many, its independent terms
scaled by the ratio, so the cost is bounded whatever the flight's length.

`ErrorSources.from_sigma` takes a video flight's stated sigmas, with the defaults below where it states none. A
perturbed answer that is not finite means the flight does not determine the method's answer (one sigma of one
observation makes it fail): the covariance is then None.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from pipeline.solve.estimate import Status
from pipeline.solve.observations import ObservationBatch, Observations, Sigma
from pipeline.solve.stacked import Stacked
from pipeline.solve_options import OPTIONS

DEFAULT_PIXEL_PX = 1.0
DEFAULT_RANGE_M = 5.0
DEFAULT_ATTITUDE_DEG = 0.5  # the mle's boresight bias prior where no attitude accuracy is stated
EXACT_FRAMES = 64
RANDOM_DRAWS = 48
#: frames the propagation runs on at most: a longer flight is thinned evenly to these, its independent terms scaled
#: by the ratio (independent errors average as 1 / frames; the shared pointing error's effect does not change)
MAX_FRAMES = 256
#: the methods whose answer can be re-run on perturbed observations (`solve_batch`)
PROPAGATED = ("dlt", "vision", "range", "los", "fusion-raw", "fusion", "ridge")
#: chi-square(1)'s median: the robust scale of normalised residuals is sqrt(median(z^2) / this)
_CHI2_1_MEDIAN = 0.45493642311957283


@dataclass(frozen=True)
class Propagated:
    """covariance_m2 (3, 3) ENU m^2 (None: not determined), the parts' traces (m^2) and the misfit scales applied to
    the independent pixel and range terms."""

    covariance_m2: np.ndarray | None
    parts_m2: dict
    misfit_scales: dict
    reason: str | None = None


@dataclass(frozen=True)
class ErrorSources:
    """The errors propagated, 1 sigma: pixel_px and range_m per observation; pointing_noise_deg per frame
    (independent, added to the pixel's as f * angle); pointing_bias_deg constant (in tilt pointing_bias_tilt_deg
    where given: a gravity-referenced pitch knows better than a compass) and pointing_drift_deg a linear drift over
    the flight, each shared by the frames and applied in pan and tilt; shared_covariance_m2 (3, 3) ENU of an offset
    every camera shares (GNSS), which moves the answer by itself."""

    pixel_px: float
    range_m: float
    pointing_bias_deg: float
    pointing_drift_deg: float
    pointing_noise_deg: float = 0.0
    shared_covariance_m2: np.ndarray = field(default_factory=lambda: np.zeros((3, 3)))
    pointing_bias_tilt_deg: float | None = None  # the constant error in tilt where it differs from pan

    @classmethod
    def from_sigma(cls, sigma: Sigma) -> ErrorSources:
        """A video flight's stated sigmas, with the defaults where it states none: the attitude error both as a
        constant and as a drift; the position error as an offset shared by the frames."""
        att = sigma.attitude_deg if sigma.attitude_deg else DEFAULT_ATTITUDE_DEG
        return cls(pixel_px=sigma.pixel_px if sigma.pixel_px else DEFAULT_PIXEL_PX,
                   range_m=sigma.range_m if sigma.range_m else DEFAULT_RANGE_M,
                   pointing_bias_deg=att, pointing_drift_deg=att,
                   shared_covariance_m2=(sigma.position_m or 0.0) ** 2 * np.eye(3))


def _perturbations(obs: Observations, s: ErrorSources, exact: bool, rng: np.random.Generator):
    """(pixel deltas (k, n, 2), range deltas (k, n), kind (k,) 'pixel' | 'range' | 'pointing') of the error
    sources at one sigma, and the drift's shape (n,): -1 at the first frame to +1 at the last."""
    n = obs.n
    has_pix, has_rng = obs.has_pixel, obs.has_range
    fx, fy = (f[0] for f in Stacked.from_observations(obs).focal_px())
    f = np.stack([fx, fy], axis=1)  # (n, 2) px per radian, near the image centre
    sig_px = np.hypot(s.pixel_px, f * np.tan(np.deg2rad(s.pointing_noise_deg)))  # (n, 2)
    t = obs.t_ns.astype(np.float64)
    span = t.max() - t.min()
    ramp = (2.0 * (t - t.min()) / span - 1.0) if span > 0 else np.zeros(n)
    dpx, drg, kind = [], [], []

    def add(px, rg, k):
        dpx.append(px)
        drg.append(rg)
        kind.append(k)

    zero_px, zero_rg = np.zeros((n, 2)), np.zeros(n)
    if exact:
        for i in np.flatnonzero(has_pix):
            for c in (0, 1):
                px = zero_px.copy()
                px[i, c] = sig_px[i, c]
                add(px, zero_rg, "pixel")
        for i in np.flatnonzero(has_rng):
            rg = zero_rg.copy()
            rg[i] = s.range_m
            add(zero_px, rg, "range")
    else:
        for _ in range(RANDOM_DRAWS if has_pix.any() else 0):
            add(rng.standard_normal((n, 2)) * sig_px * has_pix[:, None] / np.sqrt(RANDOM_DRAWS), zero_rg, "pixel")
        for _ in range(RANDOM_DRAWS if has_rng.any() else 0):
            add(zero_px, rng.standard_normal(n) * s.range_m * has_rng / np.sqrt(RANDOM_DRAWS), "range")
    tilt = s.pointing_bias_deg if s.pointing_bias_tilt_deg is None else s.pointing_bias_tilt_deg
    for pan_tilt, shape in (((s.pointing_bias_deg, tilt), np.ones(n)),
                            ((s.pointing_drift_deg, s.pointing_drift_deg), ramp)):
        for c, deg in enumerate(pan_tilt):
            if deg > 0 and has_pix.any() and shape.any():
                px = zero_px.copy()
                px[:, c] = np.where(has_pix, f[:, c] * np.tan(np.deg2rad(deg)) * shape, 0.0)
                add(px, zero_rg, "pointing")
    return np.array(dpx).reshape(-1, n, 2), np.array(drg).reshape(-1, n), np.array(kind), ramp, sig_px


def _robust_scale(z: np.ndarray) -> float:
    """max(1, sqrt(median(z^2) / median of chi-square(1))) of normalised residuals z; 1 with fewer than 4."""
    z = z[np.isfinite(z)]
    return 1.0 if z.size < 4 else max(1.0, float(np.sqrt(np.median(z * z) / _CHI2_1_MEDIAN)))


def misfit_scales(obs: Observations, position_m: np.ndarray, sig_px: np.ndarray, range_m: float,
                  ramp: np.ndarray) -> tuple[float, float]:
    """(pixel, range) misfit scales of an answer: the robust scale of its residuals over their sigmas (sig_px
    (n, 2), range_m), the pixels' after removing what the shared pointing error explains (a constant and a drift per
    axis, least squares), each at least 1."""
    from pipeline.geometry.camera import project

    X = np.asarray(position_m, dtype=np.float64)
    pix, rng = obs.has_pixel, obs.has_range
    scale_px = scale_rg = 1.0
    if pix.sum() > 2:
        res = project(obs.P[pix], np.broadcast_to(X, (int(pix.sum()), 3))) - obs.pixel[pix]
        A = np.column_stack([np.ones(int(pix.sum())), ramp[pix]])
        res = res - A @ np.linalg.lstsq(A, res, rcond=None)[0]
        scale_px = _robust_scale((res / sig_px[pix]).ravel())
    if rng.any():
        res = np.linalg.norm(X - obs.platform_m[rng], axis=1) - obs.range_m[rng]
        scale_rg = _robust_scale(res / range_m)
    return scale_px, scale_rg


def method_solver(method: str, options: dict | None = None) -> Callable:
    """A solver for `propagate`: `method` run by `solve_batch` on a batch, from the unperturbed answer where the
    method takes a start (`initial_m`, to a tolerance of 1e-6 m), with the flight's options."""
    if method not in PROPAGATED:
        raise ValueError(f"cannot propagate errors through {method!r}; only {', '.join(PROPAGATED)}")
    names = {opt.name for opt in OPTIONS[method]}
    o = {key: v for key, v in (options or {}).items() if key in names}

    def solver(batch: ObservationBatch, position_m: np.ndarray) -> np.ndarray:
        from pipeline.solve.methods import solve_batch

        extra = {}
        if "initial_m" in names:
            extra = {"initial_m": np.asarray(position_m, dtype=np.float64),
                     "tol_m": min(float(o.get("tol_m", 1e-4)), 1e-6)}
        be = solve_batch(method, batch, **{**o, **extra})
        X = be.position_m.copy()
        X[np.isin(be.status, (Status.DEGENERATE, Status.DIVERGED))] = np.nan
        return X

    return solver


def propagate(solver: Callable, obs: Observations, position_m: np.ndarray, sources: ErrorSources,
              seed: int = 0) -> Propagated:
    """The covariance of an answer `position_m` (3,) on `obs` under the error `sources`, by finite differences of
    `solver(batch, position_m) -> (B, 3)` (NaN rows where it fails; `method_solver`) over the perturbed copies of
    the observations (module docstring)."""
    thin = 1.0
    if obs.n > MAX_FRAMES:
        keep = np.unique(np.linspace(0, obs.n - 1, MAX_FRAMES).round().astype(int))
        thin = len(keep) / obs.n
        obs = obs.subset(keep)
    n_indep = 2 * int(obs.has_pixel.sum()) + int(obs.has_range.sum())
    dpx, drg, kind, ramp, sig_px = _perturbations(obs, sources, n_indep <= 3 * EXACT_FRAMES,
                                                  np.random.default_rng(seed))
    k = len(kind)
    pixel = np.broadcast_to(obs.pixel, (k + 1, obs.n, 2)).copy()
    rng = np.broadcast_to(obs.range_m, (k + 1, obs.n)).copy()
    pixel[1:] += dpx
    rng[1:] += drg
    rng = np.where(rng > 0, rng, np.nan)
    batch = ObservationBatch(P=np.broadcast_to(obs.P, (k + 1, *obs.P.shape)), pixel=pixel,
                             platform_m=np.broadcast_to(obs.platform_m, (k + 1, obs.n, 3)), range_m=rng,
                             sigma=obs.sigma)
    X = solver(batch, position_m)
    bad = ~np.isfinite(X).all(axis=1)
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        what = "the observations as they are" if i == 0 else f"a one-sigma {kind[i - 1]} error"
        return Propagated(None, {}, {}, f"it fails under {what}")
    D = X[1:] - X[0]
    scales = dict(zip(("pixel", "range"), misfit_scales(obs, position_m, sig_px, sources.range_m, ramp),
                      strict=True))
    parts, cov = {}, np.zeros((3, 3))
    for name in ("pixel", "range", "pointing"):
        d = D[kind == name]
        c = d.T @ d * scales.get(name, 1.0) ** 2 * (thin if name != "pointing" else 1.0)
        parts[name] = float(np.trace(c))
        cov += c
    shared = np.asarray(sources.shared_covariance_m2, dtype=np.float64)
    parts["shared offset"] = float(np.trace(shared))
    return Propagated(cov + shared, parts, scales)
