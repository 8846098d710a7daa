"""The observation model every estimator consumes.

Frame i has a 3x4 projection matrix P_i (world -> pixel, world = a local Cartesian frame in metres, normally
ENU at a chosen origin), the target pixel (u_i, v_i) or NaN when the target was not seen, the platform
position s_i in metres (the laser's origin), and the laser range d_i in metres or NaN when there was none.

`Observations` is one problem; `ObservationBatch` is B problems of the same frame count n stacked on a
leading axis, for the batched solvers the simulation uses. Both are validated on construction.
"""

from __future__ import annotations

import dataclasses
import json
from dataclasses import dataclass, field
from os import PathLike
from pathlib import Path

import numpy as np

from pipeline.errors import ObservationError

# Limits for `Observations.load`, so that a hostile or broken file fails with a message instead of exhausting
# memory or the stack. A frame takes ~600-1000 bytes of JSON, so 64 MB is ~60,000+ frames; the parsed document
# takes ~10x its file size in Python objects.
MAX_FILE_BYTES = 64 * 2**20
MAX_DEPTH = 32  # the format itself needs 5 levels (top, observations, frame, P, row); 'meta' may nest more
MAX_INT_DIGITS = 40  # wider integers are refused while parsing (t_ns fits in 19 digits)
INT64_MIN, INT64_MAX = -(2**63), 2**63 - 1


class _Refused:
    """Placeholder the JSON parser leaves for a value it refuses (NaN, Infinity, overflow, huge integer), so
    the message can name where it is."""

    def __init__(self, what: str):
        self.what = what


def _parse_float(text: str):
    value = float(text)
    if np.isfinite(value):
        return value
    return _Refused(f"{text[:30]}, which overflows to infinity (non-finite numbers are refused)")


def _parse_int(text: str):
    if len(text.lstrip("-")) > MAX_INT_DIGITS:
        return _Refused(f"an integer of {len(text.lstrip('-'))} digits (more than {MAX_INT_DIGITS})")
    return int(text)


def _parse_constant(text: str):
    return _Refused(f"{text} (not valid JSON: non-finite numbers are refused; write null for a missing value)")


def _check_tree(doc) -> None:
    """Refuses a document nested deeper than MAX_DEPTH or holding a refused value, naming where (iterative, so
    a deep document cannot exhaust the stack here)."""
    stack = [(doc, "", 1)]
    while stack:
        value, where, depth = stack.pop()
        if isinstance(value, _Refused):
            raise ObservationError(f"{where or 'the top level'} is {value.what}")
        if isinstance(value, dict | list):
            if depth > MAX_DEPTH:
                raise ObservationError(f"{_short_path(where)} is nested more than {MAX_DEPTH} levels deep")
            if isinstance(value, dict):
                children = [(v, f"{where}.{k}" if where else k, depth + 1) for k, v in value.items()]
            else:
                children = [(v, f"{where}[{i}]", depth + 1) for i, v in enumerate(value)]
            stack.extend(reversed(children))


def _short_path(where: str) -> str:
    return where if len(where) <= 60 else where[:40] + "..." + where[-17:]


def _is_number(v) -> bool:
    return isinstance(v, int | float) and not isinstance(v, bool)


def _numbers(value, count: int, where: str, what: str) -> list:
    """`value` as a list of `count` finite numbers, or an ObservationError naming `where`."""
    if not (isinstance(value, list) and len(value) == count and all(_is_number(v) for v in value)):
        raise ObservationError(f"{where} must be {what}, got {_short(value)}")
    if not all(np.isfinite(v) for v in value):
        raise ObservationError(f"{where} must be finite, got {_short(value)}")
    return value


