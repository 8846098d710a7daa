"""Distances on the WGS84 ellipsoid: pyproj's `Geod.inv` (GeographicLib's geodesic algorithm, vectorised), not a
hand-written haversine; it is right across the antimeridian and at the poles. tests/test_geodesic.py checks it
against GeographicLib's published JFK-LHR example."""

from __future__ import annotations

import numpy as np


def geodesic_m(lat1_deg, lon1_deg, lat2_deg, lon2_deg) -> np.ndarray:
    """Geodesic distance (m) between points 1 and 2 (deg); arrays broadcast."""
    from pyproj import Geod

    lat1, lon1, lat2, lon2 = np.broadcast_arrays(*(np.asarray(v, dtype=np.float64)
                                                   for v in (lat1_deg, lon1_deg, lat2_deg, lon2_deg)))
    _, _, d = Geod(ellps="WGS84").inv(lon1.ravel(), lat1.ravel(), lon2.ravel(), lat2.ravel())
    return np.asarray(d, dtype=np.float64).reshape(lat1.shape)


def pairwise_geodesic_m(lat_deg, lon_deg) -> np.ndarray:
    """(n, n) geodesic distances (m) between n points (deg)."""
    lat, lon = np.asarray(lat_deg, dtype=np.float64), np.asarray(lon_deg, dtype=np.float64)
    return geodesic_m(lat[:, None], lon[:, None], lat[None, :], lon[None, :])
