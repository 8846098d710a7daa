"""The six real DJI Phantom 3 photos of ../shared/photos/brighton: read with position, attitude, gimbal and
intrinsics, and their pose chain checked by triangulating marked points from two pairs of photos
(scripts/photo_brighton_check.py marked them; docs/ingest.md, "Brighton check")."""

from pathlib import Path

import numpy as np
import pytest

FOLDER = Path(__file__).resolve().parents[1].parent / "shared" / "photos/brighton"  # ../shared from the repo root
pytestmark = pytest.mark.skipif(not FOLDER.is_dir(), reason="../shared/photos/brighton is absent")

# (first photo index, pixels in photos i, i+1, i+2 in the files' frame), from scripts/photo_brighton_check.py
MARKS = [
    (0, [(1244.4, 2180.5), (1404.2, 1340.6), (1341.7, 503.9)]),
    (0, [(1262.0, 2022.0), (1387.7, 1187.1), (1321.0, 349.4)]),
    (1, [(3698.3, 1730.7), (3646.1, 896.8), (3596.4, 95.6)]),
    (2, [(1421.3, 2095.7), (1340.3, 1268.0), (1285.4, 416.7)]),
    (2, [(1467.2, 2048.6), (1387.0, 1220.0), (1335.2, 370.2)]),
    (3, [(1519.4, 2052.5), (1427.6, 1222.3), (1346.7, 416.8)]),
    (3, [(1510.0, 2101.3), (1415.7, 1271.1), (1335.6, 466.7)]),
]


@pytest.fixture(scope="module")
def photos():
    from pipeline.ingest.photo import read_photos

    photos, bad = read_photos([FOLDER])
    assert bad == []
    return photos


def test_six_photos_read_with_pose_and_intrinsics(photos):
    assert [p.name for p in photos] == [f"DJI_00{i}.JPG" for i in range(24, 30)]
    p = photos[0]
    assert (p.make, p.model, p.width_px, p.height_px) == ("DJI", "FC300S", 4000, 2250)
    # EXIF GPS 46 deg 50' 34.3126" N, 91 deg 59' 37.308" W; drone-dji:AbsoluteAltitude +198.41
    assert p.lat_deg == pytest.approx(46 + 50 / 60 + 34.3126 / 3600, abs=1e-9)
    assert p.lon_deg == pytest.approx(-(91 + 59 / 60 + 37.308 / 3600), abs=1e-9)
    assert (p.alt_m, p.alt_source, p.relative_alt_m, p.gps_alt_m) == (198.41, "drone-dji:AbsoluteAltitude", 39.9,
                                                                       198.409)
    assert p.gimbal_ypr_deg == (-140.0, -89.9, 0.0)
    assert p.flight_ypr_deg == (-138.7, -0.1, -4.0)
    # database djiFC300S: 3.61 mm / (6.3175 mm / 4000 px)
    assert p.intrinsics.fx_px == pytest.approx(3.61 / (6.3175 / 4000))
    assert p.intrinsics.dist == (-0.132438, 0.111056, 0.00011023, 0.000114239, -0.0158256)
    assert p.time_zone == "unknown" and p.t_ns is not None
    assert any("Windows Photo Viewer" in w for w in p.warnings)
    assert all(q.intrinsics is not None and q.flight_ypr_deg is not None for q in photos)


def _triangulate(views, idx, px):
    from pipeline.solve import solve
    from pipeline.solve.observations import Observations

    obs = Observations(P=views.P[idx], pixel=views.pinhole_pixels(px, idx), platform_m=views.camera_m[idx],
                       range_m=np.full(len(idx), np.nan))
    return solve("dlt", obs).position_m


def test_marked_points_agree_between_pairs(photos):
    from pipeline.ingest.photo_views import photo_views

    views = photo_views(photos, rotation_deg=180)  # the files were turned upside down after capture (docs)
    for i, px in MARKS:
        px = np.array(px)
        a = _triangulate(views, [i, i + 1], px[:2])
        b = _triangulate(views, [i + 1, i + 2], px[1:])
        assert np.linalg.norm(a - b) < 5.0, (i, a, b)
        # the beach is 30-45 m below the cameras (drone-dji:RelativeAltitude ~40 m above the take-off point)
        assert -45.0 < a[2] - views.camera_m[i, 2] < -30.0


