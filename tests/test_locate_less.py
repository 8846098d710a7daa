"""`ridgeloc locate` with less (docs/locate.md, "Answers with less", "Photos as they reach the user"): the `ground`
method on level ground, the image rotation of re-saved photos, and the marks file of `ridgeloc mark`."""

from __future__ import annotations

import json

import numpy as np
import pytest

from pipeline.cli import main as cli_main
from pipeline.errors import InputError
from pipeline.geometry.frames import enu_from_lla
from pipeline.geometry.geoid import geoid_undulation_m
from pipeline.ingest.photo import read_photo_checked, read_photos
from pipeline.locate import GroundAssumption, image_rotations, locate_photos
from support.maker_photos import write_maker_photo

LAT, LON = 46.5, 7.5


def test_ground_at_a_stated_height_puts_the_centre_ray_where_geometry_says(tmp_path):
    """A camera 300 m above level ground looking 45 deg down towards the north: the image centre's ray meets the
    ground ~300 m north (the ellipsoid's curve adds centimetres), at the ground's height; the answer carries the
    assumption and an uncertainty in which the ground's 2 m and the camera's 15 m altitude offset dominate."""
    photo = write_maker_photo(tmp_path / "p.jpg", "parrot", yaw=0.0, pitch=-45.0, lat=LAT, lon=LON, alt=800.0,
                              size=(640, 480))
    loc = locate_photos([read_photo_checked(photo)], methods=["ground"], ground=GroundAssumption("height", 500.0))
    e = loc.estimates["ground"]
    lat, lon, h = loc.views.lla(e.position_m)
    assert h == pytest.approx(500.0 + geoid_undulation_m(LAT, LON), abs=1e-3)
    d = enu_from_lla(lat, lon, h, (LAT, LON, h))
    assert d[0] == pytest.approx(0.0, abs=0.01) and d[1] == pytest.approx(300.0, abs=0.1)
    sd = np.sqrt(np.diag(e.covariance_m2))
    # first order by hand, ground distance x = h / tan(depression), h = 300 m, 45 deg: along the ray a vertical
    # error v moves the hit by v / tan(45) = v (v = hypot(2 m ground, 15 m altitude offset)), a depression error
    # d by h / sin^2(45) d = 600 m/rad d (d: the tilt 0.5 and noise 0.3 deg, and 2 px of a 443.8 px focal length:
    # 24 mm equivalent over an 800 px diagonal); across it the heading's 3 deg bias and 0.3 deg noise at 300 m and
    # 2 px at the 424 m slant range; both ways the camera's 1.5 m
    f = 24.0 * 800.0 / np.hypot(36.0, 24.0)
    along = np.sqrt(np.hypot(2.0, 15.0) ** 2 + (600 * np.radians(np.hypot(0.5, 0.3))) ** 2 + (600 * 2 / f) ** 2
                    + 1.5 ** 2)
    across = np.sqrt((300 * np.radians(np.hypot(3.0, 0.3))) ** 2 + (300 * np.sqrt(2) * 2 / f) ** 2 + 1.5 ** 2)
    assert sd[1] == pytest.approx(along, rel=0.01) and sd[0] == pytest.approx(across, rel=0.01)
    assert sd[2] == pytest.approx(2.0)
    assert "a weaker answer: level ground at the stated 500 m" in e.extras["assumption"]


def test_take_off_ground_needs_the_height_above_take_off(tmp_path):
    parrot = read_photo_checked(write_maker_photo(tmp_path / "p.jpg", "parrot"))  # no relative altitude
    with pytest.raises(InputError, match=r"--ground takeoff needs .* --ground-height-m") as exc:
        locate_photos([parrot], methods=["ground"], ground=GroundAssumption("takeoff"))
    assert "\n" not in str(exc.value) and parrot.path in str(exc.value)
    autel = read_photo_checked(write_maker_photo(tmp_path / "a.jpg", "autel-dji", pitch=-45.0, alt=580.0))
    loc = locate_photos([autel], methods=["ground"], ground=GroundAssumption("takeoff"))
    assert loc.views.lla(loc.estimates["ground"].position_m)[2] == pytest.approx(500.0, abs=1e-3)  # 580 - 80


def test_the_cli_labels_the_weaker_answer(tmp_path, capsys):
    photo = write_maker_photo(tmp_path / "a.jpg", "autel-dji", pitch=-45.0, alt=580.0)
    cli_main(["locate", str(photo), "--ground", "takeoff", "--ground-sigma-m", "8"])
    out = capsys.readouterr().out
    assert "ground" in out and "note: ground: level ground at the take-off point's height" in out
    assert "within 8 m (1 sigma)" in out and "a weaker answer" in out
    assert cli_main(["locate", str(photo), "--ground-sigma-m", "8"]) != 0
    assert "--ground-sigma-m is the assumed ground's error" in capsys.readouterr().err


