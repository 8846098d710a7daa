"""What one processed flight group yields: the contract between `ridgeloc run` and the report/export stage."""

from __future__ import annotations

import json
from dataclasses import dataclass, field

import numpy as np

from pipeline.solve.estimate import Estimate
from pipeline.solve.observations import Observations


@dataclass
class GroupResult:
    """One flight group, processed.

    Attributes:
        name: group name (folder-safe), e.g. "group1".
        origin_lla: (lat_deg, lon_deg, alt_m) of the local ENU frame's origin, WGS84, altitude above the
            ellipsoid. Every *_m position below is ENU metres relative to it.
        observations: the synchronized observations that were solved (world frame = that ENU frame).
        estimates: method name -> Estimate, methods named as in `ridgeloc solve`.
        truth_m: (3,) true target position in ENU metres when known, else None.
        intersection_angle_deg: angle between the first and last lines of sight (paper's gamma).
        timings_s: stage name -> wall seconds (ingest, track, sync, solve, ...).
        settings: the flight's resolved configuration, JSON-serialisable, for the report.
        tracking: optional per-frame tracking quality (name -> (n,) list), JSON-serialisable.
    """

    name: str
    origin_lla: tuple[float, float, float]
    observations: Observations
    estimates: dict[str, Estimate]
    truth_m: np.ndarray | None = None
    intersection_angle_deg: float = float("nan")
    timings_s: dict[str, float] = field(default_factory=dict)
    settings: dict = field(default_factory=dict)
    tracking: dict = field(default_factory=dict)

    @property
    def n_observations(self) -> int:
        return self.observations.n

    def errors_m(self) -> dict[str, float | None]:
        return {m: e.error_m(self.truth_m) for m, e in self.estimates.items()}


@dataclass
class GroupFailure:
    """A flight group that could not be processed: its name, the source (config or folder) and the one-line
    error message; `detail` holds the traceback when the cause was a bug (not a RidgelocError), else ""."""

    name: str
    source: str
    message: str
    detail: str = ""


# ---- the files of one group -----------------------------------------------------------------------------------


def estimates_document(result: GroupResult) -> dict:
    """The `ridgeloc solve OBS.json --method all --json` document of the group's observations:
    {"estimates": {method: Estimate.to_dict(truth)}, "unsolved": {method: {"status", "reason"}} (only when some
    could not run)}."""
    doc: dict = {"estimates": {m: e.to_dict(result.truth_m) for m, e in result.estimates.items()}}
    failures = result.settings.get("solve_failures") or {}
    if failures:
        doc["unsolved"] = dict(failures)
    return doc


def _json_default(o):
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, (np.floating, np.integer, np.bool_)):
        return o.item()
    raise TypeError(f"not JSON-serialisable: {type(o).__name__}")


def group_files(result: GroupResult) -> dict[str, str]:
    """The per-group files `ridgeloc run` writes, name -> text: observations.json (the `ridgeloc solve` input,
    to re-solve without re-processing video), estimates.json (its --json output) and tracking.json (per-frame
    tracking quality). The report stage can pass them on as extra files of the group's folder."""
    return {
        "observations.json": json.dumps(result.observations.to_dict(), indent=1) + "\n",
        "estimates.json": json.dumps(estimates_document(result), indent=1, default=_json_default) + "\n",
        "tracking.json": json.dumps(result.tracking, indent=1, default=_json_default) + "\n",
    }
