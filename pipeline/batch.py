"""Run many flight jobs: in this process, in local worker processes, or on a Dask distributed cluster.

    run_jobs(jobs, fn, workers=1, executor="local" | "dask", scheduler=None) -> (results, failures)
    report_stage("track")          called by a job function to show the stage it has entered
    discover_flights(path)         flight configs in a folder, or listed in a manifest (pipeline.flight_config's)
    run_groups(jobs, process, outdir, digests=..., force=False, ...)
                                   run_jobs + each group's output folder, finished groups reused on a re-run

A job that raises (a RidgelocError, or any other exception: a bug, but one flight's bug) becomes a
`GroupFailure` with a one-line message; the other jobs finish. Ctrl-C cancels the jobs not yet finished, stops
the workers and re-raises KeyboardInterrupt. Results come back in the order of `jobs`, whatever the order in
which they finished, so every executor gives the same output.

Progress: on a terminal, one bar for the whole batch and one per running flight showing its stage
(`report_stage`); on stdout, flushed, one line per finished flight with its time itemised by stage
(`GroupResult.timings_s`), and, when stdout is not a terminal (CI logs, `| tee`), one line per finished stage.
"""

from __future__ import annotations

import concurrent.futures as cf
import contextlib
import multiprocessing
import queue as queue_mod
import signal
import sys
import time
import traceback
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from os import PathLike
from pathlib import Path
from typing import Any

from pipeline.errors import ConfigError, RidgelocError, environment_error_message
from pipeline.flight_config import discover_flights
from pipeline.progress import _reporter, report_stage
from pipeline.results import GroupFailure

__all__ = ["EXECUTORS", "Job", "discover_flights", "itemised_timings", "job_digest", "report_stage", "run_groups",
           "run_jobs", "summarize_failures"]

EXECUTORS = ("local", "dask")
STAGE_TOPIC = "ridgeloc-stage"
_POLL_S = 0.1


@dataclass(frozen=True)
class Job:
    """One unit of work: `fn(payload)` is called in a worker. `name` names the outputs (the group), `source`
    the input (a config path) in messages. `payload` must be picklable for process and Dask executors."""

    name: str
    source: str
    payload: Any


# ---- what a worker runs ------------------------------------------------------------------------------------

@dataclass
class _Outcome:
    name: str
    ok: bool
    value: Any = None
    message: str = ""
    detail: str = ""
    elapsed_s: float = 0.0


def _one_line(text: str) -> str:
    lines = [ln.strip() for ln in str(text).strip().splitlines() if ln.strip()]
    return " ".join(lines) if lines else ""


def _call(fn: Callable, job: Job, sink: Callable[[str, str], None] | None) -> _Outcome:
    """Run one job, turning any exception into a failed outcome (so nothing unpicklable crosses processes)."""
    token = _reporter.set((lambda stage: sink(job.name, stage)) if sink is not None else None)
    t0 = time.perf_counter()
    try:
        value = fn(job.payload)
        return _Outcome(job.name, True, value, elapsed_s=time.perf_counter() - t0)
    except RidgelocError as exc:
        return _Outcome(job.name, False, message=_one_line(str(exc)), elapsed_s=time.perf_counter() - t0)
    except Exception as exc:
        if (env := environment_error_message(exc)) is not None:  # e.g. the disk filled while writing its folder
            return _Outcome(job.name, False, message=env, elapsed_s=time.perf_counter() - t0)
        return _Outcome(job.name, False, message=_one_line(f"internal error ({type(exc).__name__}): {exc}"),
                        detail=traceback.format_exc(), elapsed_s=time.perf_counter() - t0)
    finally:
        _reporter.reset(token)


class _QueueSink:
    """Stage reports from worker processes through a multiprocessing queue (picklable)."""

    def __init__(self, q):
        self.q = q

    def __call__(self, name: str, stage: str) -> None:
        self.q.put((name, stage))


class _DaskSink:
    """Stage reports from Dask workers as structured events the client subscribes to."""

    def __call__(self, name: str, stage: str) -> None:
        from distributed import get_worker

        get_worker().log_event(STAGE_TOPIC, {"name": name, "stage": stage})


