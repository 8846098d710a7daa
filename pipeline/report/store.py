"""A `GroupResult` to and from JSON (`OUTDIR/<group>/result.json`), so a re-run can reuse finished groups.

Strict JSON: NaN is written as null and read back as NaN.
"""

from __future__ import annotations

import json
from os import PathLike
from pathlib import Path

import numpy as np

from pipeline import observation_file
from pipeline.answer import Answer
from pipeline.atomic import atomic_write_text
from pipeline.errors import InputError
from pipeline.results import FlightResult, GroupResult, TargetFailure
from pipeline.solve.estimate import Estimate, Status

FORMAT = "ridgeloc-group-result"
VERSION = 1
FLIGHT_FORMAT = "ridgeloc-flight-targets"  # a flight with named targets (issue 21): a group result per target


def _nan_to_none(values) -> list:
    return [None if not np.isfinite(v) else float(v) for v in np.asarray(values, dtype=np.float64).ravel()]


def _finite_or_none(value):
    """`value` (nested dicts, lists, numbers) with every non-finite float as None: strict JSON."""
    if isinstance(value, dict):
        return {k: _finite_or_none(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_finite_or_none(v) for v in value]
    if isinstance(value, float) and not np.isfinite(value):
        return None
    return value


def _none_to_nan(values) -> np.ndarray:
    return np.array([np.nan if v is None else v for v in values], dtype=np.float64)


def estimate_to_json(e: Estimate) -> dict:
    return {
        "method": e.method,
        "position_m": _nan_to_none(e.position_m),
        "iterations": int(e.iterations),
        "status": e.status.name,
        "residuals": _nan_to_none(e.residuals),
        "condition_number": _nan_to_none([e.condition_number])[0],
        "covariance_m2": None if e.covariance_m2 is None else np.asarray(e.covariance_m2).tolist(),
        "extras": _finite_or_none(e.extras),
    }


def estimate_from_json(d: dict) -> Estimate:
    cov = d.get("covariance_m2")
    cond = d.get("condition_number")
    return Estimate(method=d["method"], position_m=_none_to_nan(d["position_m"]), iterations=int(d["iterations"]),
                    status=Status[d["status"]], residuals=_none_to_nan(d.get("residuals", [])),
                    condition_number=float("nan") if cond is None else float(cond),
                    covariance_m2=None if cov is None else np.asarray(cov, dtype=np.float64),
                    extras=d.get("extras") or {})


def group_result_to_json(r: GroupResult) -> dict:
    angle = r.intersection_angle_deg
    return {
        "format": FORMAT,
        "version": VERSION,
        "name": r.name,
        "origin_lla": [float(v) for v in r.origin_lla],
        "observations": observation_file.to_dict(r.observations),
        "estimates": {m: estimate_to_json(e) for m, e in r.estimates.items()},
        "truth_m": None if r.truth_m is None else [float(v) for v in r.truth_m],
        "intersection_angle_deg": float(angle) if np.isfinite(angle) else None,
        "timings_s": {k: float(v) for k, v in r.timings_s.items()},
        "settings": r.settings,
        "tracking": r.tracking,
        **({} if r.target is None else {"target": r.target}),
        **({} if r.answer is None else {"answer": r.answer.to_dict()}),
    }


def flight_result_to_json(r: FlightResult) -> dict:
    return {"format": FLIGHT_FORMAT, "version": VERSION, "name": r.name,
            "targets": [group_result_to_json(t) for t in r.targets],
            "failed": [{"target": f.target, "message": f.message, "methods": list(f.methods)} for f in r.failed],
            "timings_s": {k: float(v) for k, v in r.timings_s.items()}, "settings": r.settings}


def flight_result_from_json(doc: dict) -> FlightResult:
    if doc.get("version") != VERSION:
        raise InputError(f"unsupported {FLIGHT_FORMAT} version {doc.get('version')!r} (expected {VERSION})")
    return FlightResult(name=doc["name"], targets=[group_result_from_json(t) for t in doc["targets"]],
                        failed=[TargetFailure(f["target"], f["message"], tuple(f.get("methods") or ()))
                                for f in doc.get("failed", [])],
                        timings_s=dict(doc.get("timings_s", {})), settings=doc.get("settings", {}))


def group_result_from_json(doc: dict) -> GroupResult | FlightResult:
    if isinstance(doc, dict) and doc.get("format") == FLIGHT_FORMAT:
        return flight_result_from_json(doc)
    if not isinstance(doc, dict) or doc.get("format") != FORMAT:
        raise InputError(f"not a {FORMAT} document")
    if doc.get("version") != VERSION:
        raise InputError(f"unsupported {FORMAT} version {doc.get('version')!r} (expected {VERSION})")
    angle = doc.get("intersection_angle_deg")
    truth = doc.get("truth_m")
    return GroupResult(
        name=doc["name"],
        origin_lla=tuple(float(v) for v in doc["origin_lla"]),
        observations=observation_file.from_dict(doc["observations"]),
        estimates={m: estimate_from_json(e) for m, e in doc["estimates"].items()},
        truth_m=None if truth is None else np.asarray(truth, dtype=np.float64),
        intersection_angle_deg=float("nan") if angle is None else float(angle),
        timings_s=dict(doc.get("timings_s", {})),
        settings=doc.get("settings", {}),
        tracking=doc.get("tracking", {}),
        target=doc.get("target"),
        answer=None if doc.get("answer") is None else Answer.from_dict(doc["answer"]),
    )


def save_group_result(path: str | PathLike, r: GroupResult | FlightResult) -> None:
    """Write `r` as JSON to `path` (atomically)."""
    doc = flight_result_to_json(r) if isinstance(r, FlightResult) else group_result_to_json(r)
    atomic_write_text(path, json.dumps(doc, indent=1, allow_nan=False))


def load_group_result(path: str | PathLike) -> GroupResult:
    """Read a `GroupResult` written by `save_group_result`; InputError naming the file if it cannot."""
    path = Path(path)
    try:
        doc = json.loads(path.read_text())
    except FileNotFoundError:
        raise InputError("file not found", path) from None
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise InputError(f"cannot read group result: {exc}", path) from None
    try:
        return group_result_from_json(doc)
    except (KeyError, TypeError, ValueError) as exc:
        raise InputError(f"malformed group result: {exc!r}", path) from None
    except InputError as exc:
        raise InputError(str(exc), path) from None
