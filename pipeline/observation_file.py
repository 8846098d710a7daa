"""The observations file (`ridgeloc solve OBS.json`, docs/observations_format.md): `load`, `from_dict` (a parsed
document), `to_dict`, `save` of an `Observations`. Every problem with a file is one ObservationError naming it."""

from __future__ import annotations

import json
from os import PathLike
from pathlib import Path

import numpy as np

from pipeline.errors import ObservationError
from pipeline.solve.observations import Observations, Sigma

# Limits for `load`, so that a hostile or broken file fails with a message instead of exhausting
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


def from_dict(doc: dict) -> Observations:
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
    return Observations(P=np.array(P, dtype=np.float64), pixel=np.array(pixel, dtype=np.float64),
                        platform_m=np.array(platform, dtype=np.float64), range_m=np.array(rng, dtype=np.float64),
                        t_ns=np.array(t, dtype=np.int64), sigma=Sigma.from_dict(doc.get("sigma")), truth_m=truth)


def load(path: str | PathLike) -> Observations:
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
        if str(path).lower().endswith((".yaml", ".yml")):  # a flight or run config: `run` takes those
            raise ObservationError("a YAML config, not an observations JSON file: `ridgeloc run` takes flight "
                                   "configs; `ridgeloc solve` the observations.json a run writes per flight (docs/"
                                   "observations_format.md)", path) from None
        raise ObservationError(f"not valid JSON: {exc.msg} at line {exc.lineno} column {exc.colno}",
                               path) from None
    except RecursionError:
        raise ObservationError(f"not usable JSON: nested too deeply (the limit is {MAX_DEPTH} levels)",
                               path) from None
    except ValueError as exc:  # e.g. a number the float/int parsers refuse
        raise ObservationError(f"not valid JSON: {str(exc).splitlines()[0]}", path) from None
    try:
        _check_tree(doc)
        return from_dict(doc)
    except ObservationError as exc:
        raise ObservationError(str(exc), path) from None


def to_dict(obs: Observations) -> dict:
    """The file's JSON document for obs (absent pixels and ranges as null; sigma only where set)."""
    rows = []
    for i in range(obs.n):
        rows.append({
            "t_ns": int(obs.t_ns[i]),
            "P": obs.P[i].tolist(),
            "pixel": None if np.isnan(obs.pixel[i, 0]) else obs.pixel[i].tolist(),
            "platform_m": obs.platform_m[i].tolist(),
            "range_m": None if np.isnan(obs.range_m[i]) else float(obs.range_m[i]),
        })
    doc: dict = {"observations": rows}
    sigma = obs.sigma.to_dict()
    if sigma:
        doc["sigma"] = sigma
    if obs.truth_m is not None:
        doc["truth_m"] = obs.truth_m.tolist()
    return doc


def save(obs: Observations, path: str | PathLike) -> None:
    """Writes obs as an observations file (to_dict, indented)."""
    Path(path).write_text(json.dumps(to_dict(obs), indent=1))
