"""`ridgeloc locate`: one photo + laser, several photos + every method, --json schema, pixels and marks."""

import json

import numpy as np
import pytest

from pipeline.cli import main as cli_main
from pipeline.geometry.frames import enu_from_lla
from pipeline.synth.photos import PhotoFlightSpec, simulate_photo_flight, write_photo_flight


@pytest.fixture(scope="module")
def flight(tmp_path_factory):
    folder = tmp_path_factory.mktemp("photos")
    fl = simulate_photo_flight(PhotoFlightSpec(seed=11))
    write_photo_flight(fl, folder)
    return fl, folder


def _locate(capsys, *argv):
    rc = cli_main(["locate", *map(str, argv), "--json"])
    return rc, json.loads(capsys.readouterr().out)


def test_one_photo_centre_gives_los_at_dji_target(flight, capsys):
    """The image centre with the laser range: our pose chain (XMP angles -> Rotation -> P -> the ray through the
    centre pixel) lands where the synth put DJI's own target (its angles turned into a direction by trigonometry)."""
    _, folder = flight
    rc, doc = _locate(capsys, folder / "DJI_0001.JPG")
    assert rc == 0 and doc["ranges_used"] == 1
    los, dji = doc["estimates"]["los"], doc["estimates"]["dji"]
    d = enu_from_lla(los["lat_deg"], los["lon_deg"], los["h_m"], (dji["lat_deg"], dji["lon_deg"], dji["h_m"]))
    assert np.linalg.norm(d) < 0.05  # tags are written to 0.01 deg and 1 mm; 0.01 deg at 400 m is 0.07 m
    assert doc["estimates"]["vision"]["status"] == "insufficient_data"
    assert doc["estimates"]["dem"] == {"status": "insufficient_data", "reason": "no DEM given (--dem)"}
    for key in ("lat_deg", "lon_deg", "h_m", "alt_msl_m", "cep50_m"):
        assert key in los
    assert los["cep50_m"] is None and isinstance(doc["estimates"]["mle"]["cep50_m"], float)


def test_several_photos_every_method_mle_beats_the_one_shot_target(flight, capsys):
    fl, folder = flight
    rc, doc = _locate(capsys, folder, "--marks", folder / "marks.csv")
    assert rc == 0 and doc["ranges_used"] == 5
    est = doc["estimates"]
    truth = tuple(fl.truth["target_lla"])

    def horizontal_error(row):
        return float(np.hypot(*enu_from_lla(row["lat_deg"], row["lon_deg"], row["h_m"], truth)[:2]))

    for m in ("dlt", "vision", "range", "los", "fusion-raw", "fusion", "ridge", "mle", "dji"):
        assert "lat_deg" in est[m] and est[m]["status"], (m, est[m])  # fusion may stop at max_iterations
    assert est["mle"]["status"] == "converged"
    # a 1-5 deg compass bias at 250-600 m moves DJI's target by metres to tens of metres; the MLE sees the bias
    # through the ranges from five directions (scripts/photo_zoo.py has the statistics over 100 flights)
    assert horizontal_error(est["mle"]) < horizontal_error(est["dji"])
    assert est["mle"]["ellipse95_semi_major_m"] >= est["mle"]["ellipse95_semi_minor_m"] > 0


def test_stated_errors_replace_the_defaults(flight, capsys):
    """--bias-prior-deg, --position-sigma-m and --alt-sigma-m replace the source's defaults (error_model in --json);
    a tighter shared offset gives a smaller CEP at the same estimate; a negative sigma is refused."""
    _, folder = flight
    marks = ("--marks", folder / "marks.csv")
    _, default = _locate(capsys, folder, *marks)
    assert default["error_model"]["source"] == "GNSS without RTK, laser"
    assert default["error_model"]["shared_offset_horizontal_m"] == 1.5
    _, stated = _locate(capsys, folder, *marks, "--bias-prior-deg", "1", "--position-sigma-m", "0.1",
                        "--alt-sigma-m", "2")
    em = stated["error_model"]
    assert (em["bias_prior_deg"], em["shared_offset_horizontal_m"], em["shared_offset_vertical_m"]) == (1.0, 0.1, 2.0)
    assert "stated" in em["source"]
    assert stated["estimates"]["mle"]["cep50_m"] < default["estimates"]["mle"]["cep50_m"]
    assert cli_main(["locate", str(folder), "--alt-sigma-m", "-1"]) != 0
    err = capsys.readouterr().err
    assert "--alt-sigma-m must be a finite number >= 0, got -1" in err and len(err.strip().splitlines()) == 1


def test_pixel_off_centre_drops_the_laser(flight, capsys):
    _, folder = flight
    rc, doc = _locate(capsys, folder, "--pixel", 100, 100)
    assert rc == 0 and doc["ranges_used"] == 0
    assert doc["estimates"]["los"]["status"] == "insufficient_data"


