"""Damaged and incomplete photos: one-line InputError naming the file; a folder with a few bad photos is read with
the bad ones listed (read_photos, `ridgeloc locate`)."""

import json
import re

import numpy as np
import pytest

from pipeline.cli import main as cli_main
from pipeline.errors import InputError
from pipeline.ingest.photo import read_photo_checked, read_photos
from pipeline.synth.photos import PhotoFlightSpec, dji_xmp, simulate_photo_flight, write_photo_flight


@pytest.fixture()
def flight(tmp_path):
    fl = simulate_photo_flight(PhotoFlightSpec(seed=5))
    write_photo_flight(fl, tmp_path / "f")
    return fl, tmp_path / "f"


def _rewrite(path, tag, xmp=None, gps=True):
    """Write the photo again with an XMP packet of our choosing, or without the EXIF GPS IFD."""
    from PIL import Image

    with Image.open(path) as im:
        exif = im.getexif()
        if not gps:
            del exif[0x8825]
        pixels = im.copy()
    pixels.save(path, "JPEG", exif=exif, xmp=xmp if xmp is not None else dji_xmp(tag))


def _one_line_naming(exc, path):
    text = str(exc.value)
    assert "\n" not in text and str(path) in text
    return text


def test_no_gps(flight):
    fl, folder = flight
    p = folder / "DJI_0001.JPG"
    _rewrite(p, fl.tags[0], gps=False)
    with pytest.raises(InputError) as exc:
        read_photo_checked(p)
    assert "no GPS position" in _one_line_naming(exc, p)


def test_no_gimbal_tags(flight):
    fl, folder = flight
    p = folder / "DJI_0002.JPG"
    xmp = re.sub(rb'drone-dji:Gimbal\w+="[^"]*" ', b"", dji_xmp(fl.tags[1]))
    _rewrite(p, fl.tags[1], xmp=xmp)
    with pytest.raises(InputError) as exc:
        read_photo_checked(p)
    assert "no gimbal attitude" in _one_line_naming(exc, p)


@pytest.mark.parametrize("damage", [lambda x: x[: len(x) // 2], lambda x: x.replace(b"</rdf:RDF>", b""),
                                    lambda x: b'<!DOCTYPE x [<!ENTITY a "aaaa">]>' + x])
def test_corrupt_xmp(flight, damage):
    fl, folder = flight
    p = folder / "DJI_0003.JPG"
    _rewrite(p, fl.tags[2], xmp=damage(dji_xmp(fl.tags[2])))
    with pytest.raises(InputError) as exc:
        read_photo_checked(p)
    assert "corrupt XMP packet" in _one_line_naming(exc, p)


def test_not_a_photo(tmp_path):
    p = tmp_path / "x.jpg"
    p.write_bytes(b"\xff\xd8\xff\xe0 nonsense")
    with pytest.raises(InputError) as exc:
        read_photo_checked(p)
    _one_line_naming(exc, p)


def test_folder_with_bad_photos_is_located_with_them_listed(flight, capsys):
    fl, folder = flight
    _rewrite(folder / "DJI_0002.JPG", fl.tags[1], gps=False)
    (folder / "DJI_0009.JPG").write_bytes(b"garbage")
    photos, bad = read_photos([folder])
    assert [p.name for p in photos] == ["DJI_0001.JPG", "DJI_0003.JPG", "DJI_0004.JPG", "DJI_0005.JPG"]
    assert [b[0].rsplit("/", 1)[1] for b in bad] == ["DJI_0002.JPG", "DJI_0009.JPG"]
    rc = cli_main(["locate", str(folder), "--json"])
    out = capsys.readouterr()
    doc = json.loads(out.out)
    assert rc == 1 and len(doc["bad_photos"]) == 2
    assert "mle" in doc["estimates"] and np.isfinite(doc["estimates"]["mle"]["lat_deg"])
    assert out.err.count("ridgeloc: error:") == 2 and "DJI_0009.JPG" in out.err


def test_run_of_a_photo_flight_with_bad_photos_lists_them(tmp_path):
    """`ridgeloc run` of a photo flight whose folder holds a damaged photo and a non-image: both are left out with a
    note naming them, every target is located from the others."""
    import shutil

    from pipeline.flight_config import load_flight_config
    from pipeline.run import process_group

    fl = simulate_photo_flight(PhotoFlightSpec(seed=6, extra_targets=(("post", 30.0, -10.0),)))
    write_photo_flight(fl, tmp_path)
    shutil.copy(tmp_path / "DJI_0005.JPG", tmp_path / "DJI_0006.JPG")
    _rewrite(tmp_path / "DJI_0006.JPG", fl.tags[4], xmp=b"<x:xmpmeta")  # a corrupt XMP packet
    (tmp_path / "DJI_0007.JPG").write_bytes(b"not a jpeg")
    result = process_group(load_flight_config(tmp_path / "flight.yaml"))
    assert [r.target for r in result.targets] == ["laser_spot", "post"] and not result.failed
    for r in result.targets:
        left_out = [n for n in r.settings["notes"] if n.startswith("photo left out")]
        assert len(left_out) == 2 and "DJI_0006.JPG" in left_out[0] and "corrupt XMP" in left_out[0]
        assert "DJI_0007.JPG" in left_out[1]
        assert r.observations.n == 5


@pytest.mark.parametrize("command", [["check"], ["check", "--no-clock"]])
def test_check_of_a_photo_flight_says_which_command_reads_it(tmp_path, capsys, command):
    from pathlib import Path

    config = Path(__file__).resolve().parents[1] / "configs" / "flights" / "h20_laser.yaml"
    assert cli_main([*command, str(config)]) == 1
    assert capsys.readouterr().err.splitlines() == [
        f"ridgeloc: error: {config}: a photo flight (files.photos), not a video flight: use `ridgeloc locate` or "
        "`ridgeloc run`"]


@pytest.mark.parametrize("command", ["locate", "mark"])
def test_one_unreadable_photo_alone_is_one_line(tmp_path, capsys, command):
    p = tmp_path / "x.jpg"
    p.write_bytes(b"")
    assert cli_main([command, str(p)]) == 1
    out = capsys.readouterr()
    assert out.out == "" and len(out.err.splitlines()) == 1 and out.err.startswith(f"ridgeloc: error: {p}: ")
    assert list(tmp_path.iterdir()) == [p]


def test_a_folder_without_photos_is_named_as_such(tmp_path, capsys):
    (tmp_path / "notes.txt").write_text("no photos here")
    assert cli_main(["locate", str(tmp_path)]) == 1
    assert capsys.readouterr().err.splitlines() == [f"ridgeloc: error: {tmp_path}: no photos (.jpg, .jpeg files) here"]
