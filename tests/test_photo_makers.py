"""Photos of every maker (docs/ingest.md, "Drone photos: makers"): the readers on the real photos of
../shared/photos/makers against OpenAthena's published readings and answers for the same photos (an independent
implementation: Theta-Limited/OpenAthenaIOS, OpenAthenaIOSTests/TestDroneImage.swift and TestCalculations.swift at
commit 122fa9f2734828467d3dc2935b9b4f1c54855319), and each maker's convention on synthetic photos whose camera
direction is known."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from pipeline.cli import main as cli_main
from pipeline.errors import InputError
from pipeline.ingest.photo import read_photo_checked
from pipeline.ingest.photo_views import photo_views
from support.maker_photos import write_maker_photo

ROOT = Path(__file__).resolve().parents[1]
MAKERS = ROOT.parent / "shared" / "photos" / "makers"
needs_makers = pytest.mark.skipif(not MAKERS.is_dir(), reason="../shared/photos/makers is absent")


def optical_axis(photo) -> tuple[float, float]:
    """(azimuth from north, depression below the horizon) in degrees of the photo's optical axis (image centre)."""
    v = photo_views([photo])
    d = v.R_enu0_from_optical[0][:, 2]
    return math.degrees(math.atan2(d[0], d[1])) % 360.0, -math.degrees(math.asin(d[2]))


# ---- the real photos against OpenAthena's readings (TestDroneImage.swift): camera azimuth and depression -------

@needs_makers
@pytest.mark.parametrize("name, azimuth, depression, tol", [
    ("skydio-catilina.jpg", 127.444323, 7.468572, 0.01),  # testSkydioImageMetaData
    # testTeal2ImageMetaData (the visible-light photo of the same capture, same pose tags): OpenAthena adds the
    # camera's angles to the platform's; ridgeloc composes the rotations: 1.6 deg apart in azimuth at 58 deg down
    ("teal2_img_ir_00015.jpg", 319.002289, 58.19441, 2.0),
    # testParrotImageMetaData: Camera:Pitch 2.05 read, as Pix4D defines it, as 2.05 deg from nadir (87.95 down);
    # OpenAthena turns Camera:Roll (-2.39) about the optical axis, Pix4D (and ridgeloc) about the aircraft's
    # forward axis, which at nadir tilts the axis sideways: 3.15 deg off nadir, towards another azimuth
    ("parrot-1.jpg", None, 87.945918322, 1.2),
])
def test_the_optical_axis_is_the_one_openathena_reads(name, azimuth, depression, tol):
    photo = read_photo_checked(MAKERS / name)
    az, dep = optical_axis(photo)
    assert abs(dep - depression) < tol
    assert azimuth is None or abs((az - azimuth + 180) % 360 - 180) < tol


@needs_makers
def test_the_real_photos_positions_and_datums():
    sk = read_photo_checked(MAKERS / "skydio-catilina.jpg")
    assert (sk.maker, sk.alt_source, sk.alt_datum) == ("Skydio", "drone-skydio:AbsoluteAltitude", "amsl")
    assert (sk.lat_deg, sk.lon_deg, sk.alt_m) == pytest.approx((32.518935, -110.924547, 1034.44191), abs=1e-5)
    # the quaternion CameraOrientationQuatNED agrees with the Euler angles (no warning), the calibrated focal
    # length is scaled from the 4056 px frame to the 1500 px file, and Photoshop is named as having re-saved it
    assert not any("disagree" in w for w in sk.warnings)
    assert sk.intrinsics.fx_px == pytest.approx(2378.525221 * 1500 / 4056, rel=1e-4)
    assert "Photoshop" in sk.resaved_by
    teal = read_photo_checked(MAKERS / "teal2_img_ir_00015.jpg")
    assert (teal.maker, teal.alt_datum, teal.resaved_by) == ("Teal", "amsl", "")
    # the stated field of view, 31.53 deg over 640 px (a Boson 640's 12 um pixels behind 13.6 mm: 1133 px)
    assert teal.intrinsics.fx_px == pytest.approx(320 / math.tan(math.radians(31.534363 / 2)), rel=1e-6)
    parrot = read_photo_checked(MAKERS / "parrot-1.jpg")
    assert (parrot.maker, parrot.resaved_by) == ("Parrot", "")  # its Software 'Dragon 1.7.1' is firmware
    assert any("Pix4D" in w for w in parrot.warnings)