def test_pixel_outside_the_image_is_refused(flight, capsys):
    _, folder = flight
    assert cli_main(["locate", str(folder / "DJI_0001.JPG"), "--pixel", "5000", "10"]) == 1
    err = capsys.readouterr().err
    assert "DJI_0001.JPG" in err and "outside the 640x480 image" in err
    assert cli_main(["locate", str(folder / "DJI_0001.JPG"), "--pixel", "nan", "10"]) == 1
    assert "DJI_0001.JPG: pixel (nan, 10) is not a pair of finite numbers" in capsys.readouterr().err


def test_marks_for_an_unknown_photo(flight, capsys, tmp_path):
    _, folder = flight
    marks = tmp_path / "m.csv"
    marks.write_text("photo,x_px,y_px\nNOPE.JPG,1,2\n")
    assert cli_main(["locate", str(folder), "--marks", str(marks)]) == 1
    assert "marks for photos not given: NOPE.JPG" in capsys.readouterr().err


@pytest.mark.parametrize("rows, problem", [
    ("DJI_0001.JPG,inf,10\n", "line 2: the pixel (inf, 10) is not a finite number"),
    ("DJI_0001.JPG,1,2\nDJI_0001.JPG,3,4\n", "line 3: a second mark for photo DJI_0001.JPG"),
])
def test_a_bad_photo_mark_is_one_line_naming_file_and_line(flight, capsys, tmp_path, rows, problem):
    _, folder = flight
    marks = tmp_path / "m.csv"
    marks.write_text("photo,x_px,y_px\n" + rows)
    assert cli_main(["locate", str(folder), "--marks", str(marks)]) == 1
    err = capsys.readouterr().err.strip()
    assert str(marks) in err and problem in err and "\n" not in err, err


@pytest.mark.parametrize("text", ["", "photo,x_px,y_px\n"], ids=["empty", "header-only"])
def test_a_marks_file_without_marks_is_refused(flight, capsys, tmp_path, text):
    _, folder = flight
    marks = tmp_path / "m.csv"
    marks.write_text(text)
    assert cli_main(["locate", str(folder), "--marks", str(marks)]) == 1
    out = capsys.readouterr()
    assert out.out == "" and out.err == f"ridgeloc: error: {marks}: holds no marks: want a header photo,x_px,y_px " \
                                        "and a row per marked photo\n"


def test_synth_command_writes_a_photo_flight_without_laser(tmp_path, capsys):
    out = tmp_path / "p"
    assert cli_main(["synth", "--photos", "3", "--no-laser", "-o", str(out), "--seed", "2"]) == 0
    assert "3 photos (without laser)" in capsys.readouterr().out
    rc, doc = _locate(capsys, out, "--marks", out / "marks.csv")
    assert rc == 0 and doc["ranges_used"] == 0 and doc["estimates"]["dji"]["status"] == "insufficient_data"
    assert doc["estimates"]["mle"]["status"] == "converged"


def test_run_treats_a_photo_flight_config_as_a_flight(tmp_path, capsys):
    from pipeline.flight_config import load_flight_config

    flight = simulate_photo_flight(PhotoFlightSpec(seed=12))
    write_photo_flight(flight, tmp_path / "ph")
    cfg = load_flight_config(tmp_path / "ph" / "flight.yaml")
    assert cfg.files.photos == (str((tmp_path / "ph").resolve()),) and cfg.files.telemetry == ()
    from pipeline.run import process_group

    result = process_group(cfg)
    assert set(result.estimates) >= {"mle", "dji", "vision"} and result.observations.n == 5
    truth = np.asarray(result.truth_m)
    assert np.linalg.norm((result.estimates["mle"].position_m - truth)[:2]) < \
        np.linalg.norm((result.estimates["dji"].position_m - truth)[:2])
    assert result.settings["solve_failures"]["dem"]["status"] == "insufficient_data"


def test_nothing_located_is_a_failure(tmp_path, capsys):
    """One photo without laser and without a DEM determines no point: every method unsolved, with its reason, and
    exit 1 (as `ridgeloc solve` when no method solves)."""
    out = tmp_path / "p"
    assert cli_main(["synth", "--photos", "2", "--no-laser", "-o", str(out), "--seed", "3"]) == 0
    capsys.readouterr()
    rc, doc = _locate(capsys, out / "DJI_0001.JPG")
    assert rc == 1
    assert all("status" in r and "lat_deg" not in r for r in doc["estimates"].values())


