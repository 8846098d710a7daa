"""Marks of many targets (issue 21): the `targets:` list, marks CSV and OpenDroneMap gcp_list.txt, and their
one-line errors naming file, row and problem (pipeline/targets.py)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest
import yaml

from pipeline.errors import ConfigError, InputError
from pipeline.flight_config import load_flight_config
from pipeline.targets import flight_targets, in_image, read_gcp_list, read_marks_csv

ROOT = Path(__file__).resolve().parents[1]
GROUP1 = ROOT / "sample_data" / "group1"


def _flight(tmp_path: Path, **keys) -> Path:
    """A flight config of sample flight group1 (600x400 px, frames 0..143) without its `target:`, plus `keys`."""
    doc = yaml.safe_load((ROOT / "configs" / "flights" / "group1.yaml").read_text())
    doc.pop("target")
    doc["files"] = {"telemetry": [str(GROUP1 / "flight.tlog")], "video": str(GROUP1 / "video.mp4"),
                    "frames_csv": str(GROUP1 / "video.frames.csv")}
    doc["truth_file"] = str(GROUP1 / "truth.json")
    doc.update(keys)
    path = tmp_path / "flight.yaml"
    path.write_text(yaml.safe_dump(doc))
    return path


def test_marks_csv_groups_rows_by_name_and_reads_templates(tmp_path):
    (tmp_path / "chip.png").write_bytes((ROOT / "docs" / "sample_frame.png").read_bytes())
    p = tmp_path / "marks.csv"
    p.write_text("name,frame_or_image,x_px,y_px\npole1,4,300.5,200\npole2,4,100,50\npole1,40,310,190.25\n"
                 "roof,chip.png,12,13\n")
    targets = read_marks_csv(p)
    assert [t.name for t in targets] == ["pole1", "pole2", "roof"]
    assert [(m.frame_index, m.pixel) for m in targets[0].marks] == [(4, (300.5, 200.0)), (40, (310.0, 190.25))]
    assert targets[2].marks[0].template == str((tmp_path / "chip.png").resolve())
    assert targets[2].marks[0].template_pixel == (12.0, 13.0)
    assert targets[0].marks[1].source == f"{p}: row 4"


def test_gcp_list_marks_with_their_surveyed_truth(tmp_path):
    (tmp_path / "frame_0040.png").write_bytes((ROOT / "docs" / "sample_frame.png").read_bytes())
    p = tmp_path / "gcp_list.txt"
    p.write_text("EPSG:4326\n108.7601 34.3602 372.5 300 200 4 gcpA\n108.7601 34.3602 372.5 310 190 frame_40.jpg gcpA\n"
                 "108.7700 34.3700 371.0 20 30 frame_0040.png\n")
    targets, notes = read_gcp_list(p)
    assert notes == []
    a, b = targets
    assert a.name == "gcpA" and a.truth_lla == (34.3602, 108.7601, 372.5)  # lon lat order in the file
    assert [m.frame_index for m in a.marks] == [4, 40]  # a frame named by its number
    assert b.name == "gcp4" and b.marks[0].template.endswith("frame_0040.png")  # an image beside the list
    p.write_text("+proj=utm +zone=49 +datum=WGS84\n500000 3800000 372 300 200 4 gcpA\n")
    targets, notes = read_gcp_list(p)
    assert targets[0].truth_lla is None and "not geographic" in notes[0]


@pytest.mark.parametrize("rows, problem", [
    ("B,9999,10,10", "row 3: frame index 9999 out of range (the video has frames 0..143)"),
    ("A,4,310,200", "row 3: duplicate name 'A'"),
    ("B,nope.png,10,10", "row 3: unknown image 'nope.png'"),
    ("B,5,700,10", "row 3: pixel (700, 10) is outside the image (600x400 px)"),
    ("B,5,-1,10", "row 3: pixel (-1, 10) is outside the image"),
    ("B,5,599.6,10", "row 3: pixel (599.6, 10) is outside the image (600x400 px)"),
    ("B,5,10,-0.51", "row 3: pixel (10, -0.51) is outside the image"),
    ("B,5,ten,10", "row 3: pixel ('ten', '10') is not two numbers"),
    ("B,5,10", "row 3: expected 4 columns"),
])
def test_a_bad_marks_file_is_one_line_naming_file_row_and_problem(tmp_path, rows, problem):
    marks = tmp_path / "marks.csv"
    marks.write_text(f"name,frame_or_image,x_px,y_px\nA,4,300,200\n{rows}\n")
    with pytest.raises(ConfigError) as exc:
        load_flight_config(_flight(tmp_path, marks_file="marks.csv"))
    msg = str(exc.value)
    assert msg.startswith(f"{marks}: {problem}") and "\n" not in msg, msg


def test_a_marks_file_that_is_a_folder_or_not_text_is_one_plain_line(tmp_path):
    """A folder given as the marks file, or a binary one: one line, without Python's '[Errno 21] Is a directory:
    ...' (the path twice) or the codec's byte positions; the same for `ridgeloc locate --marks`."""
    from pipeline.locate import read_marks

    (tmp_path / "marks_dir").mkdir()
    (tmp_path / "bin.csv").write_bytes(b"\xff\xfe\x00 not text")
    for name, problem in (("marks_dir", "a folder, not a marks file: give the marks CSV in it"),
                          ("bin.csv", "cannot read the marks file: not UTF-8 text (a CSV is expected)")):
        with pytest.raises(ConfigError) as exc:
            load_flight_config(_flight(tmp_path, marks_file=name))
        assert str(exc.value).startswith(f"{tmp_path / name}: {problem}"), str(exc.value)
        with pytest.raises(InputError) as exc:
            read_marks(str(tmp_path / name), [])
        assert str(exc.value).startswith(f"{tmp_path / name}: {problem}"), str(exc.value)
        assert "Errno" not in str(exc.value) and "codec" not in str(exc.value)


@pytest.mark.parametrize("u, v, inside", [
    (-0.5, -0.5, True), (599.5, 399.5, True), (0, 0, True), (300, 200, True),  # pixel centres at integers:
    (-0.51, 10, False), (10, -0.51, False), (599.51, 10, False), (10, 399.51, False)])  # the image spans +-0.5
def test_one_pixel_in_image_rule_for_marks_and_photos(tmp_path, u, v, inside):
    from pipeline.locate import check_pixels

    assert in_image(u, v, 600, 400) is inside
    marks = tmp_path / "marks.csv"
    marks.write_text(f"name,frame_or_image,x_px,y_px\nA,4,{u},{v}\n")
    try:
        load_flight_config(_flight(tmp_path, marks_file="marks.csv"))
        marks_ok = True
    except ConfigError as exc:
        assert "outside the image" in str(exc)
        marks_ok = False
    photo = type("P", (), {"width_px": 600, "height_px": 400, "path": "p.jpg"})()
    try:
        check_pixels([photo], [(u, v)])
        photo_ok = True
    except InputError:
        photo_ok = False
    assert marks_ok is photo_ok is inside


def test_a_bad_marks_file_stops_the_run_before_anything_is_written(tmp_path):
    (tmp_path / "marks.csv").write_text("name,frame_or_image,x_px,y_px\nA,4,300,200\nB,200,10,10\n")
    out = tmp_path / "out"
    r = subprocess.run([sys.executable, "-m", "pipeline", "run", str(_flight(tmp_path, marks_file="marks.csv")),
                        "-o", str(out), "-q"], cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert r.returncode != 0 and not out.exists()
    assert r.stderr.strip().splitlines() == [
        f"ridgeloc: error: {tmp_path / 'marks.csv'}: row 3: frame index 200 out of range (the video has frames 0..143)"]


def test_targets_list_with_several_marks_and_truth(tmp_path):
    cfg = load_flight_config(_flight(tmp_path, targets=[
        {"name": "A", "frame_index": 4, "pixel": [300.0, 200.0], "marks": [{"frame_index": 50, "pixel": [290, 210]}],
         "truth": {"lat_deg": 34.36, "lon_deg": 108.76, "alt_m": 372.0}},
        {"name": "B", "frame_index": 4, "pixel": [100.0, 100.0]}]))
    a, b = flight_targets(cfg)
    assert [(m.frame_index, m.pixel) for m in a.marks] == [(4, (300.0, 200.0)), (50, (290.0, 210.0))]
    assert a.truth_lla == (34.36, 108.76, 372.0) and b.truth_lla is None


def test_single_target_stays_a_one_element_unnamed_list(tmp_path):
    cfg = load_flight_config(ROOT / "configs" / "flights" / "group1.yaml")
    (t,) = flight_targets(cfg)
    assert t.name is None and (t.marks[0].frame_index, t.marks[0].pixel) == (4, (304.02, 200.08))


@pytest.mark.parametrize("keys, problem", [
    ({"target": {"frame_index": 4, "pixel": [1.0, 1.0]}, "targets": [{"name": "A", "frame_index": 4,
                                                                      "pixel": [300.0, 200.0]}]}, "not both"),
    ({"targets": [{"name": "A", "frame_index": 4, "pixel": [300.0, 200.0]},
                  {"name": "A", "frame_index": 5, "pixel": [300.0, 200.0]}]}, "two targets are named 'A'"),
    ({"targets": [{"name": "a/b", "frame_index": 4, "pixel": [300.0, 200.0]}]}, "folder-safe"),
    ({"targets": [{"name": "A", "frame_index": 400, "pixel": [300.0, 200.0]}]},
     "targets[0] (A): frame index 400 out of range"),
    ({"targets": [{"name": "A", "frame_index": -4, "pixel": [300.0, 200.0]}]},
     "targets[0].frame_index: must be >= 0, got -4"),
    ({"targets": [{"name": "A", "frame_index": 4, "pixel": [300.0, 200.0],
                   "truth": {"lat_deg": 400.0, "lon_deg": 7.5, "alt_m": 0.0}}]},
     "targets[0].truth.lat_deg: must be <= 90, got 400"),
])
def test_targets_list_errors(tmp_path, keys, problem):
    with pytest.raises(ConfigError, match=None) as exc:
        load_flight_config(_flight(tmp_path, **keys))
    assert problem in str(exc.value)


def test_check_names_a_target_marked_on_a_frame_the_video_does_not_have(tmp_path):
    """Without a frames CSV the frame numbers are known only once the video is opened: `ridgeloc check` then
    checks every target's marks (not only the first), naming the target."""
    path = _flight(tmp_path, targets=[{"name": "panel", "frame_index": 4, "pixel": [303.0, 198.6]},
                                      {"name": "pole", "frame_index": 500, "pixel": [100.0, 100.0]}])
    doc = yaml.safe_load(path.read_text())
    del doc["files"]["frames_csv"]
    path.write_text(yaml.safe_dump(doc))
    r = subprocess.run([sys.executable, "-m", "pipeline", "check", str(path), "--no-clock"], cwd=ROOT,
                       capture_output=True, text=True, timeout=120)
    assert r.returncode != 0, r.stdout + r.stderr
    assert "problem: target 'pole' (" in r.stdout and "frame 500 is not a frame of the video" in r.stdout, r.stdout
    assert "'panel'" not in r.stdout


