"""Command-line layer: one module per `ridgeloc` subcommand, each thin over library functions; the output-path
checks they share, made before any work."""

from __future__ import annotations

from os import PathLike
from pathlib import Path

from pipeline.errors import InputError


def output_folder(path: str | PathLike) -> Path:
    """`path` as an output folder (existing or not); InputError when it, or the nearest existing parent, is a file."""
    path = Path(path)
    for p in (path, *path.parents):
        if p.is_dir():
            return path
        if p.exists():
            why = "File exists" if p == path else f"{p} is not a folder"
            raise InputError(f"cannot create the output folder: {why}", path)
    return path


def output_file(path: str | PathLike, example_name: str) -> Path:
    """`path` as an output file; InputError when it is a folder (naming `example_name` inside it as the fix) or
    its folder cannot be created."""
    path = Path(path)
    if path.is_dir():
        raise InputError(f"is a folder: name the file to write, e.g. {path / example_name}", path)
    output_folder(path.parent)
    return path
