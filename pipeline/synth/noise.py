"""Random processes for telemetry errors, all drawn from seeded numpy Generators."""

from __future__ import annotations

import math

import numpy as np
from scipy.signal import lfilter


def gauss_markov_filter(w: np.ndarray, dt_s: float, tau_s: float, axis: int = 0) -> np.ndarray:
    """A first-order Gauss-Markov process from white draws w (any shape; time along `axis`, steps dt_s apart)
    with the draws' scale as its stationary std and time constant `tau_s`: the exact discretization
    x[0] = w[0], x[k] = a x[k-1] + sqrt(1 - a^2) w[k], a = exp(-dt/tau) (started from its stationary
    distribution)."""
    a = math.exp(-dt_s / tau_s)
    v = np.moveaxis(np.array(w, dtype=np.float64), axis, 0)
    v[1:] *= math.sqrt(1.0 - a * a)
    return np.moveaxis(lfilter([1.0], [1.0, -a], v, axis=0), 0, axis)


def gauss_markov(rng: np.random.Generator, n: int, dims: int, sigma: float, tau_s: float, dt_s: float) -> np.ndarray:
    """(n, dims) first-order Gauss-Markov process, stationary std `sigma`, time constant `tau_s`, step `dt_s`
    (`gauss_markov_filter` of standard normal draws)."""
    return sigma * gauss_markov_filter(rng.standard_normal((n, dims)), dt_s, tau_s)


def smooth_gauss_markov(rng: np.random.Generator, n: int, dims: int, sigma: float, tau_s: float, smooth_s: float,
                        dt_s: float) -> np.ndarray:
    """(n, dims) a Gauss-Markov process (time constant tau_s) low-passed once more (time constant smooth_s) and
    rescaled to stationary std `sigma`: a smooth signal, like a tracker's pointing error, that sensors sampled at
    25 Hz describe well."""
    x = gauss_markov(rng, n, dims, 1.0, tau_s, dt_s)
    b = math.exp(-dt_s / smooth_s)
    y = lfilter([1.0 - b], [1.0, -b], x, axis=0, zi=np.outer([b], x[0]))[0]
    # stationary variance of the cascade of two first-order filters, a = exp(-dt/tau)
    a = math.exp(-dt_s / tau_s)
    var = (1.0 - b) ** 2 * (1.0 + a * b) / ((1.0 - a * b) * (1.0 - b * b))
    return sigma * y / math.sqrt(var)


def sample_process(grid_s: np.ndarray, values: np.ndarray, t_s: np.ndarray) -> np.ndarray:
    """(n, dims) a process drawn on `grid_s` (m,) with values (m, dims), linearly interpolated at t_s (n,)."""
    return np.stack([np.interp(t_s, grid_s, values[:, i]) for i in range(values.shape[1])], axis=-1)