def _ignore_sigint() -> None:
    # Ctrl-C goes to the whole process group; the parent decides, the workers must not print tracebacks
    signal.signal(signal.SIGINT, signal.SIG_IGN)


# ---- progress display ---------------------------------------------------------------------------------------

class _Progress:
    """What a batch shows while it runs. Bars (on stderr) only when stderr is a terminal: one for the batch and one
    per running flight with its stage. Lines on stdout, flushed as they happen: when stdout is not a terminal (a CI
    log, `| tee`), one line per finished stage of each flight; in any case one line per finished flight with its
    time itemised by stage (`GroupResult.timings_s`; `other` = the rest of the job's wall time)."""

    def __init__(self, total: int, enabled: bool, stages: Sequence[str] | None, max_bars: int, out=None):
        from tqdm.auto import tqdm

        self._tqdm = tqdm
        self.enabled = enabled
        self.out = out if out is not None else sys.stdout
        self.stage_lines = enabled and not _isatty(self.out)
        self.stages = list(stages) if stages else None
        self.max_bars = max_bars
        self.ok = self.failed = 0
        self.current: dict[str, tuple[str, float]] = {}  # flight -> (stage, when it began, perf_counter s)
        bars = enabled and _isatty(sys.stderr)
        self.bar = tqdm(total=total, desc="flights", unit="flight", position=0, disable=not bars, file=sys.stderr,
                        dynamic_ncols=True)
        self.flight_bars: dict[str, Any] = {}
        self.free_slots = list(range(1, max_bars + 1))

    def _line(self, text: str) -> None:
        if not self.enabled:
            return
        with contextlib.suppress(Exception):  # progress display must never fail a batch
            if self.bar.disable:
                print(text, file=self.out, flush=True)
            else:
                self._tqdm.write(text, file=self.out)
                self.out.flush()

    def _stage_done(self, name: str, now: float) -> None:
        prev = self.current.pop(name, None)
        if prev is not None and prev[0] != "start" and self.stage_lines:
            self._line(f"{name}: {prev[0]} finished ({now - prev[1]:.2f} s)")

    def stage(self, name: str, stage: str) -> None:
        now = time.perf_counter()
        if self.current.get(name, ("",))[0] == stage:  # re-entered at once (a flight's mark, then its track): one line
            return
        self._stage_done(name, now)
        self.current[name] = (stage, now)
        if self.bar.disable:
            return
        fb = self.flight_bars.get(name)
        if fb is None:
            if not self.free_slots:
                return
            slot = self.free_slots.pop(0)
            fb = self._tqdm(total=len(self.stages) if self.stages else None, desc=f"  {name}", position=slot,
                            leave=False, file=sys.stderr, dynamic_ncols=True,
                            bar_format="{desc} |{bar}| {n_fmt}/{total_fmt} [{elapsed}]" if self.stages
                            else "{desc} [{elapsed}]")
            fb.slot = slot
            self.flight_bars[name] = fb
        if self.stages and stage in self.stages:
            fb.n = self.stages.index(stage)
        fb.set_description_str(f"  {name}: {stage}")

    def finished(self, name: str, failure: GroupFailure | None, elapsed_s: float, timings: dict | None) -> None:
        self._stage_done(name, time.perf_counter())
        fb = self.flight_bars.pop(name, None)
        if fb is not None:
            fb.close()
            self.free_slots.append(fb.slot)
            self.free_slots.sort()
        if failure is None:
            self.ok += 1
            line = f"{name}: done in {elapsed_s:.2f} s" + itemised_timings(timings, elapsed_s)
        else:
            self.failed += 1
            line = f"{name}: FAILED: {failure.message}"
        self._line(line)
        self.bar.set_postfix(ok=self.ok, failed=self.failed)
        self.bar.update(1)

    def close(self) -> None:
        for fb in self.flight_bars.values():
            fb.close()
        self.flight_bars.clear()
        self.bar.close()


def _isatty(stream) -> bool:
    try:
        return bool(stream.isatty())
    except (AttributeError, ValueError, OSError):
        return False


