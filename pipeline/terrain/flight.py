"""A flight's `terrain:` section in `ridgeloc run` (video and log flights): the `dem` method beside the other
estimators, and the MLE's terrain prior where the MLE takes one. pipeline/run.py calls these three around its
`solve_all`; without `terrain:` they do nothing.
"""

from __future__ import annotations

import numpy as np

from pipeline.errors import RidgelocError
from pipeline.solve.estimate import Estimate
from pipeline.solve.observations import Observations
from pipeline.terrain.dem import Dem


def open_flight_dem(terrain) -> Dem | None:
    """The DEM of a flight config's `terrain` section (pipeline.flight_config.Terrain), or None without one.
    An unusable DEM is an InputError naming it: the flight fails, as with any bad input file."""
    if terrain is None:
        return None
    return Dem.open(terrain.dem, vertical_datum=terrain.vertical_datum)


def terrain_prior(dem: Dem | None, vertical_sigma_m: float | None, origin_lla):
    """The MLE's terrain prior `(fn, vertical_sigma_m)`, fn the DEM in the ENU frame at the origin (Dem.local), or
    None: no DEM, or no stated vertical sigma (then the DEM serves the `dem` method only; docs/terrain.md)."""
    if dem is None or vertical_sigma_m is None:
        return None
    return dem.local(*origin_lla), float(vertical_sigma_m)


def terrain_solve_options(dem: Dem | None, terrain, origin_lla, options: dict) -> dict:
    """`options` (method -> options) with the MLE's `terrain_prior` added where there is one."""
    prior = terrain_prior(dem, None if terrain is None else terrain.vertical_sigma_m, origin_lla)
    if prior is None:
        return options
    mle = dict(options.get("mle") or {})
    mle.setdefault("terrain", prior)
    return {**options, "mle": mle}


def add_dem_estimate(dem: Dem | None, obs: Observations, origin_lla, estimates: dict[str, Estimate],
                     failures: dict[str, dict], labels: list[str]) -> None:
    """Adds the `dem` estimate (pipeline.terrain.locate_dem) to `estimates`, or its status and one-line reason
    to `failures` (as `solve_all` reports a method that could not run). Nothing without a DEM."""
    if dem is None:
        return
    from pipeline.solve.methods import unsolved_status
    from pipeline.terrain.locate import locate_dem

    try:
        with np.errstate(invalid="ignore"):
            estimates["dem"] = locate_dem(obs, dem, origin_lla, labels=labels)
    except RidgelocError as exc:
        failures["dem"] = {"status": unsolved_status(exc), "reason": str(exc)}


#: the DEM's vertical error (m, 1 sigma) taken for the `dem` method's uncertainty where the flight states none:
#: SRTM's specified 16 m LE90 (docs/terrain.md, "The DEM vertical sigma to state")
DEFAULT_VERTICAL_SIGMA_M = 10.0


def dem_answer_inputs(dem: Dem | None, vertical_sigma_m: float | None, obs: Observations, origin_lla,
                      dem_estimate: Estimate | None) -> dict:
    """The keyword arguments of `pipeline.answer.choose_answer` a DEM gives: the ground under the answer, the
    `dem` method's solver for the propagation (each perturbed copy of the views cast into the DEM at once), and the
    DEM's own vertical error under the `dem` answer (sigma^2 g g^T, g the median line of sight scaled to a unit
    vertical step: a DEM too high by d moves the hit back along the ray by d / sin(depression)). {} without a DEM."""
    if dem is None:
        return {}
    from pipeline.answer import Ground
    from pipeline.geometry.rays import camera_rays_m
    from pipeline.terrain.locate import dem_points

    sigma = float(vertical_sigma_m) if vertical_sigma_m else DEFAULT_VERTICAL_SIGMA_M
    local = dem.local(*origin_lla)
    ground = Ground(lambda e, n: local(e, n)[0], sigma, f"the DEM ({dem.path})")

    def solver(batch, position_m):
        B, n = batch.size, batch.n
        flat = Observations(P=batch.P.reshape(B * n, 3, 4), pixel=batch.pixel.reshape(B * n, 2),
                            platform_m=batch.platform_m.reshape(B * n, 3), range_m=np.full(B * n, np.nan))
        with np.errstate(invalid="ignore"):
            pts, _ = dem_points(flat, dem, origin_lla)
            pts = pts.reshape(B, n, 3)
            X = np.full((B, 3), np.nan)
            some = np.isfinite(pts).all(axis=2).any(axis=1)
            X[some] = np.nanmedian(pts[some], axis=1)
        return X

    out = {"ground": ground, "solvers": {"dem": solver}}
    if dem_estimate is not None and obs.has_pixel.any() and np.isfinite(dem_estimate.position_m).all():
        _, a = camera_rays_m(obs.P[obs.has_pixel], obs.pixel[obs.has_pixel])
        d = np.median(a, axis=0)
        if d[2] < 0:
            g = -d / abs(d[2])
            out["added_covariance"] = {"dem": sigma ** 2 * np.outer(g, g)}
    return out
