"""The batched iteration driver shared by the Gauss-Newton style estimators.

Every problem iterates X <- X + dX until ||dX|| <= tol_m (CONVERGED), max_iterations (MAX_ITERATIONS), a
singular normal matrix (DEGENERATE) or a non-finite / exploding estimate (DIVERGED). Converged problems are
frozen: each iteration only computes the still active ones.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from pipeline.solve.estimate import Status
from pipeline.solve.stacked import Stacked, condition_numbers, is_singular

#: an estimate further than this many times the problem's size from the platforms has diverged
DIVERGENCE_FACTOR = 1e3

StepFn = Callable[[Stacked, np.ndarray], tuple[np.ndarray, np.ndarray, dict]]


def problem_scale_m(st: Stacked, X0: np.ndarray) -> np.ndarray:
    """(B,) a length scale: the largest platform-to-initial-estimate distance (>= 1 m)."""
    d = np.linalg.norm(X0[:, None, :] - st.platform_m, axis=-1).max(axis=1)
    return np.where(np.isfinite(d), np.maximum(d, 1.0), 1.0)


def start_status(X0: np.ndarray, init_status: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
    """(status (B,) int8 all MAX_ITERATIONS but where the start is unusable, bad (B,) bool): a start that is not
    finite, or that comes from a DIVERGED / DEGENERATE initial solve, keeps that status (DEGENERATE if none)."""
    finite0 = np.isfinite(X0).all(axis=1)
    status = np.full(X0.shape[0], Status.MAX_ITERATIONS, dtype=np.int8)
    if init_status is not None:
        bad = (init_status == Status.DIVERGED) | (init_status == Status.DEGENERATE) | ~finite0
        status[bad] = np.where(init_status[bad] == Status.DIVERGED, Status.DIVERGED, Status.DEGENERATE)
    else:
        bad = ~finite0
        status[bad] = Status.DEGENERATE
    return status, bad


def iterate(st: Stacked, X0: np.ndarray, step: StepFn, tol_m: float, max_iterations: int,
            init_status: np.ndarray | None = None, extra_names: tuple[str, ...] = ()):
    """Run `step(sub, X_sub) -> (dX (b,3), singular (b,) bool, extras {name: (b,)})` to convergence.

    Returns X (B,3) (the last finite iterate; callers blank DIVERGED and DEGENERATE ones with `finish`),
    iterations (B,), status (B,) int8 and the extras of each problem's last iteration (B,) arrays.
    """
    B = st.size
    X = np.array(X0, dtype=np.float64, copy=True)
    iterations = np.zeros(B, dtype=np.int64)
    status, bad_init = start_status(X, init_status)
    active = ~bad_init
    centre = st.platform_m.mean(axis=1)
    finite0 = np.isfinite(X).all(axis=1)
    bound = DIVERGENCE_FACTOR * problem_scale_m(st, np.where(finite0[:, None], X, centre))
    extras = {name: np.full(B, np.nan) for name in extra_names}
    for _ in range(max_iterations):
        idx = np.flatnonzero(active)
        if idx.size == 0:
            break
        if 2 * idx.size >= B:  # copying most of the batch costs more than computing the finished ones again
            dX, singular, ex = step(st, X)
            if idx.size < B:
                dX, singular, ex = dX[idx], singular[idx], {k: v[idx] for k, v in ex.items()}
        else:
            dX, singular, ex = step(st.take(idx), X[idx])
        for name, v in ex.items():
            extras[name][idx] = v
        iterations[idx] += 1
        Xn = X[idx] + dX
        step_norm = np.linalg.norm(dX, axis=1)
        finite = np.isfinite(Xn).all(axis=1)
        exploded = ~finite | (np.linalg.norm(Xn - centre[idx], axis=1) > bound[idx])
        X[idx] = np.where(finite[:, None], Xn, X[idx])
        done_conv = ~singular & ~exploded & (step_norm <= tol_m)
        st_idx = status[idx]
        st_idx[singular] = Status.DEGENERATE
        st_idx[~singular & exploded] = Status.DIVERGED
        st_idx[done_conv] = Status.CONVERGED
        status[idx] = st_idx
        active[idx] = ~(singular | exploded | done_conv)
    return X, iterations, status, extras


def finish(X: np.ndarray, status: np.ndarray, N: np.ndarray, N_geometry: np.ndarray | None = None) -> np.ndarray:
    """In place: problems whose final normal matrix N = A^T A (B,k,k) is singular (`is_singular`: the geometry
    does not determine the target) become DEGENERATE; DIVERGED and DEGENERATE positions become NaN. Returns
    the (B,) condition numbers of the design matrices A. N_geometry: the block judged for singularity, when
    not all of N."""
    cond = condition_numbers(N)
    finite = np.isfinite(X).all(axis=1)
    status[is_singular(N if N_geometry is None else N_geometry) & finite] = Status.DEGENERATE
    cond[~finite] = np.nan
    X[(status == Status.DIVERGED) | (status == Status.DEGENERATE)] = np.nan
    return cond
