"""Batch runs: one bad flight is reported and skipped, executors agree, Ctrl-C stops everything."""

from __future__ import annotations

import csv
import io
import json
import multiprocessing
import os
import time
from pathlib import Path

import numpy as np
import pytest

from pipeline import observation_file
from pipeline.batch import Job, discover_flights, report_stage, run_jobs, summarize_failures
from pipeline.errors import ConfigError, InputError
from pipeline.geometry.rays import intersection_angle_deg
from pipeline.report import write_run_outputs
from pipeline.results import GroupResult
from support.synthetic import (
    DEFAULT_ORIGIN_LLA,
    solve_all,
    synthetic_observations,
)

STAGES = ("load", "solve")


def solve_flight(path: str) -> GroupResult:
    """A job: load one flight's observations file and run every estimator on it."""
    report_stage("load")
    obs = observation_file.load(path)
    report_stage("solve")
    estimates, t_solve = solve_all(obs)
    return GroupResult(name=Path(path).stem, origin_lla=DEFAULT_ORIGIN_LLA, observations=obs, estimates=estimates,
                       truth_m=obs.truth_m, intersection_angle_deg=intersection_angle_deg(obs.platform_m, obs.truth_m),
                       timings_s={"solve": t_solve})


def make_flights(folder: Path, n: int, broken=(4, 13)) -> list[Job]:
    """n generated flights as observation files; the `broken` ones are damaged in two different ways."""
    jobs = []
    for i in range(n):
        name = f"flight{i:02d}"
        path = folder / name / f"{name}.json"
        path.parent.mkdir(parents=True)
        obs, _ = synthetic_observations(seed=100 + i, intersection_angle_deg=20 + 3 * i, n_frames=8 + i % 5)
        text = json.dumps(observation_file.to_dict(obs))
        if i == broken[0]:
            text = text[: len(text) // 2]  # truncated mid-write
        elif i == broken[1]:
            doc = observation_file.to_dict(obs)
            doc["observations"][3]["platform_m"] = [1.0, 2.0]  # a corrupt row
            text = json.dumps(doc)
        path.write_text(text)
        jobs.append(Job(name, str(path), str(path)))
    return jobs


def test_twenty_flights_two_broken(tmp_path):
    jobs = make_flights(tmp_path / "flights", 20)
    seen = []
    results, failures = run_jobs(jobs, solve_flight, workers=2, progress=False, stages=STAGES,
                                 on_done=lambda job, r, f: seen.append((job.name, r is None, f is None)))
    assert len(results) == 18 and len(failures) == 2
    assert [r.name for r in results] == [j.name for j in jobs if j.name not in ("flight04", "flight13")]
    assert sorted(seen) == sorted((j.name, j.name in ("flight04", "flight13"), j.name not in ("flight04", "flight13"))
                                  for j in jobs)
    f4, f13 = failures
    assert (f4.name, f13.name) == ("flight04", "flight13")
    assert f4.source.endswith("flight04.json") and "not valid JSON" in f4.message and "flight04.json" in f4.message
    assert "observations[3].platform_m must be [x, y, z]" in f13.message
    assert all("\n" not in f.message for f in failures)
    assert f4.detail == "" and f13.detail == ""  # input errors, not bugs: no traceback
    summary = summarize_failures(failures, len(jobs))
    assert summary.splitlines()[0] == "2 of 20 flight(s) failed (the others finished): flight04, flight13"
    assert summary.splitlines()[1].startswith("  flight04 (") and "not valid JSON" in summary.splitlines()[1]
    assert summarize_failures(failures, 2).splitlines()[0] == "2 of 2 flight(s) failed: flight04, flight13"

    out = tmp_path / "out"
    write_run_outputs(out, results, failures, {"workers": 2}, figures=False)
    assert sorted(p.name for p in out.iterdir() if p.is_dir() and p.name != "cot") == [r.name for r in results]
    assert all((out / r.name / ".done").is_file() for r in results)
    answers = list(csv.DictReader(io.StringIO((out / "targets.csv").read_text())))
    assert [a["name"] for a in answers] == [*(r.name for r in results), "flight04", "flight13"]  # one per flight
    assert [a["status"] for a in answers[-2:]] == ["not_located"] * 2 and "not valid JSON" in answers[-2]["reason"]
    csv_rows = (out / "estimates.csv").read_text().strip().splitlines()
    assert len(csv_rows) == 1 + sum(len(r.estimates) for r in results)
    html = (out / "report.html").read_text()
    assert "Failed groups (2)" in html and "not valid JSON" in html


@pytest.fixture(scope="module")
def dask_client():
    distributed = pytest.importorskip("distributed")
    cluster = distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=False, dashboard_address=None)
    client = distributed.Client(cluster)
    yield client
    client.close()
    cluster.close()


