"""Compact streaming accumulation of decoded samples (typed `array.array`, 8 bytes per value) and assembly of
the model's series (sorted by time) from them."""

from __future__ import annotations

from array import array

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
