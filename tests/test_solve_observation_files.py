"""`ridgeloc solve` on malformed observation files: one line naming the file and the problem, exit 1, never a
traceback; non-finite numbers refused with their location; null means missing; sizes capped."""

import json
from pathlib import Path

import pytest

import pipeline.observation_file as observations_mod
from pipeline.cli import main

ROOT = Path(__file__).resolve().parents[1]
EXAMPLE = (ROOT / "configs" / "example_observations.json").read_text()
FIRST_RANGE = '"range_m": 5003.818561195679'


def _solve(path, capsys) -> tuple[int, str, str]:
    rc = main(["solve", "--method", "vision", str(path)])
    out, err = capsys.readouterr()
    return rc, out, err


def _refused(tmp_path, capsys, text: str | bytes, *expected: str) -> str:
    path = tmp_path / "obs.json"
    path.write_bytes(text if isinstance(text, bytes) else text.encode())
    rc, out, err = _solve(path, capsys)
    assert rc == 1 and out == ""
    assert err.count("\n") == 1 and err.startswith(f"ridgeloc: error: {path}: "), err
    for e in expected:
        assert e in err, err
    return err


def test_the_example_is_accepted(tmp_path, capsys):
    (tmp_path / "obs.json").write_text(EXAMPLE)
    rc, out, _ = _solve(tmp_path / "obs.json", capsys)
    assert rc == 0 and "vision" in out


def test_deep_nesting_is_one_line(tmp_path, capsys):
    _refused(tmp_path, capsys, '{"observations": ' + "[" * 200_000 + "]" * 200_000 + "}", "nested too deeply")
    _refused(tmp_path, capsys, '{"observations": [1], "meta": ' + "[" * 100 + "]" * 100 + "}",
             "meta[0][0]", "nested more than 32 levels deep")


@pytest.mark.parametrize(("token", "where"), [("NaN", "observations[0].range_m is NaN"),
                                               ("Infinity", "observations[0].range_m is Infinity"),
                                               ("-Infinity", "observations[0].range_m is -Infinity"),
                                               ("1e999", "observations[0].range_m is 1e999, which overflows")])
def test_non_finite_numbers_are_refused_with_their_location(tmp_path, capsys, token, where):
    err = _refused(tmp_path, capsys, EXAMPLE.replace(FIRST_RANGE, f'"range_m": {token}', 1), where)
    assert "refused" in err


def test_null_means_missing(tmp_path, capsys):
    doc = json.loads(EXAMPLE)
    row = doc["observations"][1]
    row["pixel"] = row["range_m"] = row["t_ns"] = None
    doc["sigma"] = {"pixel_px": None}
    doc["truth_m"] = None
    (tmp_path / "obs.json").write_text(json.dumps(doc))
    obs = observations_mod.load(tmp_path / "obs.json")
    assert not obs.has_pixel[1] and not obs.has_range[1] and obs.t_ns[1] == 1 and obs.truth_m is None
    row["P"] = None  # a required key given as null is missing, not a crash
    _refused(tmp_path, capsys, json.dumps(doc), "observations[1] lacks required key(s): P")


@pytest.mark.parametrize(("edit", "expected"), [
    (("1291.7088319144384", '"abc"'), "observations[0].platform_m must be [x, y, z]"),
    (('"t_ns": 0', '"t_ns": ' + "9" * 25), "observations[0].t_ns must be a 64-bit integer"),
    (('"t_ns": 0', '"t_ns": ' + "9" * 5000), "observations[0].t_ns is an integer of 5000 digits"),
    (('"t_ns": 0', '"t_ns": true'), "observations[0].t_ns must be a 64-bit integer"),
    (("880.5232414187631", "[1, 2]"), "observations[0].P[0] must be a row of 4 numbers"),
    (("299.9206877524842", '{"u": 1}'), "observations[0].pixel must be [u, v] or null"),
    ((FIRST_RANGE, '"range_m": "5000"'), "observations[0].range_m must be a number or null"),
])
def test_wrong_types_name_the_key(tmp_path, capsys, edit, expected):
    assert edit[0] in EXAMPLE
    _refused(tmp_path, capsys, EXAMPLE.replace(*edit, 1), expected)


@pytest.mark.parametrize(("key", "value", "expected"), [
    ("truth_m", [1, "x", 3], "truth_m must be [x, y, z]"), ("sigma", [1], "'sigma' must be an object"),
    ("sigma", {"range_m": "2"}, "'sigma.range_m' must be a finite number"), ("extra", 1, "unknown top-level key"),
])
def test_wrong_top_level_values(tmp_path, capsys, key, value, expected):
    doc = json.loads(EXAMPLE)
    doc[key] = value
    _refused(tmp_path, capsys, json.dumps(doc), expected)


@pytest.mark.parametrize(("text", "expected"), [
    ("", "not valid JSON"), (EXAMPLE[: len(EXAMPLE) // 2], "not valid JSON"), ("[]", "top level must be"),
    ('{"observations": []}', "non-empty list"), (b"\xff\xfe\x00\x01garbage", "not UTF-8"),
    ('{"observations": [{"P": 1, "platform_m": [0, 0, 0]}]}', "observations[0].P must be 3x4"),
])
def test_truncated_and_garbage_files(tmp_path, capsys, text, expected):
    _refused(tmp_path, capsys, text, expected)


def test_size_cap_directory_missing_and_unreadable(tmp_path, capsys, monkeypatch):
    monkeypatch.setattr(observations_mod, "MAX_FILE_BYTES", 1000)
    _refused(tmp_path, capsys, EXAMPLE, "MB, over the 0.000953674 MB limit for an observations file")
    monkeypatch.undo()
    (tmp_path / "a_dir.json").mkdir()
    for path, expected in ((tmp_path / "a_dir.json", "is a directory, expected an observations JSON file"),
                           (tmp_path / "none.json", "file not found")):
        rc, _, err = _solve(path, capsys)
        assert rc == 1 and err == f"ridgeloc: error: {path}: {expected}\n"
    path = tmp_path / "locked.json"
    path.write_text(EXAMPLE)

    def denied(file, *args, **kw):
        raise PermissionError(13, "Permission denied", str(file))

    monkeypatch.setattr("builtins.open", denied)  # chmod 000 does not stop root, so the OS error is simulated
    rc, _, err = _solve(path, capsys)
    assert rc == 1 and err == f"ridgeloc: error: {path}: cannot read: Permission denied\n"