@pytest.mark.parametrize("change, problem", [
    (lambda d: d["targets"][1].update(lat_deg=400.0), "targets[1].lat_deg: must be <= 90, got 400"),
    (lambda d: d["targets"][0].update(alt_m="372"), "targets[0].alt_m: must be a finite number, got str"),
    (lambda d: d["targets"][2].pop("name"), "targets[2].name: is required"),
    (lambda d: d["target"].update(lon_deg=float("nan")), "target.lon_deg: must be a finite number"),
    (lambda d: d["targets"][2].update(name="panel"), "targets: duplicate name 'panel'"),
])
def test_a_broken_truth_file_is_refused_at_load_naming_file_and_key(tmp_path, change, problem):
    import json

    doc = json.loads((ROOT / "sample_data" / "three_targets" / "truth.json").read_text())
    change(doc)
    truth = tmp_path / "truth.json"
    truth.write_text(json.dumps(doc))  # NaN written as the JSON extension NaN, as Python reads it
    with pytest.raises(ConfigError) as exc:
        load_flight_config(_flight(tmp_path, truth_file=str(truth)))
    msg = str(exc.value)
    assert msg.startswith(f"{truth}: {problem}") and "\n" not in msg, msg


def test_the_truth_file_gives_each_named_target_its_truth(tmp_path):
    from pipeline.target_stage import truth_file_targets

    cfg = load_flight_config(_flight(tmp_path, truth_file=str(ROOT / "sample_data" / "three_targets" / "truth.json")))
    named = truth_file_targets(cfg)
    assert list(named) == ["panel", "small_grey", "far_north"]
    assert named["panel"] == (34.36, 108.76, 372.0) == cfg.truth_lla()  # the main target is the first, at the origin


