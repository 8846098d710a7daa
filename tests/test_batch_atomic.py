"""Atomic writes: a failing or interrupted writer leaves the old file/folder or nothing, never a partial one."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap

import pytest

from pipeline import atomic
from pipeline.atomic import (
    atomic_dir,
    atomic_write_bytes,
    atomic_write_text,
    config_hash,
    is_done,
    remove_stale_temporaries,
    write_done_marker,
)


def test_write_and_replace(tmp_path):
    p = tmp_path / "sub" / "a.txt"
    atomic_write_text(p, "first")
    atomic_write_text(p, "second")
    assert p.read_text() == "second"
    assert sorted(os.listdir(p.parent)) == ["a.txt"]


@pytest.mark.parametrize("exc", [OSError("disk full"), KeyboardInterrupt()])
def test_failing_write_keeps_the_old_file_and_no_temporary(tmp_path, monkeypatch, exc):
    p = tmp_path / "targets.csv"
    atomic_write_bytes(p, b"old complete content")

    def fail(fd):
        raise exc
    monkeypatch.setattr(atomic.os, "fsync", fail)  # fails after the data went to the temporary
    with pytest.raises(type(exc)):
        atomic_write_bytes(p, b"new content that never lands")
    assert p.read_bytes() == b"old complete content"
    assert os.listdir(tmp_path) == ["targets.csv"]


def test_failing_write_of_a_new_file_leaves_nothing(tmp_path, monkeypatch):
    monkeypatch.setattr(atomic.os, "replace", lambda a, b: (_ for _ in ()).throw(OSError("no")))
    with pytest.raises(OSError):
        atomic_write_text(tmp_path / "report.html", "<html>")
    assert os.listdir(tmp_path) == []


@pytest.mark.parametrize("exc", [RuntimeError("figure failed"), KeyboardInterrupt()])
def test_folder_is_all_or_nothing(tmp_path, exc):
    final = tmp_path / "group1"
    with atomic_dir(final) as d:
        (d / "result.json").write_text("{}")
    assert (final / "result.json").is_file()
    with pytest.raises(type(exc)), atomic_dir(final) as d:
        (d / "result.json").write_text('{"new": 1}')
        (d / "map.png").write_bytes(b"half")
        raise exc
    assert (final / "result.json").read_text() == "{}"  # the old folder, untouched
    assert not (final / "map.png").exists()
    assert sorted(os.listdir(tmp_path)) == ["group1"]


def test_killed_writer_leaves_no_partial_file(tmp_path):
    """A process killed (SIGKILL) in the middle of writing a large file: the target never holds a partial file,
    and the next run's cleanup removes the temporary."""
    target = tmp_path / "big.bin"
    atomic_write_bytes(target, b"old")
    code = textwrap.dedent(f"""
        import os, sys
        from pipeline import atomic
        real = os.fdopen
        class Slow:
            def __init__(self, f): self.f = f
            def __enter__(self): return self
            def __exit__(self, *a): self.f.close()
            def write(self, data):
                self.f.write(data[:1000]); self.f.flush()
                print("writing", flush=True)
                os.kill(os.getpid(), 9)
            def flush(self): pass
            def fileno(self): return self.f.fileno()
        atomic.os.fdopen = lambda fd, mode: Slow(real(fd, mode))
        atomic.atomic_write_bytes({str(target)!r}, b"x" * 10_000_000)
    """)
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert proc.returncode == -9 and "writing" in proc.stdout
    assert target.read_bytes() == b"old"
    leftovers = [p for p in tmp_path.iterdir() if p.name.startswith(".tmp-")]
    assert len(leftovers) == 1
    assert remove_stale_temporaries(tmp_path) == leftovers
    assert sorted(os.listdir(tmp_path)) == ["big.bin"]


def test_done_marker_and_config_hash(tmp_path):
    h = config_hash({"b": [1, 2], "a": {"x": 1.5}})
    assert h == config_hash({"a": {"x": 1.5}, "b": [1, 2]})  # key order does not matter
    assert h != config_hash({"a": {"x": 1.5}, "b": [1, 3]})
    assert len(h) == 64
    assert not is_done(tmp_path)
    write_done_marker(tmp_path, h)
    assert is_done(tmp_path) and is_done(tmp_path, h) and not is_done(tmp_path, "other")
    assert not is_done(tmp_path / "missing", h)


def test_a_full_disk_is_one_line_and_leaves_nothing_trusted(tmp_path, capsys, monkeypatch):
    """ENOSPC from every write under the output folder (a patched writer standing in for a full tmpfs): the run
    exits 1 with one-line messages naming the file, and leaves no group folder a re-run would trust."""
    import errno
    import pathlib

    import yaml

    from pipeline.atomic import is_done
    from pipeline.cli import main

    repo = pathlib.Path(__file__).resolve().parents[1]
    src = repo / "configs" / "flights" / "group6.yaml"
    doc = yaml.safe_load(src.read_text())
    doc["files"] = {k: [str((src.parent / p).resolve()) for p in v] if isinstance(v, list)
                    else str((src.parent / v).resolve()) for k, v in doc["files"].items()}
    doc["truth_file"] = str((src.parent / doc["truth_file"]).resolve())
    cfg = tmp_path / "flight.yaml"
    cfg.write_text(yaml.safe_dump(doc))
    out = tmp_path / "out"
    real_open = open

    def full_open(file, mode="r", *args, **kw):
        if any(m in mode for m in "wax") and str(file).startswith(str(out)):
            raise OSError(errno.ENOSPC, "No space left on device", str(file))
        return real_open(file, mode, *args, **kw)

    real_fdopen = os.fdopen

    def full_fdopen(fd, mode="r", *args, **kw):
        if any(m in mode for m in "wax"):
            raise OSError(errno.ENOSPC, "No space left on device")
        return real_fdopen(fd, mode, *args, **kw)

    monkeypatch.setattr("builtins.open", full_open)
    monkeypatch.setattr(os, "fdopen", full_fdopen)
    monkeypatch.setattr(pathlib.Path, "write_text",
                        lambda self, *a, **k: full_open(self, "w").write(a[0]))
    monkeypatch.setattr(pathlib.Path, "write_bytes",
                        lambda self, *a, **k: full_open(self, "wb").write(a[0]))
    rc = main(["run", str(cfg), "-o", str(out), "--no-figures", "-q"])
    err = capsys.readouterr().err
    assert rc == 1 and "Traceback" not in err
    lines = err.strip().splitlines()
    assert lines and all(line.startswith("ridgeloc: ") for line in lines)
    assert any("No space left on device" in line for line in lines), err
    assert not any(p.is_dir() and is_done(p) for p in out.glob("*")) if out.exists() else True