def _short(value) -> str:
    text = repr(value)
    return text if len(text) <= 60 else text[:57] + "..."


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

    # ---- JSON (the `ridgeloc solve` file format, docs/observations_format.md) -------------------------

    @classmethod
    def from_dict(cls, doc: dict) -> Observations:
        """A parsed observations document (docs/observations_format.md); `null` (None) means missing wherever a
        key is optional. Every problem is an ObservationError naming the key, e.g. `observations[3].P`."""
        if not isinstance(doc, dict):
            raise ObservationError("the top level must be a JSON object with an 'observations' list")
        unknown = sorted(set(doc) - {"observations", "sigma", "truth_m", "meta"})
        if unknown:
            raise ObservationError(f"unknown top-level key(s): {', '.join(map(str, unknown))}")
        rows = doc.get("observations")
        if not isinstance(rows, list) or not rows:
            raise ObservationError("'observations' must be a non-empty list")
        P, pixel, platform, rng, t = [], [], [], [], []
        for i, row in enumerate(rows):
            where = f"observations[{i}]"
            if not isinstance(row, dict):
                raise ObservationError(f"{where} must be an object")
            missing = sorted(k for k in ("P", "platform_m") if row.get(k) is None)
            if missing:
                raise ObservationError(f"{where} lacks required key(s): {', '.join(missing)}")
            extra = sorted(set(row) - {"t_ns", "P", "pixel", "platform_m", "range_m"})
            if extra:
                raise ObservationError(f"{where} has unknown key(s): {', '.join(map(str, extra))}")
            p = row["P"]
            if not (isinstance(p, list) and len(p) == 3):
                raise ObservationError(f"{where}.P must be 3x4 (3 rows of 4 numbers), got {_short(p)}")
            P.append([_numbers(r, 4, f"{where}.P[{k}]", "a row of 4 numbers") for k, r in enumerate(p)])
            px = row.get("pixel")
            pixel.append([np.nan, np.nan] if px is None else _numbers(px, 2, f"{where}.pixel", "[u, v] or null"))
            platform.append(_numbers(row["platform_m"], 3, f"{where}.platform_m", "[x, y, z]"))
            r = row.get("range_m")
            if r is not None and not _is_number(r):
                raise ObservationError(f"{where}.range_m must be a number or null, got {_short(r)}")
            rng.append(np.nan if r is None else r)
            ti = row.get("t_ns")
            ti = i if ti is None else ti
            if not (isinstance(ti, int) and not isinstance(ti, bool) and INT64_MIN <= ti <= INT64_MAX):
                raise ObservationError(f"{where}.t_ns must be a 64-bit integer (nanoseconds), got {_short(ti)}")
            t.append(ti)
        truth = doc.get("truth_m")
        if truth is not None:
            truth = _numbers(truth, 3, "truth_m", "[x, y, z] or null")
        return cls(P=np.array(P, dtype=np.float64), pixel=np.array(pixel, dtype=np.float64),
                   platform_m=np.array(platform, dtype=np.float64), range_m=np.array(rng, dtype=np.float64),
                   t_ns=np.array(t, dtype=np.int64), sigma=Sigma.from_dict(doc.get("sigma")), truth_m=truth)

    @classmethod
    def load(cls, path: str | PathLike) -> Observations:
        """Reads and validates an observations file. Every problem is one ObservationError naming the file:
        missing, a directory, unreadable, over MAX_FILE_BYTES, not JSON, nested deeper than MAX_DEPTH, a
        non-finite number (NaN, Infinity, 1e999) with its location, or any format violation."""
        path = Path(path)
        try:
            size = path.stat().st_size
            if path.is_dir():
                raise ObservationError("is a directory, expected an observations JSON file", path)
            if size > MAX_FILE_BYTES:
                raise ObservationError(f"is {size / 2**20:.1f} MB, over the {MAX_FILE_BYTES / 2**20:g} MB limit for "
                                       f"an observations file (split the problem)", path)
            with open(path, "rb") as f:  # bounded even for a device or a pipe, whose size stat() does not know
                data = f.read(MAX_FILE_BYTES + 1)
            if len(data) > MAX_FILE_BYTES:
                raise ObservationError(f"is over the {MAX_FILE_BYTES / 2**20:g} MB limit for an observations file",
                                       path)
            text = data.decode("utf-8")
        except FileNotFoundError:
            raise ObservationError("file not found", path) from None
        except OSError as exc:
            raise ObservationError(f"cannot read: {exc.strerror or exc}", path) from None
        except UnicodeDecodeError as exc:
            raise ObservationError(f"not UTF-8 text (byte {exc.start}): not an observations JSON file",
                                   path) from None
        try:
            doc = json.loads(text, parse_float=_parse_float, parse_int=_parse_int, parse_constant=_parse_constant)
        except json.JSONDecodeError as exc:
            raise ObservationError(f"not valid JSON: {exc.msg} at line {exc.lineno} column {exc.colno}",
                                   path) from None
        except RecursionError:
            raise ObservationError(f"not usable JSON: nested too deeply (the limit is {MAX_DEPTH} levels)",
                                   path) from None
        except ValueError as exc:  # e.g. a number the float/int parsers refuse
            raise ObservationError(f"not valid JSON: {str(exc).splitlines()[0]}", path) from None
        try:
            _check_tree(doc)
            return cls.from_dict(doc)
        except ObservationError as exc:
            raise ObservationError(str(exc), path) from None

    def to_dict(self) -> dict:
        rows = []
        for i in range(self.n):
            rows.append({
                "t_ns": int(self.t_ns[i]),
                "P": self.P[i].tolist(),
                "pixel": None if np.isnan(self.pixel[i, 0]) else self.pixel[i].tolist(),
                "platform_m": self.platform_m[i].tolist(),
                "range_m": None if np.isnan(self.range_m[i]) else float(self.range_m[i]),
            })
        doc: dict = {"observations": rows}
        sigma = self.sigma.to_dict()
        if sigma:
            doc["sigma"] = sigma
        if self.truth_m is not None:
            doc["truth_m"] = self.truth_m.tolist()
        return doc

    def save(self, path: str | PathLike) -> None:
        Path(path).write_text(json.dumps(self.to_dict(), indent=1))

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