# ---- the real photos against OpenAthena's answers (TestCalculations.swift) ---------------------------------

@needs_makers
def test_the_image_centres_answers_agree_with_openathena(tmp_path):
    import sys

    sys.path.insert(0, str(ROOT / "scripts"))
    from photo_makers_check import OPENATHENA, centre_answer, compare, corner_registered_copy

    for name in ("skydio-catilina.jpg", "teal2_img_ir_00015.jpg"):
        dem, theirs = OPENATHENA[name]
        ours, refusal, cam, ray = centre_answer(MAKERS / name, MAKERS / dem)
        assert ours is not None, refusal
        dist, _along, across = compare(ours, theirs, cam, ray)
        # the DEM read as OpenAthena reads it (its tie point as the first post): the same answer within a metre
        shifted, *_ = centre_answer(MAKERS / name, corner_registered_copy(MAKERS / dem, tmp_path / dem))
        assert compare(shifted, theirs, cam, ray)[0] < 1.0
        # read as GDAL does (posts at pixel centres) they part along the ray only: half a post of terrain under a
        # ray 7.5 deg down (Skydio) moves its hit by 10 m; at 58 deg down (Teal) by half a metre
        assert abs(across) < 1.0
        assert dist < (12.0 if name.startswith("skydio") else 1.0)


@needs_makers
def test_parrot_1s_centre_ray_is_refused_in_one_line(capsys):
    rc = cli_main(["locate", str(MAKERS / "parrot-1.jpg"), "--dem", str(MAKERS / "parrot-1-dem.tiff"),
                   "--pixel", "959.5", "543.5", "--json"])
    out = capsys.readouterr()
    dem = json.loads(out.out)["estimates"]["dem"]
    assert rc == 1 and "lat_deg" not in dem and "\n" not in dem["reason"]
    assert "parrot-1.jpg pixel (959.5, 543.5): the ray starts below the DEM surface" in dem["reason"]
    assert len(out.err.strip().splitlines()) == 1
    # the last line names the one method that could run, with its reason (docs/locate.md)
    assert "not located: dem: parrot-1.jpg pixel (959.5, 543.5): the ray starts below the DEM surface" in out.err
    assert "estimates.csv" not in out.out + out.err  # locate without -o writes none


@needs_makers
def test_a_ray_above_the_terrain_is_the_reason_in_every_output(tmp_path, capsys):
    """Skydio's pixel near the top edge looks over the DEM: the answer's reason (the table, --json, targets.csv)
    is the one method that could run and its reason, as the last line says, not the MLE's want of a second pixel
    (a single photo was told to mark it again while the DEM said the ray never meets the ground)."""
    import csv

    args = ["locate", str(MAKERS / "skydio-catilina.jpg"), "--dem", str(MAKERS / "skydio-catilina-dem.tiff"),
            "--pixel", "750", "2", "--image-rotation", "0"]
    assert cli_main([*args, "--json"]) == 1
    out = capsys.readouterr()
    reason = json.loads(out.out)["answer"]["reason"]
    assert reason.startswith("dem: skydio-catilina.jpg pixel (750.0, 2.0): the ray never meets the ground")
    assert out.err.strip().splitlines()[-1] == f"ridgeloc: error: the target is not located: {reason}"
    assert cli_main([*args, "-o", str(tmp_path / "out")]) == 1
    table = capsys.readouterr().out
    assert f"NOT LOCATED: {reason}" in table and "mle" not in table.split("photo(s)")[0]
    with open(tmp_path / "out" / "targets.csv", newline="") as f:
        assert [r["reason"] for r in csv.DictReader(f)] == [reason]


@needs_makers
@pytest.mark.parametrize("name, dem", [("skydio-catilina.jpg", "skydio-catilina-dem.tiff"),
                                       ("teal2_img_ir_00015.jpg", "teal2.tiff")])
def test_locate_answers_each_photo_its_dem_covers(capsys, name, dem):
    photo = read_photo_checked(MAKERS / name)
    cli_main(["locate", str(MAKERS / name), "--dem", str(MAKERS / dem), "--pixel",
              str((photo.width_px - 1) / 2), str((photo.height_px - 1) / 2), "--json"])
    dem_row = json.loads(capsys.readouterr().out)["estimates"]["dem"]
    assert np.isfinite(dem_row["lat_deg"]) and dem_row["status"] == "closed_form"