def test_the_weaker_answer_is_the_answer_when_nothing_else_locates(tmp_path, capsys):
    """80 m above the take-off ground, looking nearly straight down, the ground assumed within 8 m: the answer is
    `ground`, its CE90 holding the assumed ground's error. That error moves the answer as a whole, as a DEM's own
    error moves `dem`'s, so it does not make the one ray's geometry undetermined (it did: +-23 m at 95 % against
    a quarter of the 80 m, and the target was not located)."""
    photo = write_maker_photo(tmp_path / "a.jpg", "autel-dji", pitch=-85.0, alt=580.0)
    assert cli_main(["locate", str(photo), "--ground", "takeoff", "--ground-sigma-m", "8", "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    answer = doc["answer"]
    assert answer["status"] == "located" and answer["method"] == "ground"
    # its CE90 is the whole covariance's, the assumed ground's error and the shared position offset included
    assert answer["ce90_m"] == pytest.approx(doc["estimates"]["ground"]["cep90_m"], rel=1e-3)


def test_one_photo_without_laser_dem_or_ground_names_the_ways_to_an_answer(tmp_path, capsys):
    photo = write_maker_photo(tmp_path / "a.jpg", "autel-dji", pitch=-85.0, alt=580.0)
    assert cli_main(["locate", str(photo)]) == 1
    err = capsys.readouterr().err
    assert "one line of sight fixes a direction, not a point" in err and "locate's --dem" in err
    assert "--ground takeoff" in err  # what this photo needs, with the command that does it


def test_a_ray_above_the_horizon_misses_the_ground_in_one_line(tmp_path):
    photo = read_photo_checked(write_maker_photo(tmp_path / "p.jpg", "parrot", pitch=5.0))
    loc = locate_photos([photo], methods=["ground"], ground=GroundAssumption("height", 100.0))
    status, reason = loc.unsolved["ground"]
    assert status == "degenerate" and "points above the horizon" in reason and "\n" not in reason


def test_the_last_line_names_the_one_method_that_could_run(tmp_path, capsys):
    """The ground ray points above the horizon: the last line says so (not the MLE's want of a second pixel, not
    an estimates.csv that `locate` without -o never writes)."""
    photo = write_maker_photo(tmp_path / "p.jpg", "parrot", pitch=5.0)
    assert cli_main(["locate", str(photo), "--ground-height-m", "100"]) == 1
    out = capsys.readouterr()
    err = out.err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("ridgeloc: error: the target is not located: ground: ")
    assert "points above the horizon" in err[0]
    assert "estimates.csv" not in out.out + out.err


# ---- the image rotation of re-saved photos ----------------------------------------------------------------

def _pair(tmp_path, software, yaws=(0.0, 0.0)):
    """Two photos 40 m apart, 100 m up, both looking 60 deg down (headings `yaws`) at about a point between and
    ahead of them, and the point's pixel in each (projected with the photos' own views)."""
    from pipeline.ingest.photo_views import photo_views

    paths = [write_maker_photo(tmp_path / f"{k}.jpg", "parrot", yaw=yaw, pitch=-60.0, lat=LAT, lon=lon, alt=600.0,
                               size=(640, 480), software=software, model="test camera")
             for k, (yaw, lon) in enumerate(zip(yaws, (LON - 0.00026, LON + 0.00026), strict=True))]
    photos, _ = read_photos(paths)
    views = photo_views(photos)
    target = enu_from_lla(LAT + 0.0005, LON, 500.0 + geoid_undulation_m(LAT, LON), views.origin_lla)
    x = np.einsum("nij,j->ni", views.P, np.append(target, 1.0))
    return photos, x[:, :2] / x[:, 2:]


def test_photos_not_re_saved_are_taken_as_captured(tmp_path):
    photos, px = _pair(tmp_path, None)
    rot, note = image_rotations(photos, px)
    assert rot.tolist() == [0, 0] and note is None


def test_re_saved_photos_turned_by_180_are_found_from_two_marks(tmp_path):
    photos, px = _pair(tmp_path, "Microsoft Windows Photo Viewer 10.0")
    rot, note = image_rotations(photos, px)
    assert rot.tolist() == [0, 0] and "image rotation 0 deg" in note
    turned = np.array([[p.width_px - 1, p.height_px - 1] for p in photos]) - px  # the files turned after capture
    rot, note = image_rotations(photos, turned)
    assert rot.tolist() == [180, 180] and "image rotation 180 deg" in note
    loc = locate_photos(photos, turned, methods=["dlt"])
    truth = enu_from_lla(LAT + 0.0005, LON, 500.0 + geoid_undulation_m(LAT, LON), loc.views.origin_lla)
    assert np.linalg.norm(loc.estimates["dlt"].position_m - truth) < 0.05


def test_a_pair_whose_turned_rays_also_meet_is_refused(tmp_path):
    """Two cameras turned towards each other by 10 deg, symmetric about the point: the rays mirrored by a 180 deg
    turn of both images meet too, in front of both cameras: the rays cannot tell, so the user is asked."""
    photos, px = _pair(tmp_path, "Microsoft Windows Photo Viewer 10.0", yaws=(10.0, -10.0))
    with pytest.raises(InputError, match="rays do not tell"):
        image_rotations(photos, px)
    assert image_rotations(photos, px, stated=0)[0].tolist() == [0, 0]


def test_one_re_saved_photo_off_centre_is_refused_and_its_centre_is_not(tmp_path):
    photos, px = _pair(tmp_path, "Adobe Photoshop 25.0")
    with pytest.raises(InputError, match=r"re-saved after capture by 'Adobe Photoshop 25\.0'.*--image-rotation 0 "
                                         r"or 180") as exc:
        image_rotations(photos[:1], px[:1])
    assert "\n" not in str(exc.value) and photos[0].path in str(exc.value)
    centre = [[(photos[0].width_px - 1) / 2, (photos[0].height_px - 1) / 2]]
    assert image_rotations(photos[:1], centre)[0].tolist() == [0]
    assert image_rotations(photos[:1], px[:1], stated=180)[0].tolist() == [180]


# ---- the marks file of `ridgeloc mark` ---------------------------------------------------------------------

def test_locate_reads_the_mark_pages_csv_of_one_target(tmp_path, capsys):
    photos, px = _pair(tmp_path, None)
    csv = tmp_path / "marks.csv"
    csv.write_text("name,frame_or_image,x_px,y_px\n" + "".join(
        f"cairn,{p.name},{u:.3f},{v:.3f}\n" for p, (u, v) in zip(photos, px, strict=True)))
    cli_main(["locate", *(p.path for p in photos), "--marks", str(csv), "--json"])
    doc = json.loads(capsys.readouterr().out)
    assert doc["estimates"]["dlt"]["lat_deg"] == pytest.approx(LAT + 0.0005, abs=1e-6)
    csv.write_text(csv.read_text() + f"mast,{photos[0].name},10,10\n")
    assert cli_main(["locate", *(p.path for p in photos), "--marks", str(csv)]) != 0
    err = capsys.readouterr().err
    assert "holds 2 targets (cairn, mast): locate takes one" in err and len(err.strip().splitlines()) == 1


def test_photos_without_marks_or_laser_are_told_to_mark_the_target(tmp_path, capsys):
    """Several photos, no mark, no laser: each image centre is another ground point. The line says to mark the
    target (as `ridgeloc run` of the same photos does), not to fly around it, and targets.csv gives the same reason."""
    (tmp_path / "photos").mkdir()
    for k, lon in enumerate((LON - 0.0003, LON + 0.0003)):
        write_maker_photo(tmp_path / "photos" / f"P{k}.jpg", "parrot", yaw=0.0, pitch=-60.0, lat=LAT, lon=lon,
                          size=(640, 480))
    assert cli_main(["locate", str(tmp_path / "photos"), "-o", str(tmp_path / "out")]) == 1
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 1 and err[0].startswith(
        "ridgeloc: error: the target is not located: the target is not marked (--marks, --pixel), so each photo's "
        "image centre is taken")
    assert "the target is not marked" in (tmp_path / "out" / "targets.csv").read_text()
    # a marked pixel, even the same in both photos, is the user's statement: its reason is the geometry's
    assert cli_main(["locate", str(tmp_path / "photos"), "--pixel", "320", "240"]) == 1
    assert "not marked" not in capsys.readouterr().err


def test_photos_of_different_places_are_refused_in_one_line(tmp_path, capsys):
    """A DJI photo of Brighton and a Teal photo of Utah (1,735 km apart on the WGS84 geodesic) are no one target's
    photos: refused in one line naming both, before any method runs (the MLE answered +-92875 km), and nothing
    written."""
    from pathlib import Path

    shared = Path(__file__).resolve().parents[2] / "shared" / "photos"
    a, b = shared / "brighton" / "DJI_0024.JPG", shared / "makers" / "teal2_img_ir_00015.jpg"
    if not (a.is_file() and b.is_file()):
        pytest.skip("../shared/photos absent (the shared read-only material is not beside this checkout)")
    assert cli_main(["locate", str(a), str(b), "-o", str(tmp_path / "out")]) == 1
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "DJI_0024.JPG and teal2_img_ir_00015.jpg were taken 1,735 km apart" in err
    assert not (tmp_path / "out").exists()
    photos = [read_photo_checked(a), read_photo_checked(b)]
    locate_photos([photos[0]])  # each site alone is no error of this kind
    with pytest.raises(InputError, match="1,735 km apart"):
        locate_photos(photos, pixel_px=[[100.0, 100.0], [50.0, 50.0]])
    locate_photos(photos, pixel_px=[[100.0, 100.0], [np.nan, np.nan]], rotation_deg=0)  # the far one unmarked