def test_dask_gives_the_same_results_as_local(tmp_path, dask_client):
    jobs = make_flights(tmp_path, 6, broken=(2, 99))
    local = run_jobs(jobs, solve_flight, workers=1, progress=False)
    remote = run_jobs(jobs, solve_flight, executor="dask", scheduler=dask_client, progress=False, stages=STAGES)
    by_address = run_jobs(jobs[:2], solve_flight, executor="dask", scheduler=dask_client.scheduler.address,
                          progress=False)
    for (res_a, fail_a), (res_b, fail_b) in ((local, remote), ((local[0][:2], []), by_address)):
        assert [r.name for r in res_a] == [r.name for r in res_b]
        assert [(f.name, f.message) for f in fail_a] == [(f.name, f.message) for f in fail_b]
        for a, b in zip(res_a, res_b, strict=True):
            assert a.estimates.keys() == b.estimates.keys()
            for m in a.estimates:
                np.testing.assert_array_equal(a.estimates[m].position_m, b.estimates[m].position_m)
    assert len(local[0]) == 5 and local[1][0].name == "flight02"


def _sleepy(x):
    report_stage("sleeping")
    time.sleep(x)
    return x


def _interrupt(job, result, failure):
    raise KeyboardInterrupt


def test_ctrl_c_stops_the_workers():
    # Slow jobs sleep 300 s and the bound is 120 s: a wide margin so that a loaded machine (slow process start-up)
    # cannot fail this, while waiting for even one slow job would.
    jobs = [Job("fast", "-", 0.05)] + [Job(f"slow{i}", "-", 300.0) for i in range(6)]
    t0 = time.perf_counter()
    with pytest.raises(KeyboardInterrupt):
        run_jobs(jobs, _sleepy, workers=2, progress=False, on_done=_interrupt)
    assert time.perf_counter() - t0 < 120.0  # did not wait for the slow jobs
    deadline = time.time() + 60
    while multiprocessing.active_children() and time.time() < deadline:
        time.sleep(0.05)
    assert multiprocessing.active_children() == []


def _buggy(x):
    return {}["missing key"]


def test_a_bug_in_one_job_keeps_its_traceback():
    results, failures = run_jobs([Job("ok", "-", 0.0), Job("bug", "bug.yaml", "x")],
                                 lambda p: _sleepy(p) if p == 0.0 else _buggy(p), progress=False)
    assert results == [0.0] and len(failures) == 1
    f = failures[0]
    assert f.message == "internal error (KeyError): 'missing key'"
    assert "Traceback" in f.detail and "_buggy" in f.detail


def test_bad_arguments_are_clear():
    with pytest.raises(ConfigError, match="unknown executor 'spark'"):
        run_jobs([Job("a", "-", 1)], _sleepy, executor="spark")
    with pytest.raises(ConfigError, match="workers must be an integer >= 1"):
        run_jobs([Job("a", "-", 1)], _sleepy, workers=0)
    with pytest.raises(ConfigError, match="two jobs are named 'a'"):
        run_jobs([Job("a", "-", 1), Job("a", "-", 2)], _sleepy)
    assert run_jobs([], _sleepy) == ([], [])