@needs_makers
def test_skydio_off_centre_needs_the_rotation_stated_and_then_leaves_the_dem_as_openathena_says(capsys):
    """OpenAthena: the pixel at (0.25, 0.25) of the image throws (DEM out of bounds). Photoshop re-saved the file,
    so an off-centre pixel is refused until the rotation is stated; then the ray passes above the DEM."""
    args = ["locate", str(MAKERS / "skydio-catilina.jpg"), "--dem", str(MAKERS / "skydio-catilina-dem.tiff"),
            "--pixel", "374.5", "210.5"]
    assert cli_main(args) == 1
    assert "--image-rotation 0 or 180" in capsys.readouterr().err
    assert cli_main([*args, "--image-rotation", "0", "--json"]) == 1
    assert "never meets the ground within the DEM" in json.loads(capsys.readouterr().out)["estimates"]["dem"]["reason"]


# ---- each maker's convention on synthetic photos -----------------------------------------------------------

@pytest.mark.parametrize("maker, yaw, pitch, roll, azimuth, depression", [
    ("skydio", 127.4, -7.5, 0.2, 127.4, 7.5),
    ("skydio-resource", 300.0, -30.0, 0.0, 300.0, 30.0),
    ("parrot", 176.3, -78.4, -0.3, 176.3, 78.4),
    ("autel-dji", 2.4, -24.0, 0.0, 2.4, 24.0),
    ("autel-pix4d", 2.42, 66.04, 0.0, 2.42, 23.96),  # OpenAthena's Autel reading: Camera:Pitch 66.04 -> 23.96 down
    ("parrot-disco", 90.0, 0.0, 0.0, None, 90.0),  # Pix4D pitch 0: nadir
    ("autel-pix4d", 0.0, 90.0, 0.0, 0.0, 0.0),  # Pix4D pitch 90: forward, towards the north at yaw 0
])
def test_each_makers_angles_give_the_camera_direction(tmp_path, maker, yaw, pitch, roll, azimuth, depression):
    p = read_photo_checked(write_maker_photo(tmp_path / "p.jpg", maker, yaw, pitch, roll))
    az, dep = optical_axis(p)
    assert dep == pytest.approx(depression, abs=1e-6)
    if azimuth is not None:
        assert abs((az - azimuth + 180) % 360 - 180) < 1e-6


def test_pix4d_yaw_turns_the_top_of_a_nadir_image():
    """Pix4D: at pitch 0 (nadir), yaw 90 puts the image's top to the east."""
    from scipy.spatial.transform import Rotation

    from pipeline.ingest.photo_makers import gimbal_from_pix4d

    R = Rotation.from_euler("ZYX", gimbal_from_pix4d(90.0, 0.0, 0.0), degrees=True).as_matrix()  # gimbal FRD -> NED
    up_in_image = R @ np.array([0.0, 0.0, -1.0])  # image top = -z of the gimbal FRD frame (z to the image's bottom)
    np.testing.assert_allclose(up_in_image, [0.0, 1.0, 0.0], atol=1e-9)  # NED: east


def test_teal_camera_angles_are_relative_to_the_platform(tmp_path):
    """Camera pitched 50 deg down on a level platform heading 319 deg: the camera looks 50 deg down towards 319;
    a platform pitched 4 deg nose-down adds its pitch (about the same axis) to the camera's."""
    p = read_photo_checked(write_maker_photo(tmp_path / "a.jpg", "teal", 0.0, -50.0, 0.0, platform=(319.0, 0.0, 0.0)))
    assert optical_axis(p) == pytest.approx((319.0, 50.0), abs=1e-5)
    p = read_photo_checked(write_maker_photo(tmp_path / "b.jpg", "teal", 0.0, -50.0, 0.0, platform=(319.0, -4.0, 0.0)))
    assert optical_axis(p) == pytest.approx((319.0, 54.0), abs=1e-5)
    assert p.maker == "Teal" and p.intrinsics.source.startswith("stated field of view")


