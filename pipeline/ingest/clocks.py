"""Time bases: GPS week/ms -> UNIX, and mapping a series between clocks through `ClockLink` pairs."""

from __future__ import annotations

import numpy as np

# GPS time started 1980-01-06T00:00:00 UTC and has no leap seconds; UTC = GPS - 18 s since 2017-01-01 (IERS
# Bulletin C). Logs older than 2017 are off by one or more seconds with this constant; the offset is stated
# here once and in docs/ingest.md.
GPS_EPOCH_UNIX_S = 315964800
GPS_UTC_LEAP_S = 18
NS_PER_WEEK = 7 * 86400 * 10**9


def unix_ns_from_gps(week, ms_of_week, leap_s: int = GPS_UTC_LEAP_S) -> np.ndarray:
    """GPS week number and milliseconds of week -> UNIX (UTC) int64 ns."""
    week = np.asarray(week, np.int64)
    ms = np.asarray(ms_of_week, np.int64)
    return (GPS_EPOCH_UNIX_S - leap_s) * 10**9 + week * NS_PER_WEEK + ms * 10**6


def fit_clock_map(a_ns: np.ndarray, b_ns: np.ndarray) -> tuple[int, float, float, int]:
    """Least-squares b = a + offset + drift * (a - a0) over the pairs, after discarding pairs whose offset is more
    than 1 s from the median (e.g. SYSTEM_TIME before the GPS fix, time_unix_usec = 0). Returns
    (base_offset_ns (int), residual offset_ns at a0 (float), drift (dimensionless), a0_ns):
    b = a + base + offset + drift * (a - a0)."""
    a = np.asarray(a_ns, np.int64)
    b = np.asarray(b_ns, np.int64)
    if a.size == 0:
        raise ValueError("no clock pairs")
    off = b - a
    med = int(np.sort(off)[off.size // 2])  # integer median: float64 would lose ~100 ns at UNIX-ns magnitudes
    keep = np.abs(off - med) < 10**9
    a, off = a[keep], off[keep]
    a0 = int(a[0])
    y = (off - med).astype(float)
    if a.size < 3 or (a[-1] - a[0]) < 10**9:
        return med, float(np.median(y)), 0.0, a0
    drift, c = np.polyfit((a - a0).astype(float), y, 1)
    return med, float(c), float(drift), a0


def map_clock(t_ns: np.ndarray, link, reverse: bool = False) -> np.ndarray:
    """Map times on clock `link.a` onto clock `link.b` (or b -> a with reverse=True) by the fitted line."""
    a_ns, b_ns = (link.b_ns, link.a_ns) if reverse else (link.a_ns, link.b_ns)
    base, offset, drift, a0 = fit_clock_map(a_ns, b_ns)
    t = np.asarray(t_ns, np.int64)
    return t + np.int64(base) + np.round(offset + (t - a0).astype(float) * drift).astype(np.int64)


def find_link(links, a: str, b: str):
    """The first ClockLink between clocks a and b (either direction) as (link, reverse) or (None, False)."""
    for link in links:
        if (link.a, link.b) == (a, b):
            return link, False
        if (link.a, link.b) == (b, a):
            return link, True
    return None, False


def series_to_clock(series, links, clock: str = "unix"):
    """Return `series` (any model series with t_ns and clock) re-timed onto `clock` through a ClockLink, or
    unchanged when it is already there. Raises ValueError when no link connects the two clocks."""
    import dataclasses

    if series is None or series.clock == clock:
        return series
    link, reverse = find_link(links, series.clock, clock)
    if link is None:
        raise ValueError(f"no clock link from {series.clock!r} to {clock!r}")
    t = map_clock(series.t_ns, link, reverse=reverse)
    order = np.argsort(t, kind="stable")
    changes = {"t_ns": t[order], "clock": clock}
    for f in dataclasses.fields(series):
        val = getattr(series, f.name)
        if f.name not in changes and isinstance(val, np.ndarray) and val.shape[:1] == t.shape:
            changes[f.name] = val[order]
    return dataclasses.replace(series, **changes)
