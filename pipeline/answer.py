"""One answer per target: the rule that picks it from every method's estimate, and why a target has none.

The rule (docs/outputs.md, "The answer") uses only what the flight itself shows, never the truth:

1. A method's estimate is a candidate only where the flight determines it (`judge`): it exists and is finite; its
   solver did not find the geometry rank deficient or diverge; it lies in front of the cameras; its 95 % error
   ellipsoid's largest semi-axis is at most DETERMINED_REL of its distance from the cameras (lines of sight too
   nearly parallel to fix where they meet, no baseline); and it is not below the ground by more than GROUND_SIGMAS
   of its vertical uncertainty and the ground's allow (the DEM where the flight has one, else the lowest dry land
   on Earth). The uncertainty is the method's own covariance (mle) or its answer's covariance propagated through
   the method under the flight's stated errors (`pipeline.solve.propagate`); what moves the answer as a whole (an
   offset every camera's position shares, the terrain model's own error) counts in its CE90, not in whether the
   flight's geometry determines the point.
2. The answer is the MLE when it is a candidate and its fit checks pass: its error model fits the flight, or its
   misfit (`misfit_factor`: the largest variance factor its fit checks measured, the covariance inflation, the
   robust scale guard's and, where the chi-square test fails, chi-square over its degrees of freedom) is at most
   MAX_FIT_INFLATION. Where the model does not fit, the MLE's covariance is widened to that misfit wherever its
   own inflation fell short (a bias-mixture covariance is not widened by the scale guard), before it is judged.
3. Otherwise the simpler method with the smallest CE90 (horizontal circle holding 90 %) among the candidates; an
   MLE whose fit checks failed is not one (its model does not describe the flight). `ridge` is determined only
   where `fusion`, the same
   observations and model without its penalty, is: the penalty narrows its ellipse by pulling the point towards
   where its iteration started, not by measuring it.
4. Otherwise there is no answer: the target is `not_located`, with the reason in words a user can act on.

`dji` (the photos' own laser target, the maker's one-shot answer) is compared, never chosen: no covariance of it
can be stated.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from pipeline.geometry.frames import lla_from_enu
from pipeline.geometry.geoid import geoid_undulation_m
from pipeline.geometry.rays import camera_rays_m
from pipeline.solve.estimate import Estimate, Status
from pipeline.solve.fit_checks import CHI2_ALPHA
from pipeline.solve.observations import Observations
from pipeline.solve.propagate import PROPAGATED, ErrorSources, method_solver, propagate
from pipeline.solve.uncertainty import CHI2_3_95, cep_m, horizontal

#: a method is determined where its 95 % error ellipsoid's largest semi-axis is at most this fraction of its
#: distance from the cameras
DETERMINED_REL = 0.25
#: the MLE's fit checks pass when the covariance it inflated for a misfit grew at most this much (variances; the
#: axes x3): the same 9 x the evidence step admits for a variance factor (pipeline.solve.learned_tau.admitted)
MAX_FIT_INFLATION = 9.0
#: below the ground by more than this many standard deviations (the estimate's and the ground's) is underground
GROUND_SIGMAS = 3.0
#: below the lowest dry land (the Dead Sea's shore, about 430 m below sea level): a ground point there is underground
#: anywhere on Earth
LOWEST_LAND_MSL_M = -440.0
#: the 90 % two-sided quantile of the standard normal: LE90 = Z90 sigma_up
Z90 = 1.6448536269514722
#: lines of sight spanning less than this (deg), with no laser range or terrain model, have no baseline to meet
NARROW_SPAN_DEG = 3.0
#: compared, never the answer: the photos' own laser target (nothing states its uncertainty)
NEVER_THE_ANSWER = ("dji",)


@dataclass(frozen=True)
class Verdict:
    """Whether the flight determines one method's estimate: `reason` says why not (None when it does); the
    covariance (3, 3) ENU m^2 the verdict used (the method's own, or propagated: `covariance_source`), its CE90 (m)
    and the 95 % semi-axis over the distance from the cameras."""

    method: str
    determined: bool
    reason: str | None = None
    covariance_m2: np.ndarray | None = None
    covariance_source: str = ""
    ce90_m: float = math.nan
    relative_uncertainty: float = math.nan

    def to_dict(self) -> dict:
        return {"determined": self.determined, "reason": self.reason,
                "covariance_m2": None if self.covariance_m2 is None else np.asarray(self.covariance_m2).tolist(),
                "covariance_source": self.covariance_source or None,
                "ce90_m": _finite(self.ce90_m), "relative_uncertainty": _finite(self.relative_uncertainty)}

    @classmethod
    def from_dict(cls, method: str, d: dict) -> Verdict:
        cov = d.get("covariance_m2")
        return cls(method, bool(d["determined"]), d.get("reason"),
                   None if cov is None else np.asarray(cov, dtype=np.float64), d.get("covariance_source") or "",
                   _nan(d.get("ce90_m")), _nan(d.get("relative_uncertainty")))


@dataclass(frozen=True)
class Answer:
    """A target's one answer: `located`, the method it came from, its position (3,) and covariance (3, 3) in the
    flight's ENU frame (m, m^2), `reason` (why this method, or why there is none), the verdict on every method and
    the number of observations."""

    located: bool
    method: str | None
    position_m: np.ndarray | None
    covariance_m2: np.ndarray | None
    reason: str
    n_observations: int
    verdicts: dict[str, Verdict] = field(default_factory=dict)

    @property
    def status(self) -> str:
        return "located" if self.located else "not_located"

    @property
    def covariance_source(self) -> str:
        v = self.verdicts.get(self.method or "")
        return v.covariance_source if v is not None else ""

    def to_dict(self) -> dict:
        return {"status": self.status, "method": self.method,
                "position_m": None if self.position_m is None else [float(v) for v in self.position_m],
                "covariance_m2": None if self.covariance_m2 is None else np.asarray(self.covariance_m2).tolist(),
                "covariance_source": self.covariance_source or None, "reason": self.reason,
                "n_observations": int(self.n_observations),
                "methods": {m: v.to_dict() for m, v in self.verdicts.items()}}

    @classmethod
    def from_dict(cls, d: dict) -> Answer:
        pos, cov = d.get("position_m"), d.get("covariance_m2")
        return cls(d["status"] == "located", d.get("method"),
                   None if pos is None else np.asarray(pos, dtype=np.float64),
                   None if cov is None else np.asarray(cov, dtype=np.float64), str(d.get("reason", "")),
                   int(d.get("n_observations", 0)),
                   {m: Verdict.from_dict(m, v) for m, v in (d.get("methods") or {}).items()})

    def summary(self) -> dict:
        """The answer in the observations' own frame (ENU metres, no geodesy): status, method, position_m, CE90,
        LE90, CEP50, the 95 % ellipse, the covariance and why (`ridgeloc solve`'s answer)."""
        d = {"status": self.status, "method": self.method, "reason": self.reason,
             "position_m": None if self.position_m is None else [float(v) for v in self.position_m]}
        if self.covariance_m2 is not None and np.isfinite(self.covariance_m2).all():
            u = horizontal(np.asarray(self.covariance_m2))
            d.update(ce90_m=u["cep90_m"], le90_m=Z90 * u["sigma_up_m"], cep50_m=u["cep50_m"],
                     ellipse95_semi_major_m=u["ellipse95_semi_major_m"],
                     ellipse95_semi_minor_m=u["ellipse95_semi_minor_m"],
                     ellipse95_azimuth_deg=u["ellipse95_azimuth_deg"],
                     covariance_m2=np.asarray(self.covariance_m2).tolist(), covariance_source=self.covariance_source)
        return d

    @classmethod
    def none(cls, reason: str, n_observations: int = 0) -> Answer:
        """A target without an answer (e.g. one that could not be tracked at all)."""
        return cls(False, None, None, None, reason, n_observations)


def _finite(x) -> float | None:
    return float(x) if x is not None and np.isfinite(x) else None


def _nan(x) -> float:
    return math.nan if x is None else float(x)


def _fmt_m(x: float) -> str:
    return f"{x / 1000:.1f} km" if abs(x) >= 1000 else f"{x:.0f} m"


@dataclass(frozen=True)
class Ground:
    """The ground under an answer: `up_m(e_m, n_m)` its height in the flight's ENU frame (NaN where unknown), its
    1-sigma vertical error and its name in messages (e.g. "the DEM")."""

    up_m: Callable
    sigma_m: float
    name: str


def _ground_below(X: np.ndarray, origin_lla, ground: Ground | None) -> tuple[float, float, str]:
    """(ground height above X's foot in ENU up m, its sigma, its name) at X: the DEM, else the lowest dry land
    (-inf where neither is known: observations without their geodetic origin)."""
    if ground is not None:
        up = float(np.asarray(ground.up_m(np.array(X[0]), np.array(X[1])), dtype=np.float64).reshape(-1)[0])
        if np.isfinite(up):
            return up, ground.sigma_m, ground.name
    if origin_lla is None:
        return -math.inf, 0.0, "the ground"
    lat, lon, h = lla_from_enu(X, origin_lla)
    msl = h - float(geoid_undulation_m(lat, lon))
    return float(X[2]) + (LOWEST_LAND_MSL_M - msl), 0.0, "the lowest dry land on Earth (440 m below sea level)"


def _depths_ok(obs: Observations, X: np.ndarray) -> bool:
    """X lies in front of every camera that saw the target (positive depth along each ray's direction)."""
    if not obs.has_pixel.any():
        return True
    C, a = camera_rays_m(obs.P[obs.has_pixel], obs.pixel[obs.has_pixel])
    return bool(np.all(np.einsum("ij,ij->i", X - C, a) > 0))


def judge(method: str, e: Estimate | None, unsolved_reason: str | None, obs: Observations, origin_lla,
          covariance_m2: np.ndarray | None, covariance_source: str, ground: Ground | None = None,
          covariance_reason: str | None = None, offsets_m2: np.ndarray | None = None) -> Verdict:
    """The verdict on one method's estimate (rule 1 of the module docstring). `offsets_m2`: the part of the
    covariance that moves the answer as a whole (a position offset every camera shares, the terrain model's own
    error): it counts in the answer's CE90 and LE90, not in whether the flight's geometry determines the point."""
    if e is None:
        why = unsolved_reason or "it gave no estimate"
        return Verdict(method, False, why[len(method) + 2:] if why.startswith(f"{method}: ") else why)
    X = np.asarray(e.position_m, dtype=np.float64)
    if not np.isfinite(X).all() or e.status in (Status.DEGENERATE, Status.DIVERGED):
        return Verdict(method, False, "it gave no finite estimate")
    if not _depths_ok(obs, X):
        return Verdict(method, False, "its point lies behind a camera that saw the target")
    if covariance_m2 is None or not np.isfinite(covariance_m2).all():
        why = covariance_reason or "its uncertainty cannot be stated"
        return Verdict(method, False, f"the flight does not determine it: {why}")
    cov = np.asarray(covariance_m2, dtype=np.float64)
    ce90 = float(cep_m(cov[:2, :2], 0.9))
    geometric = cov if offsets_m2 is None else cov - np.asarray(offsets_m2, dtype=np.float64)
    semi95 = math.sqrt(max(float(np.linalg.eigvalsh(geometric).max()), 0.0) * CHI2_3_95)
    dist = float(np.median(np.linalg.norm(obs.platform_m - X, axis=1)))
    rel = semi95 / dist if dist > 0 else math.inf
    v = dict(covariance_m2=cov, covariance_source=covariance_source, ce90_m=ce90, relative_uncertainty=rel)
    if not rel <= DETERMINED_REL:
        return Verdict(method, False, f"the flight does not determine it: its 95 % uncertainty (+-{_fmt_m(semi95)}) "
                                      f"is more than {DETERMINED_REL:.0%} of its distance from the camera "
                                      f"({_fmt_m(dist)})", **v)
    up, sigma_g, name = _ground_below(X, origin_lla, ground)
    allowed = GROUND_SIGMAS * math.hypot(math.sqrt(max(cov[2, 2], 0.0)), sigma_g)
    if X[2] < up - allowed:
        return Verdict(method, False, f"its point lies {_fmt_m(up - X[2])} below {name}, more than its uncertainty "
                                      f"(+-{_fmt_m(allowed)}) allows", **v)
    return Verdict(method, True, None, **v)


def _fit(e: Estimate) -> dict | None:
    """The MLE's fit checks (`pipeline.solve.mle_outputs.fit_summary`) where its error model does not fit, else
    None."""
    fit = e.extras.get("fit") if isinstance(e.extras, dict) else None
    return None if not isinstance(fit, dict) or fit.get("consistent", True) else fit


def misfit_factor(fit: dict) -> tuple[float, float]:
    """(the misfit as a variance factor, the covariance inflation the MLE applied) of a fit that failed: the
    largest of that inflation, the robust scale guard's factor (the spread squared) and, where the chi-square test
    failed, chi-square / degrees of freedom."""
    inflation = max(float(fit.get("covariance_inflation") or 1.0), 1.0)
    spread = float(fit.get("robust_spread") or 1.0)
    chi2, dof, p = fit.get("chi2"), fit.get("dof"), fit.get("p_value")
    chi = chi2 / dof if chi2 is not None and dof and p is not None and p < CHI2_ALPHA else 1.0
    return max(inflation, spread * spread, chi), inflation


def mle_fit_passes(e: Estimate) -> tuple[bool, str | None]:
    """(the MLE's fit checks pass, why not): its error model fits, or its misfit is within MAX_FIT_INFLATION."""
    fit = _fit(e)
    if fit is None:
        return True, None
    factor, _ = misfit_factor(fit)
    if factor <= MAX_FIT_INFLATION:
        return True, None
    return False, (f"its error model does not fit this flight (residuals x{math.sqrt(factor):.1f} the stated "
                   f"sigmas, more than x{math.sqrt(MAX_FIT_INFLATION):.0f})")


def _misfit_covered(e: Estimate) -> str:
    """What the answer's reason adds when the MLE's error model does not fit but its covariance, widened to the
    misfit, covers it (its fit checks pass all the same), so the reason does not read as a clean fit beside the
    run's sentence that the model does not fit; "" when it fits."""
    fit = _fit(e)
    if fit is None:
        return ""
    factor, _ = misfit_factor(fit)
    return (f" (its error model does not fit this flight: the ellipse widened x{math.sqrt(factor):.1f} to cover "
            f"the misfit, at most x{math.sqrt(MAX_FIT_INFLATION):.0f} allowed)")


def _widened_to_misfit(e: Estimate) -> np.ndarray:
    """The MLE's covariance, widened to its misfit (`misfit_factor`) where its own inflation fell short."""
    cov = np.asarray(e.covariance_m2, dtype=np.float64)
    fit = _fit(e)
    if fit is None:
        return cov
    factor, inflation = misfit_factor(fit)
    return cov * max(factor / inflation, 1.0)


@dataclass(frozen=True)
class LinesOfSight:
    """How the cameras' lines of sight to the target spread: `span_deg` the largest angle between two of them,
    `baseline_m` how far the cameras moved across them (the spread of their centres perpendicular to the mean line
    of sight), `n` the rays."""

    n: int
    span_deg: float
    baseline_m: float

    @property
    def narrow(self) -> bool:
        return self.n < 2 or self.span_deg < NARROW_SPAN_DEG


def lines_of_sight(obs: Observations) -> LinesOfSight:
    """The spread of the lines of sight through the target pixels (`LinesOfSight`)."""
    pix = obs.has_pixel
    if pix.sum() < 2:
        return LinesOfSight(int(pix.sum()), 0.0, 0.0)
    return lines_of_sight_from_rays(*camera_rays_m(obs.P[pix], obs.pixel[pix]))


def lines_of_sight_from_rays(C: np.ndarray, a: np.ndarray) -> LinesOfSight:
    """The spread (`LinesOfSight`) of rays from centres C (n, 3) m along unit directions a (n, 3); of at most 256
    of them, evenly spaced (the pairwise comparison grows with the square of their number)."""
    n = len(C)
    if n < 2:
        return LinesOfSight(n, 0.0, 0.0)
    if n > 256:
        keep = np.unique(np.linspace(0, n - 1, 256).round().astype(int))
        C, a = C[keep], a[keep]
    mean = a.mean(axis=0)
    mean /= np.linalg.norm(mean)
    cos = np.clip(a @ a.T, -1.0, 1.0)
    span = math.degrees(math.acos(float(cos.min())))
    across = (C - C.mean(axis=0)) - np.outer((C - C.mean(axis=0)) @ mean, mean)
    d = np.linalg.norm(across[:, None, :] - across[None, :, :], axis=-1)
    return LinesOfSight(n, span, float(d.max()))


def baseline_problem(los: LinesOfSight, has_range: bool, has_terrain: bool) -> str | None:
    """One line naming a missing baseline, when the lines of sight span too little to meet and nothing else (a
    laser range, a terrain model) fixes the distance along them; None otherwise."""
    if not los.narrow or has_range or has_terrain:
        return None
    if los.n < 2:
        return ("the target was seen in fewer than two frames and there is no laser range or terrain model: one "
                "line of sight fixes a direction, not a point; mark it in more frames, or add a laser range or a "
                "terrain model (a flight config's terrain:, locate's --dem), or assume level ground (locate's "
                "--ground takeoff, a weaker answer)")
    return (f"no baseline: the camera moved only {_fmt_m(los.baseline_m)} across its lines of sight, which span "
            f"{los.span_deg:.1f} deg, too little for them to meet, and no laser range or terrain model fixes the "
            "distance along them; fly around the target (lines of sight at least 10-20 deg apart), or add a laser "
            "range or a terrain model (a flight config's terrain:, locate's --dem)")


def unsolved_reasons(failures: dict | None) -> dict[str, str]:
    """method -> reason of the methods that gave no estimate, from a result's settings["solve_failures"] (a
    {"status", "reason"} mapping or a message per method)."""
    return {m: str(f.get("reason", "")) if isinstance(f, dict) else str(f) for m, f in (failures or {}).items()}


def choose_answer(obs: Observations, estimates: dict[str, Estimate], unsolved: dict[str, str], origin_lla, *,
                  sources: ErrorSources | None = None, options: dict | None = None, ground: Ground | None = None,
                  solvers: dict[str, Callable] | None = None,
                  added_covariance: dict[str, np.ndarray] | None = None,
                  whole_covariance: dict[str, np.ndarray] | None = None) -> Answer:
    """The target's answer (module docstring) from every method's estimate and the reasons of those that gave none
    (`unsolved`, method -> reason). `sources`: the errors to propagate through the methods without a covariance of
    their own (default: the observations' stated sigmas); `options`: method -> the flight's solve options;
    `ground`: the terrain under the answer (a DEM); `solvers`: method -> solver for `propagate` beyond the batched
    methods (e.g. `dem`), `added_covariance`: method -> a covariance added to the propagated one (e.g. the DEM's
    own error under `dem`); `whole_covariance`: method -> the part of its own covariance that moves its answer as a
    whole, in place of the shared offsets (`ground`: the assumed ground's error and the camera's position offset)."""
    sources = sources if sources is not None else ErrorSources.from_sigma(obs.sigma)
    options, solvers, added, whole = options or {}, solvers or {}, added_covariance or {}, whole_covariance or {}
    shared = np.asarray(sources.shared_covariance_m2, dtype=np.float64)
    verdicts: dict[str, Verdict] = {}
    for m in [*estimates, *unsolved]:
        if m in verdicts or m in NEVER_THE_ANSWER:
            continue
        e = estimates.get(m)
        cov, source, why, offsets = None, "", None, whole.get(m, shared)
        if e is not None and np.isfinite(e.position_m).all():
            if e.covariance_m2 is not None:  # the estimator's own (the mle's; a photo's ground method's)
                cov, source = (_widened_to_misfit(e) if m == "mle" else e.covariance_m2), "estimator"
            elif m in PROPAGATED or m in solvers:
                solver = solvers.get(m) or method_solver(m, options.get(m))
                with np.errstate(all="ignore"):
                    p = propagate(solver, obs, e.position_m, sources)
                cov, source, why = p.covariance_m2, "propagated", p.reason
                if cov is not None and m in added:
                    cov, offsets = cov + added[m], shared + added[m]
        verdicts[m] = judge(m, e, unsolved.get(m), obs, origin_lla, cov, source, ground, why, offsets)
    _ridge_needs_fusion(verdicts)
    n = int((obs.has_pixel | obs.has_range).sum())  # the frames or photos that see or range the target
    mle = verdicts.get("mle")
    fit_ok, misfit = mle_fit_passes(estimates["mle"]) if mle is not None and mle.determined else (False, None)
    if fit_ok:
        return _located("mle", estimates, verdicts, n, "weighted MLE: determined by the flight, its fit checks pass"
                        + _misfit_covered(estimates["mle"]))
    candidates = [m for m, v in verdicts.items() if v.determined and m != "mle"]
    if candidates:
        best = min(candidates, key=lambda m: verdicts[m].ce90_m)
        precise = f"the most precise method the flight determines (CE90 {verdicts[best].ce90_m:.1f} m)"
        why = misfit or (mle.reason if mle is not None else "not run")
        return _located(best, estimates, verdicts, n, f"{best}: {precise}; the MLE is not taken: {why}")
    headline = baseline_problem(lines_of_sight(obs), bool(obs.has_range.any()), "dem" in estimates or ground
                                is not None)
    if headline is None:
        why = f" (mle: {misfit or mle.reason})" if mle is not None else ""
        headline = f"no method's estimate is determined by this flight{why}; estimates.csv says why for each"
    return Answer(False, None, None, None, headline, n, verdicts)


def _ridge_needs_fusion(verdicts: dict[str, Verdict]) -> None:
    """`ridge` undetermined (in place) where the flight does not determine `fusion`'s geometry: the same
    observations and model without the ridge penalty, whose narrower ellipse is bias towards the iteration's start,
    not measurement."""
    ridge, fusion = verdicts.get("ridge"), verdicts.get("fusion")
    if ridge is None or fusion is None or not ridge.determined or fusion.determined:
        return
    if not (fusion.reason or "").startswith("the flight does not determine it"):
        return  # fusion's own point failed (behind a camera, underground): not the geometry
    why = fusion.reason.split(": ", 1)[-1]
    verdicts["ridge"] = Verdict("ridge", False, f"the flight does not determine it: it is fusion with a penalty, and "
                                f"fusion is not determined ({why}); the penalty narrows its ellipse by pulling the "
                                "point towards where its iteration started, not by measuring it",
                                ridge.covariance_m2, ridge.covariance_source, ridge.ce90_m, ridge.relative_uncertainty)


def _located(method: str, estimates: dict[str, Estimate], verdicts: dict[str, Verdict], n: int,
             reason: str) -> Answer:
    v = verdicts[method]
    return Answer(True, method, np.asarray(estimates[method].position_m, dtype=np.float64), v.covariance_m2, reason,
                  n, verdicts)