def test_named_targets_of_a_photo_flight(tmp_path):
    """`targets:` in a photo flight's config: a mark's frame_index is the photo's index in time order; a target
    marked on a photo the flight does not have is listed as not located, the others are."""
    import yaml

    from pipeline.flight_config import load_flight_config
    from pipeline.run import process_group

    fl = simulate_photo_flight(PhotoFlightSpec(seed=13, extra_targets=(("post", 30.0, -10.0),)))
    write_photo_flight(fl, tmp_path)
    doc = yaml.safe_load((tmp_path / "flight.yaml").read_text())
    assert doc["marks_file"] == "targets.csv" and "marks" not in doc["files"]
    del doc["marks_file"]
    post = fl.extra_marks_px["post"]
    doc["targets"] = [
        {"name": "post", "marks": [{"frame_index": i, "pixel": [float(u), float(v)]}
                                   for i, (u, v) in enumerate(post) if np.isfinite(u)]},
        {"name": "ghost", "marks": [{"frame_index": 7, "pixel": [10.0, 10.0]}]}]
    (tmp_path / "named.yaml").write_text(yaml.safe_dump(doc))
    result = process_group(load_flight_config(tmp_path / "named.yaml"))
    assert [r.target for r in result.targets] == ["post"]
    assert [f.target for f in result.failed] == ["ghost"]
    assert "photo index 7 is not one of the flight's 5 readable photos" in result.failed[0].message
    post_truth = next(t for t in fl.truth["targets"] if t["name"] == "post")
    r = result.targets[0]
    truth_m = enu_from_lla(post_truth["lat_deg"], post_truth["lon_deg"], post_truth["alt_m"], r.origin_lla)
    assert np.linalg.norm(r.truth_m - truth_m) < 1e-6  # its truth is the post's (truth.json "targets")
    spot = enu_from_lla(*fl.truth["target_lla"], r.origin_lla)  # the laser's spot, 32 m away: not what was marked
    mle = r.estimates["mle"].position_m
    assert np.linalg.norm(mle - r.truth_m) < np.linalg.norm(mle - spot)


def test_a_dem_is_the_mle_prior_only_with_a_stated_sigma(tmp_path, capsys):
    """As for video flights: --dem alone adds the `dem` method and leaves the MLE as without a DEM; --dem-sigma-m
    makes the DEM its terrain prior (the estimate moves); a sigma that is not > 0 is refused in one line."""
    from pipeline.synth.photos import write_photo_sample

    write_photo_sample(tmp_path / "f", PhotoFlightSpec(seed=3, n_photos=4), dem=True)
    folder, dem = tmp_path / "f", tmp_path / "f" / "dem.tif"
    marks = ("--marks", folder / "marks.csv")
    _, plain = _locate(capsys, folder, *marks)
    _, with_dem = _locate(capsys, folder, *marks, "--dem", dem)
    _, prior = _locate(capsys, folder, *marks, "--dem", dem, "--dem-sigma-m", "0.5")
    assert "lat_deg" in with_dem["estimates"]["dem"] and "lat_deg" not in plain["estimates"]["dem"]
    assert with_dem["estimates"]["mle"] == plain["estimates"]["mle"]
    assert prior["estimates"]["mle"]["h_m"] != plain["estimates"]["mle"]["h_m"]
    assert with_dem["notes"] and "--dem-sigma-m" in with_dem["notes"][0] and not prior["notes"] + plain["notes"]
    assert cli_main(["locate", str(folder), "--dem", str(dem), "--dem-sigma-m", "0"]) != 0
    err = capsys.readouterr().err
    assert "--dem-sigma-m must be a finite number > 0, got 0" in err and len(err.strip().splitlines()) == 1
    assert cli_main(["locate", str(folder), "--dem-sigma-m", "2"]) != 0  # a DEM's sigma without a DEM
    err = capsys.readouterr().err
    assert "--dem-sigma-m is the DEM's vertical error: give the DEM with --dem" in err
    assert len(err.strip().splitlines()) == 1


def test_the_answers_method_prints_the_answers_digits(capsys):
    """The table's answer and its method's line in the list below it show the same latitude, longitude and MSL
    height: on the sample h20_laser photos the MLE's 651.0504 m MSL was '651.0' above (targets.csv's 651.05
    shown to one decimal) and '651.1' below."""
    from pathlib import Path

    folder = Path(__file__).resolve().parents[1] / "sample_data" / "photos" / "h20_laser"
    assert cli_main(["locate", str(folder), "--dem", str(folder / "dem.tif")]) == 0
    lines = capsys.readouterr().out.splitlines()
    answer = lines[1].split()
    method = next(ln.split() for ln in lines if ln.startswith(f"  {answer[-1]} "))
    assert answer[0] == "h20_laser" and answer[-1] == "mle"
    assert (method[1], method[2], method[7]) == (answer[1], answer[2], answer[3])
