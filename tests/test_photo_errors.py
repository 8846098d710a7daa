"""The photo error model by source type (pipeline/photo_errors.py) and its use by `locate`: RtkFlag / RtkStd* pick
the position sigmas, the laser's sigma follows DJI's spec at the longest range, the photos' times split the
wandering GNSS and heading errors between the shared and the per-photo parts, the shared offset enters the MLE's
covariance and the terrain prior's sigma."""

import dataclasses

import numpy as np
import pytest

from pipeline.ingest.photo import read_photos
from pipeline.photo_errors import (
    ATTITUDE_NOISE_DEG,
    ATTITUDE_WANDER_DEG,
    COMPASS_BIAS_DEG,
    GNSS_FIXED_M,
    GNSS_FLOAT_M,
    GNSS_PLAIN_M,
    WANDER_TAU_S,
    photo_error_model,
    shared_fraction,
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
    assert (m.shared_h_m, m.shared_v_m) == (1.5, 15.0)  # docs/locate.md, "Error model"
    # five photos 20 s apart (80 s): the wandering errors are nearly all shared, the per-photo sigmas close to the
    # photo-to-photo noise alone (0.5 m, 0.3 deg)
    assert m.span_s == pytest.approx(80.0) and m.wander_shared > 0.95
    assert 0.5 < m.sigma.position_m < 0.6 and 0.3 < m.sigma.attitude_deg < 0.32
    assert m.bias_prior_deg == 3.0
    longest = max(p.lrf_range_m for p in ph)
    assert m.sigma.range_m == pytest.approx(0.2 + 0.0015 * longest)
    assert m.source == "GNSS without RTK, laser"


def test_rtk_flags_and_std_tags(photos):
    ph, _ = photos
    fixed = [dataclasses.replace(p, rtk_flag=50, rtk_std_m=(0.02, 0.03, 0.05)) for p in ph]
    m = photo_error_model(fixed)
    assert m.shared_h_m == 0.03 and m.sigma.position_m == pytest.approx(0.03, rel=0.02)  # 80 s: wander shared
    assert m.shared_v_m == GNSS_FIXED_M[1]  # RtkStdHgt below the datum's floor
    no_std = [dataclasses.replace(p, rtk_flag=50, rtk_std_m=None) for p in ph]
    assert photo_error_model(no_std).shared_h_m == GNSS_FIXED_M[0]
    flt = [dataclasses.replace(p, rtk_flag=34, rtk_std_m=(0.0, 0.0, 0.0)) for p in ph]  # zeros: not stated
    assert (photo_error_model(flt).shared_h_m, photo_error_model(flt).shared_v_m) == GNSS_FLOAT_M[:2]
    mixed = [*fixed[:-1], ph[-1]]  # as good as its worst photo
    assert photo_error_model(mixed).shared_h_m == GNSS_PLAIN_M[0]
    assert "RTK fixed (RtkStdLon/Lat/Hgt)" in photo_error_model(mixed).source


def test_shared_fraction_of_a_wandering_error():
    """The mean correlation exp(-|dt| / tau) over the pairs of photos, by hand."""
    s = 1_000_000_000
    assert shared_fraction([5 * s]) == 1.0  # one photo: nothing to split
    assert shared_fraction([7 * s, 7 * s, 7 * s]) == pytest.approx(1.0)  # taken at once
    assert shared_fraction([0, int(WANDER_TAU_S) * s]) == pytest.approx(np.exp(-1.0))
    three = [0, int(WANDER_TAU_S) * s, 2 * int(WANDER_TAU_S) * s]  # pairs 1, 1 and 2 tau apart
    assert shared_fraction(three) == pytest.approx((2 * np.exp(-1.0) + np.exp(-2.0)) / 3)
    assert shared_fraction([0, None]) == 0.0  # a photo of unknown time: taken as far apart
    many = [i * 60 * s for i in range(2000)]  # a third of a day, thinned to 512 photos for the pairs
    assert 0.0 < shared_fraction(many) < 0.05


def test_the_photos_times_split_the_wandering_errors(photos):
    ph, _ = photos
    h, v, per = GNSS_PLAIN_M
    unknown = photo_error_model([dataclasses.replace(p, t_ns=None) for p in ph])
    # no times: the wander counts per photo in full, the shared parts stay whole
    assert unknown.sigma.position_m == pytest.approx(np.hypot(per, h))
    assert unknown.sigma.attitude_deg == pytest.approx(np.hypot(ATTITUDE_NOISE_DEG, ATTITUDE_WANDER_DEG))
    assert (unknown.shared_h_m, unknown.shared_v_m, unknown.bias_prior_deg) == (h, v, COMPASS_BIAS_DEG)
    assert unknown.span_s is None and unknown.wander_shared == 0.0
    # two flights a day apart (three photos, then two): 4 of the 10 pairs share the wander (the pairs within a
    # flight, 20-40 s apart: exp(-20 s / tau) ~ 0.99), the other 6 nothing
    day = [dataclasses.replace(p, t_ns=p.t_ns + (86_400 * 10**9 if i >= 3 else 0)) for i, p in enumerate(ph)]
    apart = photo_error_model(day)
    assert apart.wander_shared == pytest.approx(0.4, abs=0.01)
    assert apart.sigma.position_m == pytest.approx(np.hypot(per, h * np.sqrt(0.6)), rel=0.01)
    assert apart.span_s == pytest.approx(86_400 + 80.0)
    # one photo alone: the photo-to-photo noise only
    one = photo_error_model(ph[:1])
    assert (one.sigma.position_m, one.sigma.attitude_deg) == (per, ATTITUDE_NOISE_DEG)
    # RTK fixed: the wander is the RtkStd's size, centimetres either way; the heading's is the compass's
    fixed = photo_error_model([dataclasses.replace(p, rtk_flag=50, rtk_std_m=(0.02, 0.03, 0.05), t_ns=None)
                               for p in ph])
    assert fixed.sigma.position_m == pytest.approx(np.hypot(0.03, 0.03))
    assert fixed.sigma.attitude_deg == pytest.approx(unknown.sigma.attitude_deg)


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


def test_the_shared_offset_moves_the_answer_but_leaves_it_determined(tmp_path):
    """A photo flight close to its target without laser or DEM: the altitude datum's 15 m (95 %: +-42 m) alone is
    more than a quarter of the 100 m to the cameras, yet the lines of sight meet well; the answer rule leaves the
    offset every camera shares out of its determination test (it moves the point with the cameras) and keeps it in
    the answer's covariance. The same covariance judged as a whole (a video flight's way) is not determined."""
    from pipeline.answer import DETERMINED_REL, judge
    from pipeline.locate import locate_photos, photo_answer

    fl = simulate_photo_flight(PhotoFlightSpec(seed=5, laser=False, mark_offset_px=100.0, range_m=(70.0, 90.0),
                                               height_above_m=(40.0, 60.0)))
    write_photo_flight(fl, tmp_path)
    ph, bad = read_photos([tmp_path])
    assert not bad
    loc = locate_photos(ph, fl.marks_px)
    answer = photo_answer(loc)
    assert answer.located and answer.method == "mle", answer.reason
    cov = np.asarray(answer.covariance_m2)
    assert cov[2, 2] >= 15.0 ** 2  # the datum offset is in the answer's uncertainty
    dist = float(np.median(np.linalg.norm(loc.obs.platform_m - answer.position_m, axis=1)))
    assert np.sqrt(7.815 * 15.0 ** 2) > DETERMINED_REL * dist  # the offset alone would fail the test
    whole = judge("mle", loc.estimates["mle"], None, loc.obs, loc.views.origin_lla, cov, "estimator")
    assert not whole.determined and "does not determine" in whole.reason
