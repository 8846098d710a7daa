"""Atomic writes: a file or a folder appears complete under its final name, or not at all.

A crash, an exception or Ctrl-C while writing leaves at most a hidden temporary (`.tmp-*`) next to the target,
never a half-written file under the final name. Files go through a temporary in the same folder and
`os.replace` (atomic on POSIX and Windows when source and target are on the same file system). Folders are
built under `.tmp-<name>-<pid>` and renamed into place.

A finished folder carries a marker file (`.done`) holding a hash of the configuration that produced it, so a
re-run can skip work that is already done for the same configuration.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import os
import shutil
import tempfile
from collections.abc import Iterator
from os import PathLike
from pathlib import Path

DONE_MARKER = ".done"
TMP_PREFIX = ".tmp-"


def atomic_write_bytes(path: str | PathLike, data: bytes) -> None:
    """Write `data` to `path` atomically (temporary file in the same folder, fsync, os.replace)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f"{TMP_PREFIX}{path.name}-", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
        os.chmod(tmp, 0o644)
        os.replace(tmp, path)
    except BaseException as exc:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)
        if isinstance(exc, OSError) and exc.filename is None:  # e.g. ENOSPC from write(): name the target
            raise OSError(exc.errno, exc.strerror, str(path)) from exc
        raise


def atomic_write_text(path: str | PathLike, text: str, encoding: str = "utf-8") -> None:
    """Write `text` to `path` atomically (see `atomic_write_bytes`)."""
    atomic_write_bytes(path, text.encode(encoding))


@contextlib.contextmanager
def atomic_dir(path: str | PathLike) -> Iterator[Path]:
    """Build a folder atomically: yields a temporary folder next to `path`; when the block ends without an
    exception, an existing `path` is replaced by it, otherwise the temporary folder is removed.

    The replacement is two renames (old folder aside, new folder in), so a crash between them leaves the old
    folder under a `.tmp-` name and no `path`: never a mixed or partial folder under the final name.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.parent / f"{TMP_PREFIX}{path.name}-{os.getpid()}"
    if tmp.exists():
        shutil.rmtree(tmp)  # a leftover of an earlier crash of a process with the same pid
    tmp.mkdir()
    try:
        yield tmp
    except BaseException as exc:
        shutil.rmtree(tmp, ignore_errors=True)
        if isinstance(exc, OSError) and exc.filename is None:  # e.g. ENOSPC from write(): name the folder
            raise OSError(exc.errno, exc.strerror, str(path)) from exc
        raise
    old = None
    if path.exists():
        old = path.parent / f"{TMP_PREFIX}{path.name}-{os.getpid()}-old"
        if old.exists():
            shutil.rmtree(old)
        os.replace(path, old)
    os.replace(tmp, path)
    if old is not None:
        shutil.rmtree(old, ignore_errors=True)


def remove_stale_temporaries(folder: str | PathLike) -> list[Path]:
    """Delete `.tmp-*` leftovers of interrupted writes directly inside `folder`; returns what was removed."""
    removed = []
    folder = Path(folder)
    if not folder.is_dir():
        return removed
    for p in folder.glob(f"{TMP_PREFIX}*"):
        if p.is_dir():
            shutil.rmtree(p, ignore_errors=True)
        else:
            with contextlib.suppress(FileNotFoundError):
                p.unlink()
        removed.append(p)
    return removed


def config_hash(config) -> str:
    """sha256 (hex) of a JSON-serialisable configuration, independent of key order."""
    text = json.dumps(config, sort_keys=True, separators=(",", ":"), default=str)
    return hashlib.sha256(text.encode("utf-8")).hexdigest()


def write_done_marker(folder: str | PathLike, config_digest: str) -> None:
    """Mark `folder` as finished for the configuration with hash `config_digest`."""
    atomic_write_text(Path(folder) / DONE_MARKER, config_digest + "\n")


def is_done(folder: str | PathLike, config_digest: str | None = None) -> bool:
    """True when `folder` has a finished marker (for `config_digest` when given, else for any configuration)."""
    marker = Path(folder) / DONE_MARKER
    try:
        stored = marker.read_text().strip()
    except (FileNotFoundError, NotADirectoryError):
        return False
    return config_digest is None or stored == config_digest
