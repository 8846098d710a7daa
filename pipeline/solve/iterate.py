"""The batched iteration driver (`drive`) shared by the Gauss-Newton style estimators: finished problems are
frozen, each iteration computes only the still active ones (docs/solvers.md, "Stopping, divergence, degeneracy").
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from pipeline.solve.estimate import Status
from pipeline.solve.stacked import Stacked, condition_numbers, inverse3

#: an estimate further than this many times the problem's size from the platforms has diverged
DIVERGENCE_FACTOR = 1e3

StepFn = Callable[[Stacked, np.ndarray], tuple[np.ndarray, np.ndarray, dict]]


def divergence_bound(st: Stacked, X0: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(centre (B,3), bound (B,)): the platforms' mean and DIVERGENCE_FACTOR times the largest platform-to-start
    distance (>= 1 m; from the centre where the start is not finite)."""
    centre = st.platform_m.mean(axis=1)
    X0 = np.where(np.isfinite(X0).all(axis=1)[:, None], X0, centre)
    d = np.linalg.norm(X0[:, None, :] - st.platform_m, axis=-1).max(axis=1)
    return centre, DIVERGENCE_FACTOR * np.where(np.isfinite(d), np.maximum(d, 1.0), 1.0)


def start_status(X0: np.ndarray, init_status: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
    """(status (B,) int8 all MAX_ITERATIONS but where the start is unusable, bad (B,) bool): a start that is not
    finite, or that comes from a DIVERGED / DEGENERATE initial solve, keeps that status (DEGENERATE if none)."""
    diverged = np.zeros(X0.shape[0], dtype=bool) if init_status is None else init_status == Status.DIVERGED
    bad = ~np.isfinite(X0).all(axis=1) | diverged | (init_status is not None and init_status == Status.DEGENERATE)
    status = np.full(X0.shape[0], Status.MAX_ITERATIONS, dtype=np.int8)
    status[bad] = np.where(diverged[bad], Status.DIVERGED, Status.DEGENERATE)
    return status, bad


class Model:
    """What `drive` iterates (and, for `mle`, what `mle.finish` finishes); the defaults are a plain
    Gauss-Newton model. step(idx, X_idx, lam_idx) -> (dX (k,3), singular (k,)): the step of the active problems
    idx (lam: the damping, None unless damped); trial(idx, Xn) -> (k,) bool: evaluate the problems at Xn, where
    the cost did not rise; accept(idx, accepted) -> (k,) bool: keep the trial's state where accepted, and which
    rejected steps to retry undamped; converged(idx) -> (k,) bool: the problems to iterate again (variance
    components changed); settle() once the iteration ends. For `mle.finish`: extra_dof, adjust (the bias
    averaging), bias_extras."""

    damped = False
    drift_modelled = False
    #: the rows' weights do not depend on the loss (`mle.run` skips a phase that would change nothing)
    fixed_weights = False
    #: a step within tol_m ends the problem where it is, untried (the model's state was evaluated there)
    skips_last_step = False

    def trial(self, idx, Xn):
        return np.ones(idx.size, dtype=bool)

    def accept(self, idx, accepted):
        return np.zeros(idx.size, dtype=bool)

    def converged(self, idx):
        return np.zeros(idx.size, dtype=bool)

    def negligible(self, idx, dX):  # (k,) bool: steps dX (k,3) that end their problems (besides tol_m)
        return np.zeros(idx.size, dtype=bool)

    def settle(self):  # after the iteration: the state of the problems complete
        pass

    def extra_dof(self):
        return 0

    def adjust(self, cov, cov0, infl, vf_chi, failed, drift_pix):
        return cov, cov0, self.E, np.zeros(cov.shape[0], dtype=bool)

    def bias_extras(self, cov, vf_chi):
        return {}


def drive(model, X: np.ndarray, status: np.ndarray, active: np.ndarray, iterations: np.ndarray, bound: np.ndarray,
          centre: np.ndarray, tol_m: float, max_iterations: int, damped: bool = False) -> None:
    """THE iteration of every estimator that iterates (in place on X (B,3), status, active, iterations (B,)), on
    a `Model`. A step stops a problem as CONVERGED (||dX|| <= tol_m, or damping that cannot help any more),
    DEGENERATE (singular), DIVERGED (non-finite, or further than `bound` from `centre`), else MAX_ITERATIONS
    after max_iterations; with `damped`, Levenberg-Marquardt (a rejected step raises the damping)."""
    lam = np.zeros(X.shape[0])
    for _ in range(max_iterations):
        idx = np.flatnonzero(active)
        if idx.size == 0:
            break
        dX, singular = model.step(idx, X[idx], lam[idx] if damped else None)
        iterations[idx] += 1
        Xi = X[idx]
        Xn = Xi + np.where(singular[:, None], 0.0, dX)
        finite = np.isfinite(Xn).all(axis=1)
        exploded = ~finite | (np.sqrt(((Xn - centre[idx]) ** 2).sum(axis=1)) > bound[idx])
        step_norm = np.where(singular, np.inf, np.sqrt((dX * dX).sum(axis=1)))
        # a step the model calls negligible (an undamped one ending a start phase) ends the problem moved, untried
        # (the next phase evaluates there); a step within tol_m where the model `skips_last_step`, unmoved. Every
        # other step is tried: what a model reports (residuals, weights, covariance) belongs to the X it returns
        small = (step_norm <= tol_m) & ~singular & ~exploded
        done = ~singular & ~exploded & model.negligible(idx, dX) & (lam[idx] == 0)
        if done.any():
            X[idx[done]] = Xn[done]
        if model.skips_last_step:
            done |= small
        any_done = done.any()
        t = np.flatnonzero(~done) if any_done else slice(None)  # the others: evaluated at their trial point
        it = idx[t]
        accept = np.zeros(idx.size, dtype=bool)
        retry = np.zeros(idx.size, dtype=bool)
        if it.size:
            Xt, expl_t = Xi[t], exploded[t]
            acc_t = ~singular[t] & ~expl_t & model.trial(it, np.where(expl_t[:, None], Xt, Xn[t]))
            X[it] = np.where((acc_t | (expl_t & finite[t]))[:, None], Xn[t], Xt)
            accept[t], retry[t] = acc_t, model.accept(it, acc_t)
        if damped:
            lam[idx[accept]] = np.where(lam[idx[accept]] / 10 < 1e-9, 0.0, lam[idx[accept]] / 10)
            rej = idx[~accept & ~retry]
            lam[rej] = np.where(lam[rej] == 0, 1e-4, lam[rej] * 10)
        done |= small
        still = ~singular & ~exploded & ~done
        stuck = still & ~accept & (lam[idx] > 1e12)  # damping that cannot help: the minimum is reached
        done |= stuck
        still &= ~stuck
        if done.any():
            again = np.zeros(idx.size, dtype=bool)
            again[done] = model.converged(idx[done])
            lam[idx[again]] = 0.0
            done &= ~again
            still |= again
        s = status[idx]
        s[singular] = Status.DEGENERATE
        s[exploded & ~singular] = Status.DIVERGED
        s[done] = Status.CONVERGED
        status[idx] = s
        active[idx] = still
    model.settle()


class _StepModel(Model):
    """`drive`'s model for a plain Gauss-Newton step function: every step accepted, no damping."""

    def __init__(self, st: Stacked, step: StepFn, extras: dict, X: np.ndarray):
        self.st, self.fn, self.extras, self.X = st, step, extras, X

    def step(self, idx, X, lam):
        if 2 * idx.size >= self.st.size:  # copying most of the batch costs more than computing all again
            dX, singular, ex = self.fn(self.st, self.X)
            if idx.size < self.st.size:
                dX, singular, ex = dX[idx], singular[idx], {k: v[idx] for k, v in ex.items()}
        else:
            dX, singular, ex = self.fn(self.st.take(idx), X)
        for name, v in ex.items():
            self.extras[name][idx] = v
        return dX, singular


def iterate(st: Stacked, X0: np.ndarray, step: StepFn, tol_m: float, max_iterations: int,
            init_status: np.ndarray | None = None, extra_names: tuple[str, ...] = ()):
    """`drive` with `step(sub, X_sub) -> (dX (b,3), singular (b,) bool, extras {name: (b,)})`.

    Returns X (B,3) (the last finite iterate; callers blank DIVERGED and DEGENERATE ones with `finish`),
    iterations (B,), status (B,) int8 and the extras of each problem's last iteration (B,) arrays.
    """
    B = st.size
    X = np.array(X0, dtype=np.float64, copy=True)
    iterations = np.zeros(B, dtype=np.int64)
    status, bad_init = start_status(X, init_status)
    centre, bound = divergence_bound(st, X)
    extras = {name: np.full(B, np.nan) for name in extra_names}
    drive(_StepModel(st, step, extras, X), X, status, ~bad_init, iterations, bound, centre, tol_m, max_iterations)
    return X, iterations, status, extras


def finish(X: np.ndarray, status: np.ndarray, N: np.ndarray, N_geometry: np.ndarray | None = None) -> np.ndarray:
    """In place: problems whose final normal matrix N = A^T A (B,k,k) is singular (`inverse3`'s flag: the geometry
    does not determine the target) become DEGENERATE; DIVERGED and DEGENERATE positions become NaN. Returns
    the (B,) condition numbers of the design matrices A. N_geometry: the block judged for singularity, when
    not all of N."""
    cond = condition_numbers(N)
    finite = np.isfinite(X).all(axis=1)
    status[inverse3(N if N_geometry is None else N_geometry)[1] & finite] = Status.DEGENERATE
    cond[~finite] = np.nan
    X[(status == Status.DIVERGED) | (status == Status.DEGENERATE)] = np.nan
    return cond
