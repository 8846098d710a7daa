"""Estimators of the target position from synchronized observations (paper sections 2.1-2.4, plus MLE).

    solve(method, obs, **options) -> Estimate              one problem; raises a clear error when it cannot
    solve_batch(method, batch, **options) -> BatchEstimate  B problems at once; failures are statuses

Methods and their options: docs/solvers.md and `pipeline.solve_options.OPTIONS`. Each method has one vectorised
kernel (linear.py, least_squares.py, mle.py, correlated.py); `solve` runs it on a batch of one (methods.py).
"""

from pipeline.solve.estimate import BatchEstimate, Estimate, Status
from pipeline.solve.methods import METHODS, solve, solve_batch, unsolved_status

__all__ = ["METHODS", "BatchEstimate", "Estimate", "Status", "solve", "solve_batch", "unsolved_status"]
