"""The reader boundary: what a third-party parser raises on damaged bytes becomes one line naming the file.

Damaged bytes can make a parser (pymavlink, pyulog, rosbags, mcap, zstd, sqlite, Pillow, exifread) raise
anything. Such an exception becomes `<file>: damaged <what>: <exception> <message>`; an OSError with an errno (an
I/O failure such as a permission or a disk error, not damage) `<file>: cannot read: <reason>`; MemoryError "cannot
be read within the memory available". One raised in ridgeloc's own code is a bug and is not translated
(scripts/fuzz.py hunts for those), nor is a RidgelocError (already one line naming the file)."""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from pipeline.errors import InputError, RidgelocError

_PACKAGE = Path(__file__).resolve().parents[1]


def raised_by_library(exc: BaseException) -> bool:
    """True when the innermost Python frame of exc's traceback lies outside the pipeline package."""
    tb = exc.__traceback__
    while tb is not None and tb.tb_next is not None:
        tb = tb.tb_next
    return tb is not None and not Path(tb.tb_frame.f_code.co_filename).resolve().is_relative_to(_PACKAGE)


@contextmanager
def reader_boundary(path, what: str = "file", error: type[InputError] = InputError) -> Iterator[None]:
    """Translate, as the module docstring says, what the block raises into `error(..., path=path)`."""
    try:
        yield
    except RidgelocError:
        raise
    except MemoryError:
        raise error("cannot be read within the memory available (a damaged length field?)", path=path) from None
    except Exception as exc:
        if isinstance(exc, OSError) and exc.errno is not None:  # naming the file it was about when not `path`
            other = f" ({exc.filename})" if exc.filename and Path(exc.filename) != Path(path) else ""
            raise error(f"cannot read: {exc.strerror or exc}{other}", path=path) from None
        if not raised_by_library(exc):
            raise
        text = str(exc).splitlines()[0][:200] if str(exc) else ""
        raise error(f"damaged {what}: {type(exc).__name__} {text}".rstrip(), path=path) from None