def itemised_timings(timings: dict | None, elapsed_s: float | None = None) -> str:
    """' (ingest 0.52, track 0.80, ..., other 0.02 s)': a flight's wall seconds by stage; `other` is what the
    stages do not account for of `elapsed_s` (set-up, writing the folder). '' when there are no timings."""
    items = [(k, float(v)) for k, v in (timings or {}).items()
             if isinstance(v, (int, float)) and not isinstance(v, bool)]
    if not items:
        return ""
    if elapsed_s is not None:
        rest = elapsed_s - sum(v for _, v in items)
        if rest >= 0.005:
            items.append(("other", rest))
    return " (" + ", ".join(f"{k} {v:.2f}" for k, v in items) + " s)"


# ---- executors -------------------------------------------------------------------------------------------------

def _to_result(job: Job, out: _Outcome):
    if out.ok:
        return out.value, None
    return None, GroupFailure(name=job.name, source=job.source, message=out.message, detail=out.detail)


def _run_inline(jobs, fn, progress: _Progress, on_done):
    outcomes = {}
    for job in jobs:
        progress.stage(job.name, "start")
        out = _call(fn, job, progress.stage)
        outcomes[job.name] = out
        on_done(job, out)
    return outcomes


def _run_processes(jobs, fn, workers: int, progress: _Progress, on_done):
    outcomes = {}
    ctx = multiprocessing.get_context("spawn") if sys.platform == "win32" else multiprocessing.get_context()
    manager = ctx.Manager()
    try:
        stage_q = manager.Queue()
        sink = _QueueSink(stage_q)
        executor = cf.ProcessPoolExecutor(max_workers=workers, mp_context=ctx, initializer=_ignore_sigint)
        try:
            futures = {executor.submit(_call, fn, job, sink): job for job in jobs}
            pending = set(futures)
            while pending:
                done, pending = cf.wait(pending, timeout=_POLL_S, return_when=cf.FIRST_COMPLETED)
                _drain(stage_q, progress)
                for f in done:
                    job = futures[f]
                    try:
                        out = f.result()
                    except Exception as exc:  # the worker process died (killed, out of memory, segfault)
                        out = _Outcome(job.name, False, message=_one_line(f"worker process failed: {exc!r}"))
                    outcomes[job.name] = out
                    on_done(job, out)
        except BaseException:
            # Ctrl-C (or a bug here): drop what has not started, stop what runs, leave no worker behind
            procs = list((getattr(executor, "_processes", None) or {}).values())  # no public API before 3.14
            executor.shutdown(wait=False, cancel_futures=True)
            for p in procs:
                with contextlib.suppress(Exception):
                    p.terminate()
            for p in procs:
                with contextlib.suppress(Exception):
                    p.join(timeout=5)
            raise
        executor.shutdown(wait=True)
    finally:
        manager.shutdown()
    return outcomes


def _drain(q, progress: _Progress) -> None:
    while True:
        try:
            name, stage = q.get_nowait()
        except (queue_mod.Empty, EOFError, OSError):
            return
        progress.stage(name, stage)


def _dask_client(scheduler, workers: int):
    """(client, owned): a Client for `scheduler` (an address, a Client, or None for a LocalCluster of
    `workers` processes); owned = this call created it and must close it."""
    try:
        from distributed import Client, LocalCluster
    except ImportError:
        raise ConfigError("the Dask executor needs the optional extra: pip install 'ridgeloc[dask]'") from None
    if isinstance(scheduler, Client):
        return scheduler, False
    if scheduler is None:
        cluster = LocalCluster(n_workers=max(1, workers), threads_per_worker=1, processes=True,
                               dashboard_address=None)
        client = Client(cluster)
        client._ridgeloc_cluster = cluster
        return client, True
    try:
        return Client(scheduler, timeout="20s"), True
    except (OSError, TimeoutError) as exc:
        raise ConfigError(f"cannot connect to the Dask scheduler at {scheduler}: {exc}") from None


