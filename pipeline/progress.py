"""Progress of the job running in this context: `report_stage(stage)` announces the stage a job has entered
(e.g. "ingest", "track", "solve"); `pipeline.batch` installs the reporter around each job (`_reporter`). Here, below
every stage, so that a stage reports progress without importing the batch executor above it."""

from __future__ import annotations

import contextlib
import contextvars
from collections.abc import Callable

_reporter: contextvars.ContextVar[Callable[[str], None] | None] = contextvars.ContextVar("ridgeloc_stage",
                                                                                          default=None)


def report_stage(stage: str) -> None:
    """Announce that the current job entered `stage`. No-op outside `pipeline.batch.run_jobs`."""
    reporter = _reporter.get()
    if reporter is not None:
        with contextlib.suppress(Exception):  # progress display must never fail a flight
            reporter(stage)
