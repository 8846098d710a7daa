"""Where a flight's lines of sight meet: the cluster a gimbal that tracks a target makes, and its size.

Per frame i a ray (origin o_i, unit direction d_i, ENU metres) and optionally a laser range r_i. Two clusters:
- the laser-sphere points P_i = o_i + r_i d_i (frames with a range): their spread is the cluster size;
- the rays' least-squares meeting point X (minimising the squared perpendicular distances): the rays' median
  miss distance is the cluster size where there are no ranges, and X is the reference the ranges are checked
  against (independent of them).
A right convention gives a spread of the attitude error times the distance (tens of metres at 5 km); a wrong one
scatters the points over kilometres, or puts the meeting point behind the cameras.
Where the rays are nearly parallel (a short clip, a distant target) their meeting point is not determined along
them: a pointing error delta moves it by about |X - o| delta / sin(gamma) (gamma the angle between the first and
last ray), which does not average out over frames when the error drifts slowly, as gimbal errors do.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from pipeline.answer import NARROW_SPAN_DEG
from pipeline.geometry.rays import meeting_point

# A spread above this fraction of the distance (2.9 deg) is beyond any attitude, tracking or clock error a flight
# can have, and below CONSISTENT_REL (1.1 deg) everything is consistent; in between the check warns.
INCONSISTENT_REL = 0.05
CONSISTENT_REL = 0.02
MIN_RAYS = 3
# The pointing error (rad) taken for where the rays meet along them: the largest attitude error with which the
# cluster still counts as consistent (CONSISTENT_REL of the distance), so the range check asks no more of the
# meeting point than the convergence check does.
POINTING_ERROR_RAD = CONSISTENT_REL


@dataclass(frozen=True)
class Cluster:
    """n rays used (n_ranged of them with a range); spread_m the cluster size (`metric`: "laser sphere" or
    "ray intersection"); centre_m (3,) the cluster's centre (median laser-sphere point, else X); meet_m (3,) the
    rays' meeting point X; distance_m the median distance from the origins to the centre; ahead: X lies in front
    of the cameras (positive depth along the median ray) and below the highest origin; range_bias_m the median of
    r_i - |X - o_i| and range_bias_sigma_m its standard error (NaN without ranges); gamma_deg the angle between the
    first and the last ray and meet_along_sigma_m how far a POINTING_ERROR_RAD error moves X along the rays."""

    n: int
    n_ranged: int
    metric: str
    spread_m: float
    centre_m: np.ndarray
    meet_m: np.ndarray
    distance_m: float
    ahead: bool
    range_bias_m: float
    range_bias_sigma_m: float
    gamma_deg: float = math.nan
    meet_along_sigma_m: float = math.nan

    @property
    def no_baseline(self) -> bool:
        """No laser ranges and lines of sight spanning less than NARROW_SPAN_DEG: where they meet is noise (a
        hover, a short clip of a distant target), and no convention can be judged by it."""
        return self.n_ranged < MIN_RAYS and not self.gamma_deg >= NARROW_SPAN_DEG

    @property
    def meet_undetermined(self) -> bool:
        """Where the rays meet is not determined along them: its uncertainty there exceeds the range bias."""
        return bool(abs(self.range_bias_m) <= self.meet_along_sigma_m)

    @property
    def relative_spread(self) -> float:
        return self.spread_m / self.distance_m if self.distance_m > 0 and self.ahead else math.inf

    @property
    def consistent(self) -> bool:
        return self.relative_spread <= CONSISTENT_REL

    @property
    def inconsistent(self) -> bool:
        """Beyond doubt: behind the cameras or scattered over more than INCONSISTENT_REL of the distance."""
        return self.relative_spread > INCONSISTENT_REL

    def describe(self) -> str:
        if not self.ahead:
            return "the lines of sight meet behind the cameras or above them"
        return f"{self.metric} points within {_fmt_m(self.spread_m)} (median, at {_fmt_m(self.distance_m)})"


def _fmt_m(x: float) -> str:
    return f"{x / 1000:.1f} km" if abs(x) >= 1000 else f"{x:.0f} m"


def cluster(origins: np.ndarray, dirs: np.ndarray, ranges_m: np.ndarray | None = None) -> Cluster | None:
    """The cluster of n rays (see the module docstring); None with fewer than MIN_RAYS finite rays."""
    o = np.asarray(origins, float).reshape(-1, 3)
    d = np.asarray(dirs, float).reshape(-1, 3)
    r = np.full(len(o), np.nan) if ranges_m is None else np.asarray(ranges_m, float).reshape(-1)
    ok = np.isfinite(o).all(1) & np.isfinite(d).all(1)
    o, d, r = o[ok], d[ok] / np.linalg.norm(d[ok], axis=1, keepdims=True), r[ok]
    if len(o) < MIN_RAYS:
        return None
    X, miss, Ninv = meeting_point(o, d)
    ranged = np.isfinite(r) & (r > 0)
    d_med = np.median(d, axis=0)
    d_med /= np.linalg.norm(d_med)
    finite_X = bool(np.isfinite(X).all())
    depth = (X - o) @ d_med if finite_X else np.full(len(o), -1.0)
    ahead = finite_X and float(np.median(depth)) > 0 and float(X[2]) < float(o[:, 2].max())
    bias = sigma = math.nan
    gamma = math.acos(float(np.clip(d[0] @ d[-1], -1.0, 1.0)))
    meet_along = (float(np.median(np.linalg.norm(X - o, axis=1))) * POINTING_ERROR_RAD / max(math.sin(gamma), 1e-12)
                  if finite_X else math.inf)
    if ranged.sum() >= MIN_RAYS:
        P = o[ranged] + r[ranged, None] * d[ranged]
        centre = np.median(P, axis=0)
        spread = float(np.median(np.linalg.norm(P - centre, axis=1)))
        metric = "laser sphere"
        distance = float(np.median(r[ranged]))
        # Laser-sphere points are in front by construction; rays pointing above the platform give a wrong
        # convention away.
        ahead = bool(np.median(P[:, 2]) < o[:, 2].max())
        if finite_X:
            resid = r[ranged] - np.linalg.norm(X - o[ranged], axis=1)
            bias = float(np.median(resid))
            s2 = float(np.sum(miss ** 2) / max(2 * len(o) - 3, 1))
            sigma_depth = math.sqrt(max(float(d_med @ Ninv @ d_med) * s2, 0.0))
            sigma_r = 1.2533 * float(np.std(resid)) / math.sqrt(ranged.sum())
            sigma = math.hypot(sigma_depth, sigma_r)
    else:
        centre = X
        spread = float(np.median(miss)) if finite_X else math.inf
        metric = "ray intersection"
        distance = float(np.median(np.linalg.norm(X - o, axis=1))) if finite_X else math.nan
    return Cluster(n=len(o), n_ranged=int(ranged.sum()), metric=metric, spread_m=spread, centre_m=centre,
                   meet_m=X, distance_m=distance, ahead=bool(ahead), range_bias_m=bias, range_bias_sigma_m=sigma,
                   gamma_deg=math.degrees(gamma), meet_along_sigma_m=meet_along)


def range_bias_problem(c: Cluster) -> str | None:
    """A one-line problem when the laser ranges disagree with the distance to where the rays meet beyond their
    uncertainty (5 sigma) and by more than 3 % of the range (a bias, a wrong range source or unit), else None.
    None too where the meeting point is undetermined along the rays (see `meet_undetermined_warning`)."""
    if not math.isfinite(c.range_bias_m) or not c.ahead or c.meet_undetermined:
        return None
    if abs(c.range_bias_m) <= max(5 * c.range_bias_sigma_m, 0.03 * c.distance_m):
        return None
    longer = "longer" if c.range_bias_m > 0 else "shorter"
    ratio = c.distance_m / (c.distance_m - c.range_bias_m) if c.distance_m != c.range_bias_m else math.inf
    hint = " (a unit: feet?)" if abs(ratio - 3.2808) < 0.1 else ""
    return (f"the laser ranges are {_fmt_m(abs(c.range_bias_m))} {longer} than the distance to where the lines "
            f"of sight meet (+-{_fmt_m(c.range_bias_sigma_m)}): a range bias, a wrong range source{hint} or a "
            "wrong clock.range offset")


#: lines of sight spanning less than this (deg) are called nearly parallel; wider ones can still leave where they meet
#: undetermined for a long range (a pointing error moves it by distance * error / sin(span))
PARALLEL_DEG = 10.0


def meet_undetermined_warning(c: Cluster) -> str | None:
    """A one-line warning when the laser ranges disagree with where the rays meet beyond the statistical check
    but within how far a pointing error moves that point along nearly parallel rays, else None."""
    if not math.isfinite(c.range_bias_m) or not c.ahead or not c.meet_undetermined:
        return None
    if abs(c.range_bias_m) <= max(5 * c.range_bias_sigma_m, 0.03 * c.distance_m):
        return None
    head = (f"the lines of sight are nearly parallel (first to last {c.gamma_deg:.1f} deg): where they meet is "
            if c.gamma_deg < PARALLEL_DEG else
            f"where the lines of sight meet (first to last {c.gamma_deg:.1f} deg, {_fmt_m(c.distance_m)} away) is ")
    return (head + f"undetermined along them (+-{_fmt_m(c.meet_along_sigma_m)} for a "
            f"{math.degrees(POINTING_ERROR_RAD):.1f} deg pointing error), so the laser ranges "
            f"({_fmt_m(abs(c.range_bias_m))} {'longer' if c.range_bias_m > 0 else 'shorter'}) cannot be checked "
            "against it")
