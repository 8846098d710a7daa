"""The geoid model (pipeline.geometry.geoid) against published EGM2008 undulations.

Published values (EGM2008, NGA's tide-free model, WGS84):
- GeographicLib's GeoidEval with the egm2008-1 grid (https://geographiclib.sourceforge.io/cgi-bin/GeoidEval):
  N = 17.226 m at (0 N, 0 E) and -30.7048 m at (20 N, 50 E);
- GeographicLib's geoid documentation (https://geographiclib.sourceforge.io/C++/doc/geoid.html), the extremes of
  EGM2008 on its 1' grid: +85.839 m at (8.4 S, 147.367 E) and -106.911 m at (4.7 N, 78.767 E).
Our grid is NGA's 2.5' grid interpolated bilinearly, so it agrees to ~1 mm at the first two and to a few cm at the
extremes (peaks of the surface between grid nodes).
"""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.geometry.geoid import GeoidPatch, geoid_undulation_m, orthometric_height_m, patch_around

PUBLISHED = [  # lat_deg, lon_deg, N_m, tolerance_m
    (0.0, 0.0, 17.226, 0.003),
    (20.0, 50.0, -30.7048, 0.003),
    (-8.4, 147.367, 85.839, 0.05),
    (4.7, 78.767, -106.911, 0.05),
]


@pytest.mark.parametrize(("lat", "lon", "n_m", "tol"), PUBLISHED)
def test_undulation_at_published_points(lat, lon, n_m, tol):
    assert float(geoid_undulation_m(lat, lon)) == pytest.approx(n_m, abs=tol)


def test_vectorised_patch_and_longitude_conventions_agree():
    lat = np.array([p[0] for p in PUBLISHED])
    lon = np.array([p[1] for p in PUBLISHED])
    many = geoid_undulation_m(lat, lon)
    np.testing.assert_allclose(many, [p[2] for p in PUBLISHED], atol=0.05)
    # -180..180 and 0..360 longitudes are the same place; the 0 E seam is continuous
    np.testing.assert_allclose(geoid_undulation_m(10.0, -10.0), geoid_undulation_m(10.0, 350.0), atol=1e-9)
    seam = geoid_undulation_m([0.0, 0.0], [-1e-6, 1e-6])
    assert abs(seam[0] - seam[1]) < 1e-3
    # a patch read once around a flight gives what the global look-up gives, inside and outside its box
    patch = patch_around(47.4, 8.5)
    assert isinstance(patch, GeoidPatch)
    pts_lat, pts_lon = np.array([47.4, 47.6, 49.0]), np.array([8.5, 8.3, 8.5])
    np.testing.assert_allclose(patch(pts_lat, pts_lon), geoid_undulation_m(pts_lat, pts_lon), atol=1e-9)
    # the cached window of one area (points within AREA_DEG) and a window over a wide box give the same bits
    area_lat, area_lon = np.array([34.36, 34.41, 34.33]), np.array([108.76, 108.71, 108.79])
    wide = geoid_undulation_m(np.append(area_lat, 36.0), np.append(area_lon, 110.0))
    assert np.array_equal(geoid_undulation_m(area_lat, area_lon), wide[:3])
    assert [float(geoid_undulation_m(a, b)) for a, b in zip(area_lat, area_lon, strict=True)] == wide[:3].tolist()


def test_nan_and_shapes():
    out = geoid_undulation_m(np.array([[0.0, np.nan]]), np.array([[0.0, 0.0]]))
    assert out.shape == (1, 2) and np.isfinite(out[0, 0]) and np.isnan(out[0, 1])
    assert np.isnan(geoid_undulation_m(95.0, 0.0))
    h = orthometric_height_m(20.0, 50.0, 100.0)
    assert float(h) == pytest.approx(100.0 + 30.7048, abs=0.003)
