"""Which rangefinder is the laser: one rule for every log format (DataFlash RFND, MAVLink DISTANCE_SENSOR and
RANGEFINDER, ULog distance_sensor).

1. Keep the samples whose orientation (MAV_SENSOR_ORIENTATION) is in `<format>.range.orientations` (default
   [0, 100]: forward, custom e.g. on the gimbal); a down-facing sensor (25) is the terrain altimeter.
   null keeps every orientation.
2. Of the instances left, keep `<format>.range.instance`, or by default the lowest instance, with a warning
   when there are several, so two sensors are never interleaved into one jumping series. `most_samples`
   chooses the instance with the most samples instead (the tlog reader's rule before the unification).
"""

from __future__ import annotations

import warnings as _warnings
from collections.abc import Callable
from pathlib import Path

import numpy as np

from pipeline.ingest.columns import one_source

# Old mapping key names, still accepted (with a FutureWarning naming the new key): format -> {old: new}.
DEPRECATED_RANGE_KEYS = {"tlog": {"distance_sensor_orientations": "orientations", "distance_sensor_id": "instance"}}


def rename_deprecated_range_keys(fmt: str, override: dict) -> dict:
    """`override` (one format's mapping override) with old `range` key names renamed to the current ones."""
    old_to_new = DEPRECATED_RANGE_KEYS.get(fmt, {})
    rng = override.get("range") if isinstance(override, dict) else None
    if not isinstance(rng, dict) or not old_to_new.keys() & rng.keys():
        return override
    rng = dict(rng)
    for old, new in old_to_new.items():
        if old in rng:
            _warnings.warn(f"ingest mapping {fmt}.range.{old} is deprecated: use {fmt}.range.{new}", FutureWarning,
                           stacklevel=3)
            val = rng.pop(old)
            rng.setdefault(new, val)
    return {**override, "range": rng}


def laser_facing(a: dict, orientations, source: str, fmt: str, warnings: list[str], path: Path) -> dict:
    """The samples of `a` (dict of equal-length columns, orientation in `a["orient"]` if logged) whose orientation
    is one of `orientations` (None: all)."""
    if orientations is None or "orient" not in a:
        return a
    keep = np.isin(a["orient"], [int(o) for o in orientations])
    if not keep.all():
        found = ", ".join(str(int(o)) for o in np.unique(a["orient"][~keep]))
        warnings.append(f"{path}: {int((~keep).sum())} of {keep.size} {source} samples with orientation {found} "
                        f"ignored (not the laser: 25 = down-facing altimeter; see {fmt}.range.orientations)")
        a = {k: v[keep] for k, v in a.items()}
    return a


def one_instance(a: dict, instance, source: str, fmt: str, warnings: list[str], path: Path,
                 label: Callable[[int], str] = lambda i: f"instance {i}") -> dict:
    """The samples of one instance (`a["instance"]`): `instance` (an int), else the lowest one, or with
    `instance="most_samples"` the one with the most samples (ties: the lowest); a warning when several."""
    def warn(ids: np.ndarray, want: int) -> None:
        warnings.append(f"{path}: {source} from several rangefinders ({', '.join(label(int(i)) for i in ids)}); "
                        f"range from {label(want)} (set {fmt}.range.instance to choose)")

    most = instance == "most_samples"
    return one_source(a, "instance", None if instance is None or most else instance, most, warn)
