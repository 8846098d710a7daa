"""The photo error model by source type (pipeline/photo_errors.py) and its use by `locate`: RtkFlag / RtkStd* pick
the position sigmas, the laser's sigma follows DJI's spec at the longest range, the shared offset enters the MLE's
covariance and the terrain prior's sigma."""

import dataclasses

import numpy as np
import pytest

from pipeline.ingest.photo import read_photos
from pipeline.photo_errors import (
    COMPASS_BIAS_DEG,
    GNSS_FIXED_M,
    GNSS_FLOAT_M,
    GNSS_PLAIN_M,
    photo_error_model,
)
from pipeline.synth.photos import PhotoFlightSpec, simulate_photo_flight, write_photo_flight


@pytest.fixture(scope="module")
def photos(tmp_path_factory):
    folder = tmp_path_factory.mktemp("photos")
    flight = simulate_photo_flight(PhotoFlightSpec(seed=3))
    write_photo_flight(flight, folder)
    photos, bad = read_photos([folder])
    assert not bad
    return photos, flight


def test_plain_gnss_with_laser(photos):
    ph, _ = photos
    assert ph[0].rtk_flag == 16  # the synth writes single-point fixes
    m = photo_error_model(ph)
    assert (m.shared_h_m, m.shared_v_m, m.sigma.position_m) == (1.5, 15.0, 0.5)  # docs/locate.md, "Error model"
    assert m.bias_prior_deg == 3.0
    longest = max(p.lrf_range_m for p in ph)
    assert m.sigma.range_m == pytest.approx(0.2 + 0.0015 * longest)
    assert m.source == "GNSS without RTK, laser"


def test_rtk_flags_and_std_tags(photos):
    ph, _ = photos
    fixed = [dataclasses.replace(p, rtk_flag=50, rtk_std_m=(0.02, 0.03, 0.05)) for p in ph]
    m = photo_error_model(fixed)
    assert m.shared_h_m == 0.03 and m.sigma.position_m == 0.03
    assert m.shared_v_m == GNSS_FIXED_M[1]  # RtkStdHgt below the datum's floor
    no_std = [dataclasses.replace(p, rtk_flag=50, rtk_std_m=None) for p in ph]
    assert photo_error_model(no_std).shared_h_m == GNSS_FIXED_M[0]
    flt = [dataclasses.replace(p, rtk_flag=34, rtk_std_m=(0.0, 0.0, 0.0)) for p in ph]  # zeros: not stated
    assert (photo_error_model(flt).shared_h_m, photo_error_model(flt).shared_v_m) == GNSS_FLOAT_M[:2]
    mixed = [*fixed[:-1], ph[-1]]  # as good as its worst photo
    assert photo_error_model(mixed).shared_h_m == GNSS_PLAIN_M[0]
    assert "RTK fixed (RtkStdLon/Lat/Hgt)" in photo_error_model(mixed).source


def test_no_laser(photos):
    ph, _ = photos
    m = photo_error_model([dataclasses.replace(p, lrf_status="") for p in ph])
    assert m.source.endswith("no laser")


def test_locate_adds_the_shared_offset_to_the_mle(photos):
    from pipeline.locate import locate_photos

    ph, flight = photos
    m = photo_error_model(ph)
    loc = locate_photos(ph, flight.marks_px, errors=m, methods=["mle"])
    none = dataclasses.replace(m, shared_h_m=0.0, shared_v_m=0.0)
    bare = locate_photos(ph, flight.marks_px, errors=none, methods=["mle"])
    a, b = loc.estimates["mle"], bare.estimates["mle"]
    np.testing.assert_allclose(a.position_m, b.position_m, atol=1e-9)  # the offset moves nothing, only the cov
    np.testing.assert_allclose(np.asarray(a.covariance_m2) - np.asarray(b.covariance_m2),
                               np.diag([1.5 ** 2, 1.5 ** 2, 15.0 ** 2]), atol=1e-9)
    assert a.extras["cep50_m"] > b.extras["cep50_m"]
    assert a.extras["error_model"]["source"] == m.source
    assert a.extras["ellipsoid"]["semi_axes_1sigma_m"][-1] > 14.0


def test_terrain_prior_sigma_grows_by_the_shared_vertical_offset(photos):
    from pipeline.locate import mle_options

    m = photo_error_model(photos[0])
    o = mle_options(m, terrain=(abs, 5.0))
    assert o["terrain"] == (abs, pytest.approx(np.hypot(5.0, 15.0)))
    assert o["bias_prior_deg"] == COMPASS_BIAS_DEG
