"""`ridgeloc inspect PHOTO...` lists what each photo states."""

import json
from pathlib import Path

import pytest

from pipeline.cli import main as cli_main
from pipeline.synth.photos import PhotoFlightSpec, simulate_photo_flight, write_photo_flight

BRIGHTON = Path(__file__).resolve().parents[1].parent / "shared" / "photos/brighton"  # ../shared from the repo root


@pytest.mark.skipif(not BRIGHTON.is_dir(), reason="../shared/photos/brighton is absent")
def test_inspect_brighton(capsys):
    assert cli_main(["inspect", str(BRIGHTON)]) == 0
    out = capsys.readouterr().out
    assert out.count("[photo DJI FC300S 4000x2250]") == 6
    assert "altitude 198.41 m amsl (drone-dji:AbsoluteAltitude; EXIF GPSAltitude 198.41 m" in out
    assert "gimbal 220.00 -89.90 0.00; aircraft 221.30 -0.10 -4.00" in out
    assert "database djiFC300S + EXIF FocalLength" in out and "time zone unknown" in out


MAKERS = BRIGHTON.parent / "makers"


@pytest.mark.skipif(not MAKERS.is_dir(), reason="../shared/photos/makers is absent")
def test_inspect_makers_says_each_height_once_and_yaws_in_one_range(capsys):
    """Parrot's height is EXIF GPSAltitude itself (said once, not twice); Teal's aircraft yaw (319.02) and its
    gimbal's (-39.39 in the tags) are both shown from north in 0-360, so they compare."""
    assert cli_main(["inspect", str(MAKERS / "parrot-1.jpg"), str(MAKERS / "teal2_img_ir_00015.jpg")]) == 0
    out = capsys.readouterr().out
    assert "altitude 78.99 m amsl (EXIF GPSAltitude; no height above the take-off point)" in out
    assert "gimbal 320.61 -58.18 -1.96; aircraft 319.02 -3.93 -1.04" in out


def test_inspect_json_with_a_bad_photo(tmp_path, capsys):
    flight = simulate_photo_flight(PhotoFlightSpec(seed=4, n_photos=2))
    write_photo_flight(flight, tmp_path)
    (tmp_path / "DJI_0003.JPG").write_bytes(b"\xff\xd8\xff")
    assert cli_main(["inspect", "--json", str(tmp_path)]) == 1
    cap = capsys.readouterr()
    doc = json.loads(cap.out)
    assert [p["lrf_range_m"] for p in doc["photos"]] == pytest.approx([t["lrf_range_m"] for t in flight.tags],
                                                                       abs=1e-3)
    assert doc["photos"][0]["intrinsics"]["source"] == "drone-dji Calibrated* + DewarpData"
    assert len(doc["errors"]) == 1 and "DJI_0003.JPG" in doc["errors"][0]["path"]
    assert "DJI_0003.JPG" in cap.err


def test_inspect_a_photo_flight_config_lists_its_photos(capsys):
    """`inspect FLIGHT.yaml` of a photo flight (files.photos) lists what its photos state ('no input files given')."""
    config = Path(__file__).resolve().parents[1] / "configs" / "flights" / "h20_laser.yaml"
    assert cli_main(["inspect", str(config)]) == 0
    cap = capsys.readouterr()
    assert cap.out.count("[photo DJI ZH20T 640x480]") == 5 and cap.err == ""
    assert cli_main(["inspect", "--json", str(config)]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["config"] == str(config) and len(doc["photos"]) == 5 and doc["errors"] == []