def test_without_the_rotation_the_pairs_do_not_locate(photos):
    """The same marks with the files' pixels taken as captured: the rays diverge (behind the cameras) or the pairs
    disagree, which is how the 180-degree turn was found."""
    from pipeline.errors import GeometryError
    from pipeline.ingest.photo_views import photo_views

    views = photo_views(photos)
    for i, px in MARKS:
        px = np.array(px)
        try:
            a = _triangulate(views, [i, i + 1], px[:2])
            b = _triangulate(views, [i + 1, i + 2], px[1:])
        except GeometryError:
            continue
        assert np.linalg.norm(a - b) > 10.0 or a[2] > views.camera_m[i, 2]


def _marks_csv(path, photos, rows):
    path.write_text("photo,x_px,y_px\n" + "".join(f"{photos[i].name},{u},{v}\n" for i, (u, v) in rows))
    return str(path)


def test_pairs_locate_a_point_with_no_flag_and_agree(photos, tmp_path, capsys):
    """`ridgeloc locate` of a pair with the point marked in both, no flag: the rotation is found from the two rays
    (they meet in front of both cameras only with the files turned by 180 degrees), and the two pairs of each
    triple agree within a few metres."""
    import json

    from pipeline.cli import main as cli_main
    from pipeline.geometry.frames import enu_from_lla

    for n, (i, px) in enumerate(MARKS):
        answers = []
        for pair in ((i, i + 1), (i + 1, i + 2)):
            marks = _marks_csv(tmp_path / f"m{n}-{pair[0]}.csv", photos, [(k, px[k - i]) for k in pair])
            cli_main(["locate", *(photos[k].path for k in pair), "--marks", marks, "--json"])
            doc = json.loads(capsys.readouterr().out)
            assert any("image rotation 180 deg" in note for note in doc["notes"])
            answers.append([doc["estimates"]["dlt"][k] for k in ("lat_deg", "lon_deg", "h_m")])
        e = enu_from_lla(*answers[1], answers[0])
        assert np.hypot(e[0], e[1]) < 3.0 and abs(e[2]) < 5.0, (n, e)


def test_one_re_saved_photo_off_its_centre_is_refused_in_one_line(photos, capsys):
    from pipeline.cli import main as cli_main

    assert cli_main(["locate", photos[1].path, "--pixel", "1404.2", "1340.6", "--ground", "takeoff"]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "Windows Photo Viewer" in err[0] and "--image-rotation 0 or 180" in err[0]


def test_take_off_ground_answers_cover_their_error_against_the_pairs(photos):
    """One photo, no laser, no DEM, `--ground takeoff` (the rotation stated, as the pairs found it): the weaker
    answer's 95 % horizontal ellipse holds the two-photo answer, for every photo of every marked point."""
    from pipeline.geometry.frames import enu_from_lla
    from pipeline.locate import GroundAssumption, locate_photos, photo_answer

    chi2_2_95 = 5.991
    worst = 0.0
    for i, px in MARKS:
        px = np.array(px)
        pair = locate_photos(photos[i:i + 2], px[:2], methods=["dlt"])
        truth = pair.views.lla(pair.estimates["dlt"].position_m)
        for k in range(3):
            one = locate_photos([photos[i + k]], px[k:k + 1], rotation_deg=180, methods=["ground"],
                                ground=GroundAssumption("takeoff"))
            e = one.estimates["ground"]
            assert "a weaker answer" in e.extras["assumption"] and any("ground:" in n for n in one.notes)
            d = enu_from_lla(*truth, one.views.origin_lla)[:2] - e.position_m[:2]
            worst = max(worst, float(d @ np.linalg.solve(e.covariance_m2[:2, :2], d)))
            assert np.hypot(*d) < 6.0
            answer = photo_answer(one)  # the answer, not only an estimate (was not located: 40 m up, the assumed
            assert answer.located and answer.method == "ground"  # ground's +-5 m counted as the geometry's)
    assert worst < chi2_2_95


def test_an_unmarked_photo_flight_without_laser_is_told_to_mark_the_target(photos, tmp_path, capsys):
    """No marks, no laser: each photo's image centre is a different ground point; the failure says to mark the
    target (it listed every method's reason, 'dlt: dlt: ...', and nothing a user could do)."""
    import yaml

    from pipeline.cli import main as cli_main

    config = tmp_path / "flight.yaml"
    config.write_text(yaml.safe_dump({"name": "brighton", "files": {"photos": [p.path for p in photos]}}))
    assert cli_main(["run", str(config), "-o", str(tmp_path / "o"), "-q"]) == 1
    err = capsys.readouterr().err
    assert "the target is not marked" in err and "`ridgeloc mark`" in err and "dlt: dlt:" not in err