def _run_dask(jobs, fn, workers: int, scheduler, progress: _Progress, on_done):
    client, owned = _dask_client(scheduler, workers)
    events: queue_mod.Queue = queue_mod.Queue()
    outcomes = {}
    try:
        with contextlib.suppress(Exception):
            client.subscribe_topic(STAGE_TOPIC, lambda ev: events.put(ev[1]))
        # pure=False: two jobs with equal payloads are still two runs
        futures = {client.submit(_call, fn, job, _DaskSink(), pure=False, key=f"ridgeloc-{i}-{job.name}"): job
                   for i, job in enumerate(jobs)}
        pending = list(futures)
        try:
            while pending:
                still = []
                for f in pending:
                    if not f.done():
                        still.append(f)
                        continue
                    job = futures[f]
                    try:
                        out = f.result()
                    except Exception as exc:  # the worker died or the task could not run
                        out = _Outcome(job.name, False, message=_one_line(f"dask task failed: {exc!r}"))
                    outcomes[job.name] = out
                    on_done(job, out)
                pending = still
                while True:
                    try:
                        ev = events.get_nowait()
                    except queue_mod.Empty:
                        break
                    progress.stage(ev["name"], ev["stage"])
                if pending:
                    time.sleep(_POLL_S)
        except BaseException:
            with contextlib.suppress(Exception):
                client.cancel(list(futures))
            raise
    finally:
        with contextlib.suppress(Exception):
            client.unsubscribe_topic(STAGE_TOPIC)
        if owned:
            cluster = getattr(client, "_ridgeloc_cluster", None)
            client.close()
            if cluster is not None:
                cluster.close()
    return outcomes


def run_jobs(jobs: Sequence[Job], fn: Callable[[Any], Any], *, workers: int = 1, executor: str = "local",
             scheduler=None, progress: bool = True, stages: Sequence[str] | None = None,
             on_done: Callable[[Job, Any, GroupFailure | None], None] | None = None
             ) -> tuple[list[Any], list[GroupFailure]]:
    """Run `fn(job.payload)` for every job; returns (results, failures), each in the order of `jobs`.

    executor "local": in this process when workers == 1, else a pool of `workers` processes (`fn` and payloads
    must be picklable: a module-level function). executor "dask": on the cluster at `scheduler` (an address such
    as "tcp://host:8786", or a `distributed.Client`), or on a new LocalCluster of `workers` processes when None.
    `stages`: the stage names `fn` reports through `report_stage`, in order, for the per-flight bars.
    `on_done(job, result, failure)` is called in this process as each job finishes (exactly one of result and
    failure is None), e.g. to log or to write outputs. Job names must be unique.
    """
    jobs = list(jobs)
    if executor not in EXECUTORS:
        raise ConfigError(f"unknown executor {executor!r}; choose one of {', '.join(EXECUTORS)}")
    if isinstance(workers, bool) or not isinstance(workers, int) or workers < 1:
        raise ConfigError(f"workers must be an integer >= 1, got {workers!r}")
    names = [j.name for j in jobs]
    dup = sorted({n for n in names if names.count(n) > 1})
    if dup:
        raise ConfigError(f"two jobs are named {dup[0]!r}; job names must be unique")
    if not jobs:
        return [], []
    bars = _Progress(len(jobs), progress, stages, max_bars=min(workers, 8) if executor == "local" else 8)

    def done(job: Job, out: _Outcome) -> None:
        result, failure = _to_result(job, out)
        bars.finished(job.name, failure, out.elapsed_s, getattr(result, "timings_s", None))
        if on_done is not None:
            on_done(job, result, failure)

    try:
        if executor == "dask":
            outcomes = _run_dask(jobs, fn, workers, scheduler, bars, done)
        elif workers == 1:
            outcomes = _run_inline(jobs, fn, bars, done)
        else:
            outcomes = _run_processes(jobs, fn, workers, bars, done)
    finally:
        bars.close()
    results, failures = [], []
    for job in jobs:
        result, failure = _to_result(job, outcomes[job.name])
        if failure is None:
            results.append(result)
        else:
            failures.append(failure)
    return results, failures


