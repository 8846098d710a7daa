"""Estimators of the target position from synchronized observations (paper sections 2.1-2.4, plus MLE).

    solve(method, obs, **options) -> Estimate              one problem; raises a clear error when it cannot
    solve_batch(method, batch, **options) -> BatchEstimate  B problems at once; failures are statuses

Methods (docs/solvers.md): dlt, vision, range, los, fusion-raw, fusion, ridge, mle. Each has one
implementation, a vectorised kernel (linear.py, least_squares.py, mle.py; correlated.py for the mle with
time-correlated errors, one problem at a time); `solve` runs it on a batch of one (methods.py).

Options: tol_m (1e-4, the paper's threshold on ||dX||), max_iterations (50), initial_m ((3,) or (B,3));
ridge: hkb ("paper" | "textbook"), k (a fixed ridge parameter; k=0 is `fusion`); mle: robust ("huber" |
"cauchy" | None), sigma (a `Sigma` or dict overriding the observations' sigmas), estimate_variance_components
(default: on when the pixel or range sigma is unknown).
"""

from pipeline.solve.estimate import BatchEstimate, Estimate, Status
from pipeline.solve.methods import METHODS, solve, solve_batch, unsolved_status

__all__ = ["METHODS", "BatchEstimate", "Estimate", "Status", "solve", "solve_batch", "unsolved_status"]
