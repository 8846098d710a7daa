"""Compact streaming accumulation of decoded samples (typed `array.array`, 8 bytes per value) and assembly of
the model's series (sorted by time) from them."""

from __future__ import annotations

from array import array
from collections.abc import Callable

import numpy as np


class Columns:
    """Named columns filled one sample at a time: `add(t_ns=..., lat=...)`; `arrays()` -> dict of numpy."""

    def __init__(self, **typecodes: str):
        self._cols = {name: array(code) for name, code in typecodes.items()}
        self._appends = [(name, col.append) for name, col in self._cols.items()]

    def add(self, **values) -> None:
        for name, append in self._appends:
            append(values[name])

    def appenders(self) -> list:
        """The `append` of each column in declaration order (for hot loops that fill every column)."""
        return [append for _, append in self._appends]

    def extend(self, name: str, values) -> None:
        self._cols[name].extend(values)

    def __len__(self) -> int:
        return len(next(iter(self._cols.values()))) if self._cols else 0

    def arrays(self) -> dict[str, np.ndarray]:
        """Numpy views of the columns (no copy: the arrays keep the buffers alive; add() no longer allowed)."""
        self._appends = []
        return {name: np.frombuffer(col, dtype=np.int64 if col.typecode == "q" else col.typecode)
                if len(col) else np.zeros(0, dtype=np.int64 if col.typecode == "q" else float)
                for name, col in self._cols.items()}


def sort_by_time(t_ns: np.ndarray, *columns: np.ndarray) -> tuple[np.ndarray, ...]:
    """Stable sort of t_ns and the matching rows of each column."""
    t_ns = np.asarray(t_ns, np.int64)
    if t_ns.size < 2 or (np.diff(t_ns) >= 0).all():
        return (t_ns, *columns)
    order = np.argsort(t_ns, kind="stable")
    return (t_ns[order], *(c[order] for c in columns))


def one_source(a: dict[str, np.ndarray], field: str, want=None, most_samples: bool = False,
               on_several: Callable[[np.ndarray, int], None] | None = None) -> dict[str, np.ndarray]:
    """The samples of one source (a sensor instance, a device, a system id: `a[field]`), so that two receivers,
    mounts or rangefinders are never interleaved into one jumping series.

    `want` (an int) chooses it; else the lowest value logged, or with `most_samples` the one with the most samples
    (ties: the lowest), and `on_several(values logged (k,), the one chosen)` is called when there were several
    (the caller's warning). `a` is returned as is when it has no `field`, no samples or a single source."""
    if field not in a or not a[field].size:
        return a
    if want is None:
        ids, n = np.unique(a[field], return_counts=True)
        if ids.size == 1:
            return a
        want = int(ids[np.argmax(n)] if most_samples else ids[0])
        if on_several is not None:
            on_several(ids, want)
    keep = a[field] == int(want)
    return {k: v[keep] for k, v in a.items()}
