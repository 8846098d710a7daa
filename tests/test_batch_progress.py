"""Progress output of a batch when stdout is not a terminal (CI logs, `| tee`): lines, streamed, itemised."""

from __future__ import annotations

import io
import time

from pipeline.batch import Job, _Progress, itemised_timings, report_stage, run_jobs
from pipeline.results import GroupFailure


class _Flight:
    def __init__(self, name):
        self.name = name
        self.timings_s = {}


def _staged(name):
    for stage, seconds in (("ingest", 0.02), ("track", 0.03), ("solve", 0.01)):
        report_stage(stage)
        time.sleep(seconds)
    if name == "bad":
        raise ValueError("broken on purpose")
    f = _Flight(name)
    f.timings_s = {"ingest": 0.02, "track": 0.03, "solve": 0.01}
    return f


class _Recorder(io.StringIO):
    """A non-terminal stream that records what had been written when each write happened."""

    def __init__(self):
        super().__init__()
        self.flushes = 0

    def flush(self):
        self.flushes += 1
        super().flush()


def test_piped_output_has_a_line_per_finished_stage_and_an_itemised_line_per_flight(capsys):
    results, failures = run_jobs([Job("a", "a.yaml", "a"), Job("bad", "bad.yaml", "bad")], _staged,
                                 progress=True, stages=("ingest", "track", "solve"))
    out = capsys.readouterr().out.splitlines()
    assert [r.name for r in results] == ["a"] and [f.name for f in failures] == ["bad"]
    a = [ln for ln in out if ln.startswith("a: ")]
    assert [ln.split(" finished")[0] for ln in a[:3]] == ["a: ingest", "a: track", "a: solve"]
    assert a[3].startswith("a: done in ") and "(ingest 0.02, track 0.03, solve 0.01" in a[3]
    bad = [ln for ln in out if ln.startswith("bad: ")]
    assert bad[-1] == "bad: FAILED: internal error (ValueError): broken on purpose" and len(bad) == 4
    # stage lines come in the order they happened: a's all before bad's
    assert out.index(a[-1]) < out.index(bad[0])


def test_lines_are_flushed_as_they_happen_and_bars_stay_off_a_pipe():
    out = _Recorder()
    p = _Progress(2, enabled=True, stages=("ingest", "solve"), max_bars=1, out=out)
    assert p.bar.disable  # stderr under pytest is not a terminal: no bar
    p.stage("g", "ingest")
    assert out.getvalue() == ""  # nothing finished yet
    p.stage("g", "solve")
    assert out.getvalue().startswith("g: ingest finished (") and out.flushes >= 1
    p.finished("g", None, 1.0, {"ingest": 0.25, "solve": 0.5})
    assert out.getvalue().splitlines()[-2].startswith("g: solve finished (")
    assert out.getvalue().splitlines()[-1] == "g: done in 1.00 s (ingest 0.25, solve 0.50, other 0.25 s)"
    p.stage("k", "track")
    p.stage("k", "track")  # entered again at once (the mark's acquisition, then the track): one stage, one line
    p.stage("k", "sync")
    k_lines = [ln for ln in out.getvalue().splitlines() if ln.startswith("k: ")]
    assert len(k_lines) == 1 and k_lines[0].startswith("k: track finished (")
    p.finished("h", GroupFailure("h", "h.yaml", "no video"), 0.1, None)
    assert out.getvalue().splitlines()[-1] == "h: FAILED: no video"
    p.close()
    quiet = _Recorder()
    q = _Progress(1, enabled=False, stages=None, max_bars=1, out=quiet)
    q.stage("g", "ingest")
    q.finished("g", None, 1.0, {"ingest": 1.0})
    assert quiet.getvalue() == ""


def test_itemised_timings():
    assert itemised_timings({"ingest": 1.0, "report": 0.5}, 2.0) == " (ingest 1.00, report 0.50, other 0.50 s)"
    assert itemised_timings({"ingest": 1.0}, 1.0) == " (ingest 1.00 s)"
    assert itemised_timings({}, 1.0) == "" and itemised_timings(None) == ""
