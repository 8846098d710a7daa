"""Command-line layer: one module per `ridgeloc` subcommand, each thin over library functions; the checks they
share on output paths (made before any work) and on a log given where a config belongs."""

from __future__ import annotations

from os import PathLike
from pathlib import Path

from pipeline.errors import InputError, RidgelocError


def output_folder(path: str | PathLike, option: str = "-o") -> Path:
    """`path` as an output folder (existing or not); InputError when it, or the nearest existing parent, is a file
    (`option`: how the command line names it)."""
    path = Path(path)
    if path.exists() and not path.is_dir():
        raise InputError(f"is a file, not a folder: {option} names the folder to write the outputs into", path)
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


def not_a_config(path: str | PathLike) -> InputError | None:
    """The one-line error for a folder, a telemetry log, bag, video or drone photo given where a flight or run config
    belongs (by the readers' own suffix and content sniffing), saying what to do with it; None otherwise."""
    from pipeline.ingest.dispatch import detect_format
    from pipeline.ingest.photo_inspect import is_photo_input

    p = Path(path)
    if p.suffix.lower() in (".yaml", ".yml") or not p.exists():
        return None
    if is_photo_input(p):
        return InputError("drone photos, not a flight config: use `ridgeloc inspect` or `ridgeloc locate`", p)
    try:
        fmt = detect_format(p)
    except RidgelocError:
        return _a_folder(p) if p.is_dir() else None
    if fmt == "video":
        return InputError(f"a video, not a flight config: `ridgeloc init {p.parent}` writes one from the flight's "
                          "files, or name it in a flight config's files.video", p)
    return InputError(f"a telemetry log, not a flight config: `ridgeloc init {p.parent}` writes one from the flight's "
                      "files, or name it in a flight config's files.telemetry", p)


def _a_folder(p: Path) -> InputError:
    """A folder (not a bag, not photos) given where a flight config belongs: its flight.yaml, or how to write one."""
    config = p / "flight.yaml"
    if config.is_file():
        return InputError(f"a folder, not a flight config: give its flight config, {config}", p)
    return InputError(f"a folder, not a flight config: `ridgeloc init {p}` writes one from its files", p)


def read_photos_reporting(paths, alt_datum: str | None = None) -> tuple[list, list[tuple[str, str]]]:
    """`pipeline.ingest.photo.read_photos`, each unreadable photo's one-line error printed on stderr; InputError
    when none is readable: the photo's own error when it was the only one, "no photos" for folders without any."""
    import sys

    from pipeline.ingest.photo import PHOTO_SUFFIXES, read_photos

    photos, bad = read_photos(paths, alt_datum=alt_datum)
    if not photos and len(bad) == 1:
        raise InputError(bad[0][1])
    for _path, err in bad:
        print(f"ridgeloc: error: {err}", file=sys.stderr)
    if not photos:
        where = ", ".join(map(str, paths))
        if not bad:
            raise InputError(f"{where}: no photos ({', '.join(PHOTO_SUFFIXES)} files) here")
        raise InputError(f"no readable photo among {where}")
    return photos, bad

