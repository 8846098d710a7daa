"""UTM meridian convergence from PROJ (pyproj), checked against a worked value and against the projection."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.geometry.grid_north import utm_convergence_deg, utm_zone


def test_new_york_worked_example():
    """New York (40.6 N, 74 W) in UTM zone 18 (central meridian 75 W): atan(tan(1 deg) sin(40.6 deg)) = 0.65 deg,
    grid north east of true north (the usual worked example of the sphere's formula)."""
    assert utm_zone(-74.0) == 18
    assert utm_convergence_deg(40.6, -74.0) == pytest.approx(0.6508, abs=5e-4)


@pytest.mark.parametrize("lat, lon", [(38.25, -77.37), (-33.9, 18.4), (64.1, -21.9), (1.0, 179.9), (-45.0, -3.0)])
def test_it_is_the_grid_bearing_of_true_north_in_the_projection(lat, lon):
    """Projected into the point's UTM zone, a step due north along the meridian has grid bearing -convergence."""
    from pyproj import Transformer

    zone = int(utm_zone(lon))
    epsg = (32600 if lat >= 0 else 32700) + zone
    t = Transformer.from_crs(4326, epsg, always_xy=True)
    e0, n0 = t.transform(lon, lat)
    e1, n1 = t.transform(lon, lat + 1e-5)
    bearing = np.degrees(np.arctan2(e1 - e0, n1 - n0))
    assert float(utm_convergence_deg(lat, lon)) == pytest.approx(-bearing, abs=1e-5)


def test_arrays_and_missing_points():
    got = utm_convergence_deg([40.6, np.nan, 10.0], [-74.0, 3.0, 3.0])
    assert got.shape == (3,) and np.isnan(got[1]) and got[2] == pytest.approx(0.0, abs=1e-9)
