"""The sample batch on a real Dask cluster: a `dask scheduler` and two `dask worker` processes started the way a
user starts them (loopback only), `ridgeloc run --executor dask --scheduler tcp://...`; and the race such a worker
exposed in the KLV reader (issue 40)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SAMPLE_FMV = ROOT / "sample_data" / "fmv" / "flight.ts"


def test_klv_packets_decode_while_a_profiler_holds_the_readers_frames():
    """A Dask worker samples its threads' stacks every few milliseconds and holds the frame objects it saw, and
    with them their locals. The ST 0601 library's one-packet parser read a BER length through a memoryview of
    its bytearray and then shrank the bytearray: with that frame held, "BufferError: Existing exports of data:
    object cannot be re-sized" failed the fmv flight in about one run in five. Holding every frame (a profile
    hook keeping them all) makes the race certain; every packet must still decode."""
    from pipeline.ingest.klv import read_klv_table
    from pipeline.ingest.video import demux_index

    index = demux_index(SAMPLE_FMV, data_streams=True)
    held = []

    def keep(frame, event, arg):
        if event == "call":
            held.append(frame)

    sys.setprofile(keep)
    try:
        table, warnings = read_klv_table(SAMPLE_FMV, index)
    finally:
        sys.setprofile(None)
    assert table.n == len(index.data_packets) > 100 and warnings == []
    assert any(f.f_code.co_name == "decode_ber_length" for f in held)  # the hook did see the library's frames


def _start(args: list[str], log: Path) -> subprocess.Popen:
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])}
    return subprocess.Popen([sys.executable, "-m", "dask", *args], cwd=ROOT, env=env, stdout=log.open("w"),
                            stderr=subprocess.STDOUT, start_new_session=True)


@pytest.fixture
def dask_cluster(tmp_path):
    """The address of a scheduler with two worker processes (two threads each), all on 127.0.0.1."""
    pytest.importorskip("distributed")
    from distributed import Client

    sched_file = tmp_path / "scheduler.json"
    procs = [_start(["scheduler", "--host", "127.0.0.1", "--port", "0", "--no-dashboard", "--scheduler-file",
                     str(sched_file)], tmp_path / "scheduler.log")]
    try:
        deadline = time.monotonic() + 60
        while not sched_file.is_file() and time.monotonic() < deadline:
            assert procs[0].poll() is None, (tmp_path / "scheduler.log").read_text()
            time.sleep(0.2)
        address = json.loads(sched_file.read_text())["address"]
        for k in range(2):
            procs.append(_start(["worker", address, "--host", "127.0.0.1", "--nworkers", "1", "--nthreads", "2",
                                 "--no-dashboard", "--name", f"w{k}", "--local-directory", str(tmp_path / f"w{k}")],
                                tmp_path / f"worker{k}.log"))
        with Client(address, timeout="30s") as client:
            client.wait_for_workers(2, timeout=90)
        yield address
    finally:
        for p in reversed(procs):
            p.terminate()
        for p in reversed(procs):
            try:
                p.wait(timeout=20)
            except subprocess.TimeoutExpired:
                p.kill()


def test_the_sample_batch_runs_on_a_scheduler_with_two_worker_processes(tmp_path, dask_cluster, capsys):
    from pipeline.cli import main
    from pipeline.flight_config import load_run_config

    out = tmp_path / "out"
    code = main(["run", "configs/sample.yaml", "-o", str(out), "--executor", "dask", "--scheduler", dask_cluster,
                 "-q"])
    captured = capsys.readouterr()
    names = [e.config.name for e in load_run_config(str(ROOT / "configs" / "sample.yaml"))]
    assert code == 0, captured.err
    assert f"all {len(names)} flight(s) finished" in captured.out
    assert all((out / n / ".done").is_file() for n in names)
    assert "fmv" in names and (out / "fmv" / "estimates.json").is_file()