def test_makers_datums_and_relative_altitude(tmp_path):
    autel = read_photo_checked(write_maker_photo(tmp_path / "a.jpg", "autel-dji", alt=513.0))
    assert (autel.maker, autel.alt_datum, autel.alt_m, autel.relative_alt_m) == ("Autel", "ellipsoid", 513.0, 80.0)
    assert autel.takeoff_ground_m == pytest.approx(433.0)
    old = read_photo_checked(write_maker_photo(tmp_path / "b.jpg", "autel-pix4d"))
    assert (old.maker, old.alt_datum, old.alt_source) == ("Autel", "ellipsoid", "EXIF GPSAltitude")
    anafi = read_photo_checked(write_maker_photo(tmp_path / "c.jpg", "parrot"))
    assert (anafi.maker, anafi.alt_datum) == ("Parrot", "amsl")
    assert read_photo_checked(write_maker_photo(tmp_path / "d.jpg", "parrot"), alt_datum="ellipsoid").alt_datum \
        == "ellipsoid"


def test_a_photo_without_any_makers_pose_is_refused_naming_what_was_looked_for(tmp_path):
    from PIL import Image

    path = tmp_path / "plain.jpg"
    exif = Image.Exif()
    exif.get_ifd(0x8825).update({1: "N", 2: (46.0, 30.0, 0.0), 3: "E", 4: (7.0, 30.0, 0.0), 6: 900.0})
    Image.new("L", (32, 24)).save(path, exif=exif)
    with pytest.raises(InputError, match=r"no gimbal attitude .*drone-skydio:CameraOrientationNED") as exc:
        read_photo_checked(path)
    assert "\n" not in str(exc.value) and str(path) in str(exc.value)


# ---- photos as they reach the user: resized, turned, orientation tags ----------------------------------------

def test_a_resized_photo_scales_its_calibrated_intrinsics(tmp_path):
    p = read_photo_checked(write_maker_photo(tmp_path / "r.jpg", "skydio", size=(1500, 844),
                                             exif_extra={40962: 4056, 40963: 2282}))
    s = 1500 / 4056
    assert p.intrinsics.fx_px == pytest.approx(2378.5 * s) and p.intrinsics.fy_px == pytest.approx(2376.9 * s)
    # Skydio's optical centre is in the 4056 x 3040 sensor's pixels (the database's size): its offset from the
    # sensor's centre, scaled, moves the image centre
    assert p.intrinsics.cx_px == pytest.approx(749.5 + (2029.2 - 2027.5) * s)
    assert p.intrinsics.cy_px == pytest.approx(421.5 + (1520.3 - 1519.5) * s)
    assert any("resized after capture from 4056x2282" in w for w in p.warnings)


@pytest.mark.parametrize("size, extra, software, match", [
    ((48, 64), {40962: 64, 40963: 48}, None, "turned by 90 degrees after capture"),
    ((64, 40), {40962: 64, 40963: 48}, "Adobe Photoshop 25.0", "cropped by 'Adobe Photoshop 25.0' after capture"),
])
def test_pixels_that_cannot_be_mapped_to_the_cameras_are_refused(tmp_path, size, extra, software, match):
    path = write_maker_photo(tmp_path / "t.jpg", "parrot", size=size, exif_extra=extra, software=software)
    with pytest.raises(InputError, match=match) as exc:
        read_photo_checked(path)
    assert "\n" not in str(exc.value) and "original file" in str(exc.value)


def test_an_orientation_tag_leaves_the_stored_pixels_as_the_cameras(tmp_path):
    from PIL import Image

    path = write_maker_photo(tmp_path / "o.jpg", "parrot")
    with Image.open(path) as im:
        exif, xmp, pixels = im.getexif(), im.info["xmp"], im.copy()
    exif[274] = 6
    pixels.save(path, "JPEG", exif=exif, xmp=xmp)
    p = read_photo_checked(path)
    assert p.orientation == 6 and (p.width_px, p.height_px) == (64, 48)
    assert any("EXIF Orientation 6" in w for w in p.warnings)
    assert p.intrinsics.cx_px == pytest.approx(31.5)  # the stored image's centre: nothing turned


def test_database_numbers_written_as_java_doubles():
    from pipeline.ingest.photo_camera import _number, database_entry

    assert _number("7.68d/640.0d") == pytest.approx(0.012)
    entry = database_entry("DJI", "ZH20T", thermal=True)
    assert entry is not None and entry["isThermal"] and _number(entry["ccdWidthMMPerPixel"]) == pytest.approx(0.012)
    assert database_entry("Hasselblad", "L1D-20c") is not None and database_entry("DJI", "M3E") is not None
