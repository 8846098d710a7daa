"""Photo times (pipeline/ingest/photo.py, docs/ingest.md "Time"): EXIF DateTimeOriginal with OffsetTimeOriginal,
checked against GPSDateStamp/GPSTimeStamp; without the offset the GPS time stamp gives the time zone; a camera
clock off by no whole zone, or no DateTimeOriginal, leaves the GPS time."""

import pytest
from PIL import Image

from pipeline.ingest.photo import read_photo_checked
from pipeline.synth.photos import PhotoFlightSpec, simulate_photo_flight, write_photo_flight

T_UNIX = 1_700_000_000  # 2023-11-14 22:13:20 UTC: the synth's first photo


@pytest.fixture
def photo(tmp_path):
    write_photo_flight(simulate_photo_flight(PhotoFlightSpec(seed=2, n_photos=1)), tmp_path)
    return tmp_path / "DJI_0001.JPG"


def _retag(path, dto=None, offset=None, gps_time=None, gps_date="2023:11:14"):
    """The photo with DateTimeOriginal / OffsetTimeOriginal set (None: removed) and a GPS time stamp (h, m, s)."""
    with Image.open(path) as im:
        exif = im.getexif()
        xmp = im.info.get("xmp")
        pixels = im.copy()
    ex = exif.get_ifd(0x8769)
    for tag, value in ((36867, dto), (36881, offset)):
        if value is None:
            ex.pop(tag, None)
        else:
            ex[tag] = value
    if gps_time is not None:
        gps = exif.get_ifd(0x8825)
        gps[7], gps[29] = gps_time, gps_date
    pixels.save(path, "JPEG", exif=exif, xmp=xmp)


def test_offset_time_checked_against_gps_time(photo):
    _retag(photo, "2023:11:14 23:13:20", "+01:00", (22.0, 13.0, 20.0))
    p = read_photo_checked(photo)
    assert p.t_ns == p.gps_t_ns == T_UNIX * 10**9 and p.time_zone == "+01:00" and not p.warnings
    _retag(photo, "2023:11:14 23:13:20", "+01:00", (22.0, 14.0, 0.0))
    p = read_photo_checked(photo)
    assert p.t_ns == T_UNIX * 10**9  # DateTimeOriginal kept, the disagreement said
    assert any("differ by -40 s" in w for w in p.warnings)


def test_gps_time_gives_the_time_zone(photo):
    _retag(photo, "2023:11:14 16:43:21", None, (22.0, 13.0, 20.0))  # UTC-05:30, one second apart
    p = read_photo_checked(photo)
    assert p.time_zone == "-05:30 (from the GPS time stamp)"
    assert p.t_ns == (T_UNIX + 1) * 10**9  # DateTimeOriginal's own second, in UTC
    assert not p.warnings


def test_camera_clock_off_by_no_zone_and_no_datetimeoriginal(photo):
    _retag(photo, "2023:11:14 22:20:00", None, (22.0, 13.0, 20.0))
    p = read_photo_checked(photo)
    assert p.t_ns == T_UNIX * 10**9 and p.time_zone == "UTC (GPS time stamp)"
    assert any("+400 s from the GPS time stamp" in w for w in p.warnings)
    _retag(photo, None, None, (22.0, 13.0, 20.5))
    p = read_photo_checked(photo)
    assert p.t_ns == T_UNIX * 10**9 + 500_000_000 and p.time_zone == "UTC (GPS time stamp)"


def test_no_time_tags_at_all(photo):
    _retag(photo, None, None)
    p = read_photo_checked(photo)
    assert p.t_ns is None and p.gps_t_ns is None
    assert any("photos are ordered by name" in w for w in p.warnings)


def test_damaged_gps_time_is_no_time(photo):
    _retag(photo, "2023:11:14 22:13:20", None, (25.0, 0.0, 0.0), gps_date="2023:13:40")
    p = read_photo_checked(photo)
    assert p.gps_t_ns is None and p.time_zone == "unknown"


@pytest.mark.parametrize("offset, when", [(None, "2024-07-31 19:17 camera local time"),
                                          ("+02:00", "2024-07-31 17:17 UTC")])
def test_the_tak_remarks_call_a_time_without_a_zone_the_cameras_local_time(tmp_path, offset, when):
    """A photo's DateTimeOriginal without OffsetTimeOriginal or a GPS time is the camera's local clock (`inspect`
    says so): the CoT remarks ATAK shows must not call it UTC."""
    from pipeline.cli import main
    from support.maker_photos import write_maker_photo

    folder = tmp_path / "photos"
    folder.mkdir()
    write_maker_photo(folder / "P0.jpg", "parrot", yaw=0.0, pitch=-60.0, alt=900.0, size=(640, 480),
                      model="test camera", exif_extra=None if offset is None else {36881: offset})
    assert main(["locate", str(folder), "--ground-height-m", "800", "-o", str(tmp_path / "out")]) == 0
    (cot,) = (tmp_path / "out" / "cot").glob("*.cot")
    assert f"flight photos, {when}</remarks>" in cot.read_text()
