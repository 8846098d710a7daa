"""Per-angle statistics of one estimator's batched answers against the truth.

Which trials count: a trial whose status is DEGENERATE (the estimator says the geometry does not determine the
target) or DIVERGED, or whose position is not finite, has no error to average; it is counted in
`nonconverged_pct` (and DEGENERATE also in `degenerate_pct`) and left out of `median_m` and `rms_m`. Trials that
stopped at the iteration limit (MAX_ITERATIONS) still gave an answer: they count in `nonconverged_pct` AND their
errors are in `median_m` / `rms_m`, because that is the answer a user would get.
"""

from __future__ import annotations

import numpy as np

from pipeline.solve.estimate import BatchEstimate, Status

# statistic name -> what it means (the CSV's `statistic` column; the first four are the issue's)
STATISTICS = {
    "median_m": "median 3D error over the answered trials, m",
    "rms_m": "root mean square 3D error over the answered trials, m",
    "nonconverged_pct": "share of trials not CONVERGED / CLOSED_FORM (iteration limit, diverged, degenerate), %",
    "median_iterations": "median iteration count over all trials",
    "degenerate_pct": "share of trials flagged DEGENERATE (geometry does not determine the target), %",
    "failed_pct": "share of trials without an answer (degenerate, diverged or non-finite), %",
    "p90_m": "90th percentile of the 3D error over the answered trials, m",
    "median_condition": "median 2-norm condition number of the final design matrix",
}


def error_statistics(errors_m: np.ndarray) -> dict[str, float]:
    """median, RMS and 90th percentile of (B,) errors, NaN entries excluded (all NaN -> NaN)."""
    e = errors_m[np.isfinite(errors_m)]
    if e.size == 0:
        return {"median_m": float("nan"), "rms_m": float("nan"), "p90_m": float("nan")}
    return {"median_m": float(np.median(e)), "rms_m": float(np.sqrt(np.mean(e ** 2))),
            "p90_m": float(np.percentile(e, 90))}


def answered_mask(est: BatchEstimate) -> np.ndarray:
    """(B,) bool: trials with a usable answer (not DEGENERATE, not DIVERGED, finite position)."""
    status = np.asarray(est.status)
    return ((status != Status.DEGENERATE) & (status != Status.DIVERGED)
            & np.isfinite(est.position_m).all(axis=1))


def summarize(est: BatchEstimate, truth_m: np.ndarray) -> dict[str, float]:
    """All STATISTICS of one estimator at one angle; truth_m (B, 3)."""
    status = np.asarray(est.status)
    B = status.shape[0]
    ok = answered_mask(est)
    errors = np.where(ok, est.errors_m(truth_m), np.nan)
    stats = error_statistics(errors)
    converged = (status == Status.CONVERGED) | (status == Status.CLOSED_FORM)
    cond = np.asarray(est.condition_number, dtype=np.float64)
    cond = cond[np.isfinite(cond)]
    stats.update({
        "nonconverged_pct": 100.0 * float(np.count_nonzero(~converged)) / B,
        "median_iterations": float(np.median(est.iterations)),
        "degenerate_pct": 100.0 * float(np.count_nonzero(status == Status.DEGENERATE)) / B,
        "failed_pct": 100.0 * float(np.count_nonzero(~ok)) / B,
        "median_condition": float(np.median(cond)) if cond.size else float("nan"),
    })
    return {k: stats[k] for k in STATISTICS}
