"""What one processed flight group yields: the contract between `ridgeloc run` and the report/export stage."""

from __future__ import annotations

import json
from dataclasses import dataclass, field

import numpy as np

from pipeline import observation_file
from pipeline.answer import Answer
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
        target: the target's name when the flight names its targets (`targets:`, issue 21), else None.
        answer: the target's one answer (`pipeline.answer`), chosen from the estimates by the documented rule.
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
    target: str | None = None
    answer: Answer | None = None

    @property
    def n_observations(self) -> int:
        return self.observations.n

    @property
    def label(self) -> str:
        """`group`, or `group:target` for a named target (its column in Table 4, its heading in the report)."""
        return self.name if self.target is None else f"{self.name}:{self.target}"

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


def group_files(result: GroupResult | FlightResult) -> dict[str, str]:
    """The per-group files `ridgeloc run` writes, name -> text: observations.json (the `ridgeloc solve` input,
    to re-solve without re-processing video), estimates.json (its --json output) and tracking.json (per-frame
    tracking quality). The report stage can pass them on as extra files of the group's folder. A flight with
    named targets: `flight_files`."""
    if isinstance(result, FlightResult):
        return flight_files(result)
    return {
        "observations.json": json.dumps(observation_file.to_dict(result.observations), indent=1) + "\n",
        "estimates.json": json.dumps(estimates_document(result), indent=1, default=_json_default) + "\n",
        "tracking.json": json.dumps(result.tracking, indent=1, default=_json_default) + "\n",
    }


# ---- many targets per flight (issue 21) ---------------------------------------------------------------------


@dataclass
class TargetFailure:
    """A named target of a flight that could not be located: its name and the one-line reason."""

    target: str
    message: str
    methods: tuple[str, ...] = ()  # the methods the flight asked for: one row each in targets.csv


@dataclass
class FlightResult:
    """One flight with named targets, processed: a GroupResult per located target (`target` set, `name` the
    flight's), a TargetFailure per target that could not be located, the flight's stage timings (targets'
    stages summed) and settings (notes: the flight-level ones)."""

    name: str
    targets: list[GroupResult]
    failed: list[TargetFailure] = field(default_factory=list)
    timings_s: dict[str, float] = field(default_factory=dict)
    settings: dict = field(default_factory=dict)


def per_target(results) -> list[GroupResult]:
    """GroupResults and FlightResults flattened into one GroupResult per located target, in order."""
    out: list[GroupResult] = []
    for r in results:
        out.extend(r.targets if isinstance(r, FlightResult) else [r])
    return out


def target_failures(results) -> list[tuple[str, TargetFailure]]:
    """(flight name, TargetFailure) of every target that could not be located."""
    return [(r.name, f) for r in results if isinstance(r, FlightResult) for f in r.failed]


def flight_files(result: FlightResult) -> dict[str, str]:
    """The per-flight files of a flight with named targets, name -> text: estimates.json keyed by target
    ({"targets": {name: the single-target document | {"status": "not_located", "reason"}}}), and per located
    target <target>/observations.json, <target>/estimates.json and <target>/tracking.json (as for one target)."""
    doc: dict = {"targets": {}}
    files: dict[str, str] = {}
    for r in result.targets:
        doc["targets"][r.target] = estimates_document(r)
        files.update({f"{r.target}/{k}": v for k, v in group_files(r).items()})
    for f in result.failed:
        doc["targets"][f.target] = {"status": "not_located", "reason": f.message}
    return {"estimates.json": json.dumps(doc, indent=1, default=_json_default) + "\n", **files}
