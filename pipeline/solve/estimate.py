"""The result type every estimator returns, single-problem (`Estimate`) and batched (`BatchEstimate`)."""

from __future__ import annotations

from dataclasses import dataclass, field
from enum import IntEnum

import numpy as np


class Status(IntEnum):
    """Why an estimator stopped. Stored as int8 in batches."""

    CONVERGED = 0  # ||dX|| fell below the threshold
    MAX_ITERATIONS = 1  # the iteration limit was reached first (slow convergence or oscillation)
    DIVERGED = 2  # the step or the estimate grew without bound / became non-finite
    DEGENERATE = 3  # the geometry does not determine the target (rank-deficient design matrix)
    CLOSED_FORM = 4  # a non-iterative method (dlt, los) that produced an answer


@dataclass
class Estimate:
    """One estimator's answer to one problem.

    Attributes:
        method: estimator name as in `ridgeloc solve` (dlt vision range los fusion-raw fusion ridge mle).
        position_m: (3,) target position in the observations' world frame, metres.
        iterations: iterations taken (0 for closed-form methods).
        status: why it stopped; `converged` is derived from it.
        residuals: (m,) final residuals of the observations the method used (px for pixels, m for ranges).
        condition_number: 2-norm condition number of the final design matrix (NaN when not defined).
        covariance_m2: (3, 3) covariance of position_m in m^2, where the method defines one, else None.
        extras: method-specific results (los per-frame points, mle CEP and ellipsoid, ridge k, ...),
            JSON-serialisable.
    """

    method: str
    position_m: np.ndarray
    iterations: int
    status: Status
    residuals: np.ndarray = field(default_factory=lambda: np.zeros(0))
    condition_number: float = float("nan")
    covariance_m2: np.ndarray | None = None
    extras: dict = field(default_factory=dict)

    @property
    def converged(self) -> bool:
        return self.status in (Status.CONVERGED, Status.CLOSED_FORM)

    def error_m(self, truth_m: np.ndarray | None) -> float | None:
        if truth_m is None or not np.isfinite(self.position_m).all():
            return None
        return float(np.linalg.norm(self.position_m - truth_m))

    def to_dict(self, truth_m: np.ndarray | None = None) -> dict:
        d = {
            "position_m": [float(v) for v in self.position_m],
            "iterations": int(self.iterations),
            "converged": bool(self.converged),
            "status": self.status.name.lower(),
            "condition_number": finite_or_none(self.condition_number),
            "rms_residual": finite_or_none(float(np.sqrt(np.mean(self.residuals ** 2)))
                                            if self.residuals.size else float("nan")),
        }
        err = self.error_m(truth_m)
        if err is not None:
            d["error_m"] = err
        if self.covariance_m2 is not None:
            d["covariance_m2"] = self.covariance_m2.tolist()
        d.update(self.extras)
        return d


@dataclass
class BatchEstimate:
    """One estimator's answers to B problems: position_m (B, 3), iterations (B,) int, status (B,) int8,
    condition_number (B,) float, and optionally covariance_m2 (B, 3, 3) and extras of (B, ...) arrays."""

    method: str
    position_m: np.ndarray
    iterations: np.ndarray
    status: np.ndarray
    condition_number: np.ndarray
    covariance_m2: np.ndarray | None = None
    extras: dict = field(default_factory=dict)

    @property
    def converged(self) -> np.ndarray:
        return (self.status == Status.CONVERGED) | (self.status == Status.CLOSED_FORM)

    def errors_m(self, truth_m: np.ndarray) -> np.ndarray:
        """(B,) 3D error against (B, 3) truths; NaN where the estimate is not finite."""
        return np.linalg.norm(self.position_m - truth_m, axis=1)


def finite_or_none(x: float) -> float | None:
    return float(x) if np.isfinite(x) else None
