"""Run the simulation experiment: for each intersection angle, draw all trials at once, solve them with every
configured estimator in one batched call each, and reduce the answers to per-angle statistics."""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from pipeline.errors import SolverError
from pipeline.simulate.config import SimulationConfig
from pipeline.simulate.scenario import generate, observation_angle_deg
from pipeline.simulate.statistics import STATISTICS, error_statistics, summarize
from pipeline.solve.estimate import BatchEstimate

LOS_ORACLE = "los-oracle"


@dataclass
class SimulationResult:
    """Statistics of every estimator at every angle.

    rows: row name -> statistic name -> (len(angles_deg),) list of floats (NaN where undefined). Row names are
        the methods, plus "los-oracle" (the best single frame of `los`, chosen knowing the truth) when los runs.
    method_seconds: method -> wall seconds spent in its batched solves, summed over the angles.
    """

    config: SimulationConfig
    angles_deg: tuple[float, ...]
    rows: dict[str, dict[str, list[float]]]
    measured_angles_deg: list[float]
    method_seconds: dict[str, float]
    generation_seconds: float
    wall_seconds: float = float("nan")
    notes: list[str] = field(default_factory=list)

    @property
    def observation_angle_deg(self) -> float:
        return observation_angle_deg(self.config.geometry)

    def value(self, row: str, statistic: str, angle_deg: float) -> float:
        return self.rows[row][statistic][self.angles_deg.index(angle_deg)]

    def solves(self) -> int:
        """Problems solved per method."""
        return self.config.trials * len(self.angles_deg)


def solver_options(cfg: SimulationConfig, method: str) -> dict:
    """The keyword options one estimator receives from the config (the closed-form dlt and los take none)."""
    if method in ("dlt", "los"):
        return {}
    s = cfg.solver
    opts: dict = {"tol_m": s.tol_m, "max_iterations": s.max_iterations}
    if method == "ridge":
        opts["hkb"] = s.ridge_hkb
    if method == "mle":
        opts["robust"] = None if s.mle_robust == "none" else s.mle_robust
        # the simulated errors are independent from frame to frame, and the MLE is told so: no boresight bias
        opts["bias_prior_deg"] = 0.0
    return opts


def los_oracle_errors_m(est: BatchEstimate, truth_m: np.ndarray) -> np.ndarray | None:
    """(B,) error of the best single frame of the line-of-sight method (the paper's Table 4 protocol: "we select
    the positioning result with the smallest localization error"), or None if los gives no per-frame points."""
    points = est.extras.get("points_m")
    if points is None:
        return None
    points = np.asarray(points, dtype=np.float64)  # (B, n, 3), NaN where a frame gave no point
    err = np.linalg.norm(points - truth_m[:, None, :], axis=-1)
    err = np.where(np.isfinite(err), err, np.inf)
    best = err.min(axis=1)
    return np.where(np.isfinite(best), best, np.nan)


def run_simulation(cfg: SimulationConfig, progress: Callable[[str], None] | None = None) -> SimulationResult:
    """The whole experiment of `cfg`; `progress` receives one line per angle."""
    try:
        from pipeline.solve import solve_batch
    except ImportError:
        raise SolverError("this installation has no batched estimators (pipeline.solve.solve_batch)") from None

    t_start = time.perf_counter()
    rows: dict[str, dict[str, list[float]]] = {}
    seconds = dict.fromkeys(cfg.methods, 0.0)
    measured = []
    t_generation = 0.0

    def put(row: str, i: int, stats: dict[str, float]) -> None:
        table = rows.setdefault(row, {k: [float("nan")] * len(cfg.angles_deg) for k in STATISTICS})
        for k, v in stats.items():
            table[k][i] = v

    for i, angle in enumerate(cfg.angles_deg):
        t0 = time.perf_counter()
        trials = generate(cfg, angle)
        t_generation += time.perf_counter() - t0
        measured.append(trials.intersection_angle_deg)
        truth = trials.batch.truth_m
        for method in cfg.methods:
            t0 = time.perf_counter()
            est = solve_batch(method, trials.batch, **solver_options(cfg, method))
            seconds[method] += time.perf_counter() - t0
            put(method, i, summarize(est, truth))
            if method == "los":
                oracle = los_oracle_errors_m(est, truth)
                if oracle is not None:
                    stats = dict.fromkeys(STATISTICS, float("nan"))
                    stats.update(error_statistics(oracle))
                    stats["failed_pct"] = 100.0 * float(np.count_nonzero(~np.isfinite(oracle))) / oracle.size
                    put(LOS_ORACLE, i, stats)
        if progress is not None:
            parts = ", ".join(f"{m} {rows[m]['median_m'][i]:.1f}" for m in cfg.methods)
            progress(f"{angle:g} deg: median error (m) {parts}")
    return SimulationResult(config=cfg, angles_deg=tuple(cfg.angles_deg), rows=rows, measured_angles_deg=measured,
                            method_seconds=seconds, generation_seconds=t_generation,
                            wall_seconds=time.perf_counter() - t_start)