def summarize_failures(failures: Iterable[GroupFailure], total: int) -> str:
    """A short summary: 'k of n flight(s) failed (the others finished): a, b' (the names; 'the others finished'
    only when some did), then one line per failure with its message."""
    failures = list(failures)
    if not failures:
        return f"all {total} flight(s) finished"
    others = " (the others finished)" if len(failures) < total else ""
    lines = [f"{len(failures)} of {total} flight(s) failed{others}: " + ", ".join(f.name for f in failures)]
    lines += [f"  {f.name} ({f.source}): {f.message}" for f in failures]
    return "\n".join(lines)


# ---- flight groups with their output folders -------------------------------------------------------------------

class _GroupTask:
    """Worker side of `run_groups`: process one group and write its folder (picklable when `process` is)."""

    def __init__(self, process, outdir: str, extra_files, figures: bool, overlay: bool = False):
        self.process, self.outdir, self.extra_files, self.figures = process, outdir, extra_files, figures
        self.overlay = overlay

    def __call__(self, payload):
        from pipeline.report.outputs import add_overlay, write_group_outputs

        name, job_payload, digest = payload
        result = self.process(job_payload)
        if getattr(result, "name", None) != name:
            raise ValueError(f"the job named {name!r} produced a group named {getattr(result, 'name', None)!r}")
        extra = dict(self.extra_files(result)) if self.extra_files is not None else {}
        if self.overlay:
            report_stage("overlay")
            extra.update(add_overlay(self.outdir, result))
        report_stage("report")
        write_group_outputs(self.outdir, result, digest, extra_files=extra or None, figures=self.figures)
        return result


def job_digest(config, files: Iterable[str | PathLike] = ()) -> str:
    """Hash of what a group's outputs depend on: its configuration (JSON-serialisable), the size and modification
    time of its input files, and the ridgeloc version. Equal digests: the finished folder can be reused."""
    from pipeline import __version__
    from pipeline.atomic import config_hash

    stats = []
    for f in files:
        try:
            st = Path(f).stat()
            stats.append([str(f), st.st_size, st.st_mtime_ns])
        except OSError:
            stats.append([str(f), None, None])
    return config_hash({"config": config, "files": stats, "ridgeloc": __version__})


def run_groups(jobs: Sequence[Job], process: Callable[[Any], Any], outdir: str | PathLike, *,
               digests: dict[str, str] | None = None, force: bool = False,
               extra_files: Callable[[Any], dict] | None = None, figures: bool = True, overlay: bool = False,
               **run_jobs_options
               ) -> tuple[list[Any], list[GroupFailure], list[str]]:
    """Process flight groups into OUTDIR/<group>/ folders, reusing finished ones.

    A job whose folder is finished for its digest (`digests[job.name]`, see `job_digest`; "" when not given) is not
    run again unless `force`: its saved GroupResult is loaded. The others run through `run_jobs` (same options:
    workers, executor, scheduler, progress, stages, on_done); each worker calls `process(job.payload)` and writes
    the group's folder atomically with `extra_files(result)` (name -> content) beside the report's files, and with
    `overlay` a video flight's overlay.mp4 (`pipeline.report.overlay`; its time is the result's "overlay" stage).
    `process` must return a GroupResult named `job.name`. Returns (results in job order, failures, names reused).
    """
    from pipeline.report.outputs import load_finished_group

    digests = digests or {}
    reused: dict[str, Any] = {}
    if not force:
        for job in jobs:
            r = load_finished_group(outdir, job.name, digests.get(job.name, ""))
            if r is not None:
                reused[job.name] = r
    todo = [Job(j.name, j.source, (j.name, j.payload, digests.get(j.name, ""))) for j in jobs
            if j.name not in reused]
    task = _GroupTask(process, str(outdir), extra_files, figures, overlay)
    stages = run_jobs_options.pop("stages", None)
    if stages is not None and "report" not in stages:
        stages = (*stages, *(("overlay",) if overlay else ()), "report")
    new, failures = run_jobs(todo, task, stages=stages, **run_jobs_options)
    by_name = {**reused, **{r.name: r for r in new}}
    results = [by_name[j.name] for j in jobs if j.name in by_name]
    return results, failures, [j.name for j in jobs if j.name in reused]
