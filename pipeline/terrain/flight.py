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
