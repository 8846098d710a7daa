"""`ridgeloc inspect`: tables for every real log, exit status and one-line errors."""

from __future__ import annotations

import json
from pathlib import Path

from pipeline.cli import main

LOGS = Path(__file__).resolve().parents[1] / ".." / "shared" / "logs"
REAL = sorted(p for p in LOGS.iterdir() if p.name != "README.md")


def test_inspect_every_real_log(capsys):
    assert main(["inspect", *map(str, REAL)]) == 0
    out = capsys.readouterr().out
    assert "GLOBAL_POSITION_INT" in out and "807" in out
    assert "/gps/fix" in out and "sensor_msgs/msg/NavSatFix" in out and "151" in out
    assert "missing for localization: position, attitude, gimbal, range, frames" in out  # the talker bag
    assert "iterated 0 of 20 messages" in out
    assert "truncated" in out  # the 64 KiB DataFlash log
    assert out.count("\n  missing for localization:") == len(REAL)
    assert "all files named together, missing for localization: gimbal, range" in out


def test_inspect_json_and_bad_file(tmp_path, capsys):
    bad = tmp_path / "broken.tlog"
    bad.write_bytes(b"\x00" * 100)
    rc = main(["inspect", "--json", str(LOGS / "rviz_satellite_sample_gps.bag"), str(bad)])
    cap = capsys.readouterr()
    assert rc == 1
    doc = json.loads(cap.out)
    good = doc["files"][0]
    assert good["streams"][0]["count"] == 151 and good["streams"][0]["supplies"] == ["position"]
    assert abs(good["streams"][0]["rate_hz"] - 10.0) < 0.05
    assert good["read"]["position"]["alt_datum"] == "ellipsoid"
    assert "error" in doc["files"][1]
    errs = [ln for ln in cap.err.splitlines() if ln]
    assert len(errs) == 1 and "broken.tlog" in errs[0] and errs[0].startswith("ridgeloc: error:")


def test_inspect_flight_folder(tmp_path, capsys):
    import shutil

    folder = tmp_path / "flight"
    folder.mkdir()
    shutil.copy(LOGS / "rviz_satellite_sample_gps.bag", folder / "gps.bag")
    shutil.copy(LOGS / "ubiquity_fiducials_aruco_marker.bag", folder / "camera.bag")
    (folder / "truth.json").write_text("{}")
    assert main(["inspect", str(folder)]) == 0
    out = capsys.readouterr().out
    assert "gps.bag  [ros1]" in out and "camera.bag  [ros1]" in out and "truth.json" not in out
    assert f"all files of {folder} together, missing for localization: attitude, gimbal, range" in out


def test_inspect_a_folder_without_logs_is_one_line_and_exit_1(tmp_path, capsys):
    """An empty folder, one of notes only and one named like a log: one line each, not silence and exit 0."""
    empty, notes, named = tmp_path / "empty", tmp_path / "notes", tmp_path / "x.tlog"
    for d in (empty, notes, named):
        d.mkdir()
    (notes / "notes.txt").write_text("flown on Tuesday\n")
    for d in (empty, notes, named):
        assert main(["inspect", str(d)]) == 1
        cap = capsys.readouterr()
        assert cap.out == "" and cap.err.splitlines() == [f"ridgeloc: error: {d}: no logs, videos or photos found"]
    assert main(["inspect", "--json", str(empty)]) == 1
    cap = capsys.readouterr()
    assert json.loads(cap.out)["files"] == [{"path": str(empty), "error": f"{empty}: no logs, videos or photos found"}]
