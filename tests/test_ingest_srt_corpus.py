"""DJI SRT: every layout of the corpus in tests/data/srt and the six real files in ../shared/srt are read into
positions, attitudes, field of view and wall-clock times. Expected values are read off the fixture text."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from pipeline.ingest import read_flight
from pipeline.ingest.inspect import format_result, inspect_paths
from pipeline.ingest.srt import fov_from_focal

DATA = Path(__file__).parent / "data" / "srt"
REAL = Path(__file__).resolve().parents[1].parent / "shared" / "srt"  # ../shared from the repo root
MS = 10**6


def _naive_ns(stamp: str) -> int:
    return int(np.datetime64(stamp, "ns").astype(np.int64))


def _hfov(f35_mm: float) -> float:
    """Horizontal field of a 4:3 sensor for a 35 mm-equivalent focal length (36 x 24 mm diagonal 43.27 mm)."""
    return math.degrees(2 * math.atan(math.hypot(36, 24) / (2 * f35_mm) * 0.8))


# file: (n positions, first t_ns, first lat, first lon, first alt, datum, attitude?, gimbal?, focal mm x zoom
# of the first cue with a focal length (None: no field of view), wall time of the first cue with a position
# (None: no date))
CORPUS = {
    "mavic3_bracketed.SRT": (5, 33 * MS, 45.463110, 9.188220, 132.4, "amsl", False, False, 24.0,
                             "2023-01-14T12:51:03.637"),
    "mavic2zoom_longtitude_crlf.SRT": (4, 0, 31.452012, 74.398751, 213.980, "amsl", False, False, 24.0,
                                       "2020-04-02T15:19:58.720764"),
    "p4rtk_gps_lon_lat_pry.SRT": (3, 0, -34.237920, -58.851740, 85.8, "relative", True, True, None, None),
    "mavicpro_home_baro.SRT": (3, 2000 * MS, -20.2533, 149.0251, 2.0, "relative", False, False, None,
                               "2017-08-05T14:11:51"),
    "m300_multiline_truncated.SRT": (3, 0, 49.125741, 14.634775, 535.401, "amsl", True, True, 94.0,
                                     "2024-05-20T15:06:07.221"),
    "avata_gimbal.SRT": (3, 0, 53.365080, 6.460739, -124.744, "amsl", False, True, 28.0, "2026-05-27T13:10:00.015"),
    "enterprise_gps_lat_lon_alt.SRT": (3, 0, 47.385200, 8.652100, 512.30, "amsl", False, False, 31.7,
                                       "2021-06-01T10:00:00.100"),
    "mini2_na_noalt_ffmpeg.srt": (2, 33 * MS, 41.424721, 2.234156, 117.1, "amsl", False, False, 24.0,
                                  "2022-08-07T13:40:40.807808"),
    "joined_mavicpro_mavic3.SRT": (4, 0, 47.3852, 8.6521, 30.0, "relative", False, False, 24.0,
                                   "2021-06-01T10:00:00"),
}


def test_corpus_lists_every_fixture():
    assert sorted(p.name for p in DATA.iterdir() if p.suffix.lower() == ".srt") == sorted(CORPUS)


@pytest.mark.parametrize("name", sorted(CORPUS))
def test_every_layout_is_read(name):
    n, t0, lat, lon, alt, datum, att, gim, focal, wall = CORPUS[name]
    log = read_flight(DATA / name)
    p = log.position
    assert p.t_ns.size == n and p.t_ns[0] == t0 and p.clock == "video" and p.source == name
    assert (p.lat_deg[0], p.lon_deg[0], p.alt_m[0], p.alt_datum) == pytest.approx((lat, lon, alt, datum))
    assert (log.attitude is not None, log.gimbal is not None) == (att, gim)
    if focal is None:
        assert log.field_of_view is None
    else:
        assert log.field_of_view.hfov_deg[0] == pytest.approx(_hfov(focal), abs=1e-9)
    if wall is None:
        assert not log.clock_links
    else:
        (link,) = log.clock_links
        assert (link.a, link.b) == ("video", "local")
        assert link.a_ns[0] == t0 and link.b_ns[0] == _naive_ns(wall)
    assert (np.diff(p.t_ns) >= 0).all()


def test_layout_details():
    log = read_flight(DATA / "mavic3_bracketed.SRT")
    assert any("1 cues without a GPS fix" in w for w in log.warnings)
    fov = log.field_of_view  # dzoom_ratio 1.00 for cues 2-3, 2.00 for cues 4-6
    np.testing.assert_allclose(fov.hfov_deg, [_hfov(24)] * 2 + [_hfov(48)] * 3)
    log = read_flight(DATA / "mavic2zoom_longtitude_crlf.SRT")  # focal_len 240, 240, 360, 480 (x10)
    np.testing.assert_allclose(log.field_of_view.hfov_deg, [_hfov(24), _hfov(24), _hfov(36), _hfov(48)])
    np.testing.assert_allclose(log.position.alt_m, [213.980, 213.981, 213.982, 213.983])

    log = read_flight(DATA / "p4rtk_gps_lon_lat_pry.SRT")  # F.PRY (2.7, -7.0, 110.1), G.PRY (-24.4, 0, 110.4)
    ypr = Rotation.from_quat(log.attitude.quat_wxyz[0], scalar_first=True).as_euler("ZYX", degrees=True)
    np.testing.assert_allclose(ypr, [110.1, 2.7, -7.0], atol=1e-9)
    ypr = Rotation.from_quat(log.gimbal.quat_wxyz[0], scalar_first=True).as_euler("ZYX", degrees=True)
    np.testing.assert_allclose(ypr, [110.4, -24.4, 0.0], atol=1e-9)

    log = read_flight(DATA / "m300_multiline_truncated.SRT")  # drone (y, p, r) = (-88.3, 6.0, 0.7)
    ypr = Rotation.from_quat(log.attitude.quat_wxyz[0], scalar_first=True).as_euler("ZYX", degrees=True)
    np.testing.assert_allclose(ypr, [-88.3, 6.0, 0.7], atol=1e-9)
    assert log.streams[0].count == 4  # the cut-off fourth cue is counted, not read
    assert any("1 cue(s) cut off inside the position" in w for w in log.warnings)
    assert not any("GPS fix" in w for w in log.warnings)

    log = read_flight(DATA / "avata_gimbal.SRT")
    pitch = Rotation.from_quat(log.gimbal.quat_wxyz, scalar_first=True).as_euler("ZYX", degrees=True)[:, 1]
    np.testing.assert_allclose(pitch, [0, -10, -20], atol=1e-9)

    log = read_flight(DATA / "enterprise_gps_lat_lon_alt.SRT")  # dzoom_ratio 1, 2, 3 at 31.7 mm
    np.testing.assert_allclose(log.field_of_view.hfov_deg, [_hfov(31.7 * z) for z in (1, 2, 3)])
    np.testing.assert_allclose(log.position.lat_deg, [47.385200, 47.385201, 47.385202])

    log = read_flight(DATA / "mini2_na_noalt_ffmpeg.srt")
    np.testing.assert_array_equal(log.position.t_ns, [33 * MS, 99 * MS])
    assert any("1 cues without a GPS fix" in w for w in log.warnings)
    assert any("1 of 3 cues without an altitude skipped" in w for w in log.warnings)

    log = read_flight(DATA / "joined_mavicpro_mavic3.SRT")  # times 0, 1 | 0, 1 s -> 0, 1, 2, 3 s
    np.testing.assert_array_equal(log.position.t_ns, np.array([0, 1, 2, 3]) * 10**9)
    np.testing.assert_allclose(log.position.alt_m, [30, 31, 32, 33])
    np.testing.assert_allclose(log.position.lat_deg, [47.3852, 47.3853, 47.3854, 47.3855])
    assert any("start again" in w for w in log.warnings)
    assert any("lack the absolute altitude" in w for w in log.warnings)


def test_utc_offset_puts_the_wall_clock_on_unix():
    log = read_flight(DATA / "avata_gimbal.SRT", mapping={"srt": {"utc_offset_h": 2}})
    (link,) = log.clock_links
    assert link.b == "unix" and link.b_ns[0] == _naive_ns("2026-05-27T11:10:00.015")


def test_fov_matches_dji_published_figures():
    """Mavic 2 Zoom specification: FOV about 83 deg at 24 mm and 48 deg at 48 mm (diagonal, 4:3 photo)."""
    h, v = fov_from_focal(np.array([24.0, 48.0]), np.array([1.0, 1.0]), (4, 3), (4, 3))
    diag = np.degrees(2 * np.arctan(np.hypot(np.tan(np.radians(h) / 2), np.tan(np.radians(v) / 2))))
    np.testing.assert_allclose(diag, [83, 48], atol=1.5)
    h16, v16 = fov_from_focal(np.array([24.0]), np.array([np.nan]), (4, 3), (16, 9))
    assert h16[0] == pytest.approx(h[0]) and v16[0] < v[0]  # 16:9 video keeps the width, crops the height


REAL_FILES = {  # file: (cues read, first lat, first lon, altitude datum, focal length present)
    "juanirache_p4_rtk.SRT": (-34.237922, -58.851745, "relative", False),
    "juanirache_mavic_pro.SRT": (-20.2533, 149.0251, "relative", False),
    "juanirache_mavic_air2.srt": (41.420684, 2.162162, "amsl", True),
    "juanirache_m2zoom.SRT": (31.452012, 74.398751, "amsl", True),
    "ruz76_DJI_M300RTK.SRT": (49.125749, 14.634775, "amsl", True),
    "callmarcus_Avata360_clip.SRT": (53.365080, 6.460739, "amsl", True),
}


@pytest.mark.parametrize("name", sorted(REAL_FILES))
def test_real_files(name):
    lat, lon, datum, fov = REAL_FILES[name]
    log = read_flight(REAL / name)
    assert (log.position.lat_deg[0], log.position.lon_deg[0], log.position.alt_datum) == pytest.approx(
        (lat, lon, datum))
    assert (log.field_of_view is not None) == fov
    assert not [w for w in log.warnings if "skipped" in w]


def test_real_mavic2_zoom_changes_the_field_of_view():
    """The Mavic 2 Zoom file zooms from focal_len 240 to 480 (24 -> 48 mm): the tangent of half the field halves."""
    fov = read_flight(REAL / "juanirache_m2zoom.SRT").field_of_view
    tan_half = np.tan(np.radians(fov.hfov_deg) / 2)
    assert tan_half.max() / tan_half.min() == pytest.approx(2.0)
    assert fov.hfov_deg[0] == pytest.approx(_hfov(24.0)) and fov.t_ns.size == 7113


def test_inspect_shows_the_field_of_view_source():
    (result,) = inspect_paths([str(DATA / "mavic3_bracketed.SRT")])
    text = format_result(result)
    assert "field_of_view 5 from mavic3_bracketed.SRT (video clock)" in text
