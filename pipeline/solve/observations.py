"""The observation model every estimator consumes.

Frame i has a 3x4 projection matrix P_i (world -> pixel, world = a local Cartesian frame in metres, normally
ENU at a chosen origin), the target pixel (u_i, v_i) or NaN when the target was not seen, the platform
position s_i in metres (the laser's origin), and the laser range d_i in metres or NaN when there was none.

`Observations` is one problem; `ObservationBatch` is B problems of the same frame count n stacked on a
leading axis, for the batched solvers the simulation uses. Both are validated on construction.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

import numpy as np

from pipeline.errors import ObservationError

#: timestamps spanning less than this are frame numbers (0..n-1 when unknown), not times
REAL_TIMES_NS = 1_000_000


@dataclass(frozen=True)
class Sigma:
    """A priori standard deviations of the sensors (None = unknown, to be estimated from the data), and the
    correlation times of the attitude and platform position errors (first-order Gauss-Markov: correlation
    exp(-|t_i - t_j| / tau) between frames; None or 0 = independent from frame to frame)."""

    pixel_px: float | None = None
    range_m: float | None = None
    position_m: float | None = None
    attitude_deg: float | None = None
    attitude_tau_s: float | None = None
    position_tau_s: float | None = None

    @property
    def correlated(self) -> bool:
        """True when an attitude or position error with a sigma > 0 has a correlation time > 0."""
        return bool((self.attitude_tau_s and self.attitude_deg) or (self.position_tau_s and self.position_m))

    @classmethod
    def from_dict(cls, d: dict | None, source: str = "sigma") -> Sigma:
        if d is None:
            return cls()
        if not isinstance(d, dict):
            raise ObservationError(f"'{source}' must be an object, got {type(d).__name__}")
        names = {f.name for f in dataclasses.fields(cls)}
        unknown = sorted(set(d) - names)
        if unknown:
            raise ObservationError(f"unknown key(s) in '{source}': {', '.join(unknown)} (known: {sorted(names)})")
        values = {}
        for k, v in d.items():
            if v is None:
                continue
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not np.isfinite(v) or v < 0:
                raise ObservationError(f"'{source}.{k}' must be a finite number >= 0, got {v!r}")
            values[k] = float(v)
        return cls(**values)

    def to_dict(self) -> dict:
        return {k: v for k, v in dataclasses.asdict(self).items() if v is not None}


def _as_float_array(value, shape_tail: tuple, name: str, n: int | None, allow_nan: bool) -> np.ndarray:
    try:
        arr = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise ObservationError(f"'{name}' is not numeric: {exc}") from None
    if arr.ndim != 1 + len(shape_tail) or arr.shape[1:] != shape_tail:
        raise ObservationError(f"'{name}' must have shape (n, {', '.join(map(str, shape_tail))}), got {arr.shape}")
    if n is not None and arr.shape[0] != n:
        raise ObservationError(f"'{name}' has {arr.shape[0]} rows but there are {n} frames (mismatched lengths)")
    if np.isinf(arr).any():
        raise ObservationError(f"'{name}' contains infinite values")
    if not allow_nan and np.isnan(arr).any():
        raise ObservationError(f"'{name}' contains NaN values")
    return arr


@dataclass(frozen=True)
class Observations:
    """One localization problem with n frames.

    Attributes:
        P: (n, 3, 4) projection matrices, world metres -> homogeneous pixels.
        pixel: (n, 2) target pixel (u, v) in px; a row of NaN where the target was not seen.
        platform_m: (n, 3) platform (laser origin) position in the world frame, metres.
        range_m: (n,) laser range in metres; NaN where there was none.
        t_ns: (n,) int64 timestamps in nanoseconds (0..n-1 when unknown).
        sigma: a priori sensor standard deviations.
        truth_m: (3,) true target position when known, else None.
    """

    P: np.ndarray
    pixel: np.ndarray
    platform_m: np.ndarray
    range_m: np.ndarray
    t_ns: np.ndarray = None  # type: ignore[assignment]
    sigma: Sigma = field(default_factory=Sigma)
    truth_m: np.ndarray | None = None

    def __post_init__(self):
        P = _as_float_array(self.P, (3, 4), "P", None, allow_nan=False)
        n = P.shape[0]
        if n == 0:
            raise ObservationError("there are no observations")
        pixel = _as_float_array(self.pixel, (2,), "pixel", n, allow_nan=True)
        if (np.isnan(pixel[:, 0]) != np.isnan(pixel[:, 1])).any():
            raise ObservationError("'pixel' has a row with only one of u, v missing")
        platform = _as_float_array(self.platform_m, (3,), "platform_m", n, allow_nan=False)
        rng = _as_float_array(np.asarray(self.range_m, dtype=np.float64).reshape(-1, 1), (1,), "range_m", n,
                              allow_nan=True)[:, 0]
        if (rng[~np.isnan(rng)] <= 0).any():
            raise ObservationError("'range_m' must be positive where given")
        if self.t_ns is None:
            t = np.arange(n, dtype=np.int64)
        else:
            t = np.asarray(self.t_ns)
            if t.shape != (n,):
                raise ObservationError(f"'t_ns' has shape {t.shape} but there are {n} frames (mismatched lengths)")
            if not np.issubdtype(t.dtype, np.integer):
                raise ObservationError("'t_ns' must be integers (nanoseconds)")
            t = t.astype(np.int64)
        truth = self.truth_m
        if truth is not None:
            truth = np.asarray(truth, dtype=np.float64)
            if truth.shape != (3,) or not np.isfinite(truth).all():
                raise ObservationError(f"'truth_m' must be 3 finite numbers, got {self.truth_m!r}")
        for name, value in (("P", P), ("pixel", pixel), ("platform_m", platform), ("range_m", rng),
                            ("t_ns", t), ("truth_m", truth)):
            if value is not None:
                value.setflags(write=False)
            object.__setattr__(self, name, value)

    @property
    def n(self) -> int:
        return self.P.shape[0]

    @property
    def has_pixel(self) -> np.ndarray:
        """(n,) bool: frames whose target pixel is known."""
        return ~np.isnan(self.pixel[:, 0])

    @property
    def has_range(self) -> np.ndarray:
        """(n,) bool: frames with a laser range."""
        return ~np.isnan(self.range_m)

    def subset(self, mask: np.ndarray) -> Observations:
        """The frames selected by a boolean or index mask, as a new problem."""
        return dataclasses.replace(self, P=self.P[mask], pixel=self.pixel[mask], platform_m=self.platform_m[mask],
                                   range_m=self.range_m[mask], t_ns=self.t_ns[mask])


@dataclass(frozen=True)
class ObservationBatch:
    """B problems of n frames each, stacked: P (B, n, 3, 4), pixel (B, n, 2), platform_m (B, n, 3),
    range_m (B, n); NaN marks a missing pixel or range as in `Observations`. truth_m is (B, 3) or None.
    Validated once for the whole batch (shapes and non-finite values), not per problem."""

    P: np.ndarray
    pixel: np.ndarray
    platform_m: np.ndarray
    range_m: np.ndarray
    sigma: Sigma = field(default_factory=Sigma)
    truth_m: np.ndarray | None = None

    def __post_init__(self):
        P = np.asarray(self.P, dtype=np.float64)
        if P.ndim != 4 or P.shape[2:] != (3, 4):
            raise ObservationError(f"batch 'P' must have shape (B, n, 3, 4), got {P.shape}")
        B, n = P.shape[:2]
        expected = {"pixel": (B, n, 2), "platform_m": (B, n, 3), "range_m": (B, n)}
        arrays = {"P": P}
        for name, shape in expected.items():
            arr = np.asarray(getattr(self, name), dtype=np.float64)
            if arr.shape != shape:
                raise ObservationError(f"batch '{name}' must have shape {shape}, got {arr.shape}")
            arrays[name] = arr
        if not np.isfinite(P).all() or not np.isfinite(arrays["platform_m"]).all():
            raise ObservationError("batch 'P' and 'platform_m' must be finite")
        if np.isinf(arrays["pixel"]).any() or np.isinf(arrays["range_m"]).any():
            raise ObservationError("batch 'pixel' and 'range_m' must be finite or NaN")
        for name, arr in arrays.items():
            object.__setattr__(self, name, arr)
        if self.truth_m is not None:
            truth = np.asarray(self.truth_m, dtype=np.float64)
            if truth.shape != (B, 3):
                raise ObservationError(f"batch 'truth_m' must have shape ({B}, 3), got {truth.shape}")
            object.__setattr__(self, "truth_m", truth)

    @property
    def size(self) -> int:
        return self.P.shape[0]

    @property
    def n(self) -> int:
        return self.P.shape[1]

    @classmethod
    def stack(cls, problems: list[Observations]) -> ObservationBatch:
        if not problems:
            raise ObservationError("cannot stack an empty list of problems")
        truths = [p.truth_m for p in problems]
        truth = np.stack(truths) if all(t is not None for t in truths) else None
        return cls(P=np.stack([p.P for p in problems]), pixel=np.stack([p.pixel for p in problems]),
                   platform_m=np.stack([p.platform_m for p in problems]),
                   range_m=np.stack([p.range_m for p in problems]), sigma=problems[0].sigma, truth_m=truth)

    def problem(self, b: int) -> Observations:
        return Observations(P=self.P[b], pixel=self.pixel[b], platform_m=self.platform_m[b],
                            range_m=self.range_m[b], sigma=self.sigma,
                            truth_m=None if self.truth_m is None else self.truth_m[b])