@pytest.mark.parametrize("pixel, problem", [
    ([-40, 99999], "target: pixel (-40, 99999) is outside the image (600x400 px)"),
    ([200, 500], "target: pixel (200, 500) is outside the image (600x400 px); it looks like [row, column]: give "
                 "[x (column), y (row)]"),
])
def test_the_single_target_mark_is_checked_at_load_too(tmp_path, pixel, problem):
    path = _flight(tmp_path, target={"frame_index": 4, "pixel": pixel})
    with pytest.raises(ConfigError) as exc:
        load_flight_config(path)
    assert str(exc.value) == f"{path.resolve()}: {problem}"


def test_a_truth_file_without_the_single_targets_truth_is_refused_at_load(tmp_path):
    import json

    truth = tmp_path / "truth.json"
    truth.write_text(json.dumps({"targets": [{"name": "a", "lat_deg": 1.0, "lon_deg": 2.0, "alt_m": 3.0}]}))
    path = _flight(tmp_path, truth_file=str(truth), target={"frame_index": 4, "pixel": [300, 200]})
    with pytest.raises(ConfigError) as exc:
        load_flight_config(path)
    assert str(exc.value) == (f"{path.resolve()}: truth_file: no 'target' in {truth} (the truth of the flight's one "
                              "target)")
    truth.write_text(json.dumps({"targets": None, "target": {"lat_deg": 1.0, "lon_deg": 2.0, "alt_m": 3.0}}))
    assert load_flight_config(path).truth_lla() == (1.0, 2.0, 3.0)  # a rewritten file is read again
