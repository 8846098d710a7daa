import math

import numpy as np
import pytest

from pipeline.errors import GeometryError
from pipeline.geometry.frames import (
    R_ENU_FROM_NED,
    R_enu0_from_ned_at,
    check_origin,
    ecef_from_lla,
    ellipsoid_from_amsl_m,
    enu_from_lla,
    lla_from_enu,
)
from pipeline.geometry.lens import distort_pixels, undistort_pixels

A_WGS84 = 6378137.0


def test_amsl_to_ellipsoid_adds_geoid_separation():
    np.testing.assert_allclose(ellipsoid_from_amsl_m([100.0, 0.0], 31.5), [131.5, 31.5])


def test_enu_of_origin_and_of_a_point_straight_above():
    origin = (30.0, 114.0, 50.0)
    np.testing.assert_allclose(enu_from_lla(30.0, 114.0, 50.0, origin), [0, 0, 0], atol=1e-6)
    np.testing.assert_allclose(enu_from_lla(30.0, 114.0, 1050.0, origin), [0, 0, 1000.0], atol=1e-6)


def test_enu_on_the_equator_matches_the_circle():
    # At the equator a longitude step dl moves a*dl east on a circle of radius a, and the chord drops below the
    # tangent plane by a(1 - cos dl).
    dl = math.radians(0.01)
    enu = enu_from_lla(0.0, 0.01, 0.0, (0.0, 0.0, 0.0))
    np.testing.assert_allclose(enu, [A_WGS84 * math.sin(dl), 0.0, -A_WGS84 * (1 - math.cos(dl))], atol=1e-6)


def test_lla_enu_round_trip_vectorised():
    origin = (45.0, 7.0, 300.0)
    lat = np.array([45.01, 44.98, 45.0])
    lon = np.array([7.02, 6.97, 7.0])
    h = np.array([1500.0, 200.0, 300.0])
    enu = enu_from_lla(lat, lon, h, origin)
    assert enu.shape == (3, 3)
    np.testing.assert_allclose(lla_from_enu(enu, origin), np.c_[lat, lon, h], atol=1e-7)


def test_ned_rotation_at_origin_is_the_axis_swap():
    np.testing.assert_allclose(R_enu0_from_ned_at(30.0, 114.0, (30.0, 114.0, 0.0)), R_ENU_FROM_NED, atol=1e-12)


def test_local_down_tilts_with_distance_from_origin():
    # On the equator at longitude a (radians) the local up in ECEF is (cos a, sin a, 0); at the origin (0, 0)
    # east = ECEF y, north = ECEF z, up = ECEF x, so the local down in ENU0 is (-sin a, 0, -cos a).
    a = 5000.0 / A_WGS84  # about 5 km east
    R = R_enu0_from_ned_at(0.0, math.degrees(a), (0.0, 0.0, 0.0))
    np.testing.assert_allclose(R[:, 2], [-math.sin(a), 0.0, -math.cos(a)], atol=1e-12)
    np.testing.assert_allclose(R[:, 0], [0.0, 1.0, 0.0], atol=1e-12)  # north stays north
    np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-12)
    assert 0.7e-3 < a < 0.8e-3  # the ~0.16 mrad per km of FIELD_NOTES


def test_ecef_of_equator_prime_meridian():
    np.testing.assert_allclose(ecef_from_lla(0.0, 0.0, 10.0), [A_WGS84 + 10.0, 0.0, 0.0], atol=1e-6)


def test_check_origin_rejects_garbage():
    assert check_origin(["1", 2, 3.0]) == (1.0, 2.0, 3.0)
    with pytest.raises(GeometryError):
        check_origin((95.0, 0.0, 0.0))
    with pytest.raises(GeometryError):
        check_origin("abc")


def test_undistort_inverts_distort_and_keeps_nan():
    K = np.array([[1200.0, 0, 300], [0, 1200.0, 200], [0, 0, 1]])
    dist = [-0.2, 0.1, 0.001, -0.001, 0.01]
    ideal = np.array([[10.0, 10.0], [590.0, 390.0], [300.0, 200.0]])
    seen = distort_pixels(ideal, K, dist)
    assert np.abs(seen - ideal).max() > 3  # the lens matters at the corners
    np.testing.assert_allclose(seen[2], [300.0, 200.0], atol=1e-9)  # not at the principal point
    back = undistort_pixels(np.vstack([seen, [np.nan, np.nan]]), K, dist)
    np.testing.assert_allclose(back[:3], ideal, atol=1e-6)
    assert np.isnan(back[3]).all()
