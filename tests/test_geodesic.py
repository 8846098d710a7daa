"""pipeline.geometry.geodesic against published values."""

import numpy as np
import pytest

from pipeline.geometry.geodesic import geodesic_m, pairwise_geodesic_m


def test_geographiclib_jfk_to_lhr():
    # GeographicLib's documented example (Karney, geographiclib Python docs): Inverse(40.6, -73.8, 51.6, -0.5),
    # s12 = 5551759.400318679 m on WGS84
    assert geodesic_m(40.6, -73.8, 51.6, -0.5) == pytest.approx(5551759.4003, abs=1e-3)


def test_across_the_antimeridian_and_pairwise():
    # 0.2 deg of longitude on the equator across 180 deg: a * 0.2 deg in radians (a = 6378137 m)
    assert geodesic_m(0.0, 179.9, 0.0, -179.9) == pytest.approx(6378137.0 * np.radians(0.2), rel=1e-9)
    d = pairwise_geodesic_m([0.0, 0.0, 10.0], [0.0, 1.0, 0.0])
    assert d.shape == (3, 3) and np.allclose(np.diag(d), 0.0) and np.allclose(d, d.T)
