"""Command-line layer: one module per `ridgeloc` subcommand, each thin over library functions; the output-path
checks they share, made before any work."""

from __future__ import annotations

from os import PathLike
from pathlib import Path

from pipeline.errors import InputError


def output_folder(path: str | PathLike) -> Path:
    """`path` as an output folder (existing or not); InputError when it, or the nearest existing parent, is a file."""
    path = Path(path)
    if path.exists() and not path.is_dir():
        raise InputError("cannot create the output folder: File exists", path)
    _parent_is_a_folder(path, "cannot create the output folder")
    return path


def output_file(path: str | PathLike, example_name: str) -> Path:
    """`path` as an output file; InputError when it is a folder (naming `example_name` inside it as the fix) or
    the nearest existing parent is a file."""
    path = Path(path)
    if path.is_dir():
        raise InputError(f"is a folder: name the file to write, e.g. {path / example_name}", path)
    _parent_is_a_folder(path, "cannot write")
    return path


def _parent_is_a_folder(path: Path, what: str) -> None:
    parent = next((p for p in path.parents if p.exists()), None)
    if parent is not None and not parent.is_dir():
        raise InputError(f"{what}: {parent} is not a folder", path)
