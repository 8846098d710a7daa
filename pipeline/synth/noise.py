"""Random processes for telemetry errors, all drawn from seeded numpy Generators."""

from __future__ import annotations

import math

import numpy as np
from scipy.signal import lfilter


def gauss_markov(rng: np.random.Generator, n: int, dims: int, sigma: float, tau_s: float, dt_s: float) -> np.ndarray:
    """(n, dims) first-order Gauss-Markov process, stationary std `sigma`, time constant `tau_s`, step `dt_s`
    (x[k+1] = a x[k] + sqrt(1 - a^2) sigma w, a = exp(-dt/tau); started from its stationary distribution)."""
    a = math.exp(-dt_s / tau_s)
    w = rng.standard_normal((n, dims))
    w[1:] *= math.sqrt(1.0 - a * a)
    return sigma * lfilter([1.0], [1.0, -a], w, axis=0)


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