def test_discover_flights(tmp_path):
    for name in ("b", "a", "nested/c", ".tmp-x"):
        (tmp_path / "flights" / name).mkdir(parents=True)
        (tmp_path / "flights" / name / "flight.yaml").write_text("name: x\n")
    (tmp_path / "flights" / "a" / "notes.yaml").write_text("x: 1\n")
    found = discover_flights(tmp_path / "flights")
    assert [p.relative_to(tmp_path / "flights").as_posix() for p in found] == [
        "a/flight.yaml", "b/flight.yaml", "nested/c/flight.yaml"]
    manifest = tmp_path / "flights" / "manifest.yaml"
    manifest.write_text("- b/flight.yaml\n- nested/c/flight.yaml\n- missing/flight.yaml\n")
    assert [p.name for p in discover_flights(manifest)] == ["flight.yaml"] * 3
    assert discover_flights(manifest)[2] == (tmp_path / "flights" / "missing" / "flight.yaml").resolve()
    run_config = tmp_path / "flights" / "run.yaml"
    run_config.write_text("groups: [a/flight.yaml]\n")
    assert discover_flights(run_config) == [(tmp_path / "flights" / "a" / "flight.yaml").resolve()]
    single = tmp_path / "flights" / "a" / "flight.yaml"
    assert discover_flights(single) == [single.resolve()]
    with pytest.raises(InputError, match=r"no flight configs named none\.yaml"):
        discover_flights(tmp_path / "flights", config_name="none.yaml")
    with pytest.raises(InputError, match="no such file or folder"):
        discover_flights(tmp_path / "nowhere")
    bad = tmp_path / "bad.yaml"
    bad.write_text("groups: []\n")
    with pytest.raises(ConfigError, match=r"groups: must have at least 1 element"):
        discover_flights(bad)


CALLS: list[str] = []


def counted_solve_flight(path: str) -> GroupResult:
    CALLS.append(Path(path).stem)
    return solve_flight(path)


def test_run_groups_reuses_finished_folders(tmp_path):
    from pipeline.batch import job_digest, run_groups

    jobs = make_flights(tmp_path / "flights", 4, broken=(1, 99))
    out = tmp_path / "out"
    digests = {j.name: job_digest({"name": j.name}, [j.source]) for j in jobs}

    def go(**kw):
        CALLS.clear()
        return run_groups(jobs, counted_solve_flight, out, digests=digests, figures=False, progress=False,
                          extra_files=lambda r: {"note.txt": f"{r.name}\n"}, **kw)

    results, failures, reused = go()
    assert [r.name for r in results] == ["flight00", "flight02", "flight03"] and reused == []
    assert [f.name for f in failures] == ["flight01"]
    assert (out / "flight02" / "note.txt").read_text() == "flight02\n" and not (out / "flight01").exists()
    first = {r.name: r.estimates["mle"].position_m for r in results}

    results, failures, reused = go()  # a re-run: only the failed flight runs again
    assert CALLS == ["flight01"] and reused == ["flight00", "flight02", "flight03"]
    assert [r.name for r in results] == ["flight00", "flight02", "flight03"] and len(failures) == 1
    for r in results:
        np.testing.assert_array_equal(r.estimates["mle"].position_m, first[r.name])

    st = Path(jobs[3].source).stat()  # an input changed: its digest changes, the flight runs again
    os.utime(jobs[3].source, ns=(st.st_atime_ns, st.st_mtime_ns + 10**9))
    digests[jobs[3].name] = job_digest({"name": jobs[3].name}, [jobs[3].source])
    go()
    assert CALLS == ["flight01", "flight03"]
    go(force=True)
    assert CALLS == ["flight00", "flight01", "flight02", "flight03"]
