"""Meridian convergence of UTM zones: the angle between true north and a UTM zone's grid north, for payloads that
log azimuths from grid north (the KWIVER Fort A.P. Hill clips, issue 40).

Computed by PROJ through pyproj (`Proj(proj="utm", zone=Z).get_factors(...).meridian_convergence`: the bearing of
grid north clockwise from true north, in degrees), not by a hand-written series; docs/ingest.md says why pyproj,
and tests/test_grid_north.py checks it against a worked value and against the projection itself.
"""

from __future__ import annotations

import numpy as np


def utm_zone(lon_deg) -> np.ndarray:
    """The standard 6-degree UTM zone number (1..60) of each longitude (deg); the Norway/Svalbard exceptions are
    not applied (a payload's grid is its zone's by longitude)."""
    lon = (np.asarray(lon_deg, dtype=np.float64) + 180.0) % 360.0
    return (np.floor(lon / 6.0).astype(np.int64) % 60) + 1


def utm_convergence_deg(lat_deg, lon_deg) -> np.ndarray:
    """Meridian convergence (deg) of each point's UTM zone, WGS84: grid north's bearing clockwise from true
    north, positive east of the zone's central meridian in the northern hemisphere. A grid azimuth becomes a true
    one by adding it: true = grid + convergence. Arrays broadcast; NaN where lat/lon is not finite."""
    from pyproj import Proj

    lat, lon = np.broadcast_arrays(np.asarray(lat_deg, dtype=np.float64), np.asarray(lon_deg, dtype=np.float64))
    out = np.full(lat.shape, np.nan)
    ok = np.isfinite(lat) & np.isfinite(lon) & (np.abs(lat) < 90.0)
    zones = utm_zone(np.where(ok, lon, 0.0))
    for z in np.unique(zones[ok]):
        m = ok & (zones == z)
        proj = Proj(proj="utm", zone=int(z), ellps="WGS84")
        out[m] = proj.get_factors(lon[m], lat[m]).meridian_convergence
    return out
