"""One error hierarchy. Every message is one line that names the file (when there is one) and the problem.

The CLI turns any `RidgelocError` into `ridgeloc: error: <message>` and a non-zero exit; anything else
escaping is a bug in ridgeloc, not a user mistake.
"""

from __future__ import annotations

from os import PathLike


class RidgelocError(Exception):
    """Base class for errors caused by input, configuration or geometry (not by a bug)."""

    def __init__(self, message: str, path: str | PathLike | None = None):
        self.path = None if path is None else str(path)
        super().__init__(f"{self.path}: {message}" if self.path else message)


class InputError(RidgelocError):
    """A file or value the user supplied is malformed, inconsistent or unusable."""


class ConfigError(InputError):
    """A configuration file has unknown keys, wrong types or units, or points at missing files."""


class LogReadError(InputError):
    """A flight log, bag or video cannot be read (truncated, garbage, missing definitions, no data)."""


class ObservationError(InputError):
    """Observations cannot be used by an estimator (too few, non-finite, mismatched, degenerate)."""


class GeometryError(ObservationError):
    """The observation geometry does not determine the target (collinear, coincident, behind camera)."""


def none_located(failures, path: str | PathLike | None) -> InputError:
    """The error of a flight none of whose targets could be located: each target's reason, without the config's
    path that the error already starts with. `failures`: objects with `target` and `message`."""
    prefix = f"{path}: " if path is not None else None

    def reason(message: str) -> str:
        return message[len(prefix):] if prefix and message.startswith(prefix) else message

    return InputError("no target could be located: " + "; ".join(f"{f.target}: {reason(f.message)}" for f in failures),
                      path)


def environment_error_message(exc: BaseException) -> str | None:
    """One line for an OSError the machine caused (full disk, quota, read-only file system, permissions, I/O
    error), naming the file; None for anything else (a bug, not the user's environment)."""
    import errno

    if not isinstance(exc, OSError) or exc.errno not in (errno.ENOSPC, errno.EDQUOT, errno.EROFS, errno.EACCES,
                                                         errno.EPERM, errno.EIO, errno.EMFILE, errno.ENFILE):
        return None
    where = f"{exc.filename}: " if exc.filename else ""
    hint = " (free some space and run again: finished work is kept)" if exc.errno in (errno.ENOSPC, errno.EDQUOT) \
        else ""
    return f"{where}{exc.strerror or exc}{hint}"


class SolverError(RidgelocError):
    """An estimator failed in a way the caller should hear about (for example divergence)."""
