"""Every reader survives hostile bytes: a mutated input reads (warnings allowed) or is refused with one line that
names the file, never a traceback (docs/damaged_input.md).

The readers, their seeds and the mutations live in tests/support/fuzz_targets.py, one `Target(...)` line per reader.
To cover a new reader, add a `_seed_<name>(folder) -> path` building a small valid input and one line in
`TARGETS` there: this file and scripts/fuzz.py (long runs, inputs tried and failures per reader) pick it up.

In CI each reader gets a fixed, derandomized set of examples (a few seconds per reader); run
`nice -n 10 python scripts/fuzz.py --minutes N` for a long search.
"""

import os
import random
import subprocess
import sys
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from support.fuzz_targets import TARGETS, check, mutate, mutate_bytes

ROOT = Path(__file__).resolve().parents[1]
SLOW = {"ros1-bag", "ros2-sqlite3", "ros2-mcap", "ros2-metadata"}  # ~0.2-0.5 s per input (rosbags' type compiler)


@pytest.fixture(scope="module")
def seeds(tmp_path_factory):
    """name -> (path to mutate, its original bytes), built once."""
    out = {}
    for t in TARGETS:
        folder = tmp_path_factory.mktemp(t.name)
        path = t.make_seed(folder)
        out[t.name] = (path, path.read_bytes())
    return out


@pytest.mark.parametrize("target", TARGETS, ids=lambda t: t.name)
def test_seed_reads(target, seeds):
    path, data = seeds[target.name]
    path.write_bytes(data)
    target.read(path)  # the seed itself must read without any error, or the fuzzing tests nothing


@pytest.mark.parametrize("target", TARGETS, ids=lambda t: t.name)
def test_mutated_inputs_read_or_fail_in_one_line(target, seeds):
    path, data = seeds[target.name]

    @settings(max_examples=8 if target.name in SLOW else 30, deadline=None, derandomize=True, database=None,
              suppress_health_check=list(HealthCheck))
    @given(rng=st.randoms(use_true_random=False))
    def run(rng):
        damaged, ops = mutate(target, data, rng)
        path.write_bytes(damaged)
        try:
            assert check(target, path) is None, ops
        finally:
            path.write_bytes(data)

    run()


@pytest.mark.parametrize("target", TARGETS, ids=lambda t: t.name)
def test_every_truncation_class_and_header_only(target, seeds):
    """Empty, 1 byte, the magic, a header, half, all but the last byte."""
    path, data = seeds[target.name]
    try:
        for n in sorted({0, 1, 4, 8, 16, 64, 256, len(data) // 2, len(data) - 1}):
            path.write_bytes(data[: max(0, min(n, len(data)))])
            assert check(target, path) is None, f"truncated to {n} bytes"
    finally:
        path.write_bytes(data)


@pytest.mark.parametrize("target", TARGETS, ids=lambda t: t.name)
def test_random_bytes_after_the_magic_and_huge_lengths(target, seeds):
    path, data = seeds[target.name]
    rng = random.Random(1)
    try:
        for keep in (4, 8, 16):
            path.write_bytes(data[:keep] + rng.randbytes(2048))
            assert check(target, path) is None, f"magic {keep} + random"
        for at in range(8, min(len(data), 400), 150 if target.name in SLOW else 37):
            for v in (b"\xff\xff\xff\xff", b"\xff\xff\xff\x7f\xff\xff\xff\xff"):
                path.write_bytes(data[:at] + v + data[at + len(v):])
                assert check(target, path) is None, f"{v.hex()} at {at}"
    finally:
        path.write_bytes(data)


@pytest.mark.parametrize("target", TARGETS, ids=lambda t: t.name)
def test_directory_where_a_file_is_expected(target, seeds, tmp_path):
    path, _ = seeds[target.name]
    fake = tmp_path / "sub" / path.name
    fake.mkdir(parents=True)
    assert check(target, fake) is None


@pytest.mark.skipif(not hasattr(os, "geteuid"), reason="POSIX permissions")
@pytest.mark.parametrize("target", TARGETS, ids=lambda t: t.name)
def test_unreadable_file(target, seeds, tmp_path):
    """chmod 000: as root (which ignores it) the read runs as user 'nobody' in a subprocess."""
    path, _ = seeds[target.name]
    os.chmod(path, 0)
    try:
        code = ("import sys; from pathlib import Path; from support.fuzz_targets import BY_NAME, check; "
                f"print(check(BY_NAME[{target.name!r}], Path({str(path)!r})))")
        if os.geteuid() != 0:
            result = check(target, path)
            assert result is None, result
            return
        try:
            proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, user=65534,
                                  cwd=tmp_path, timeout=120,
                                  env={**os.environ, "PYTHONPATH": f"{ROOT}{os.pathsep}{ROOT / 'tests'}"})
        except PermissionError:
            pytest.skip("cannot switch to user nobody")
        if "Permission denied" in proc.stderr and "pipeline" not in proc.stderr:
            pytest.skip("user nobody cannot reach the interpreter or the repository")
        assert proc.returncode == 0 and proc.stdout.strip().splitlines()[-1] == "None", proc.stdout + proc.stderr
    finally:
        os.chmod(path, 0o644)


def test_mutations_are_varied_and_reproducible():
    data = bytes(range(256)) * 8
    a = [mutate_bytes(data, random.Random(s)) for s in range(200)]
    b = [mutate_bytes(data, random.Random(s)) for s in range(200)]
    assert a == b
    kinds = {op.split()[0] for _, ops in a for op in ops}
    assert {"truncate", "bitflip", "overwrite", "huge", "insert", "delete", "duplicate", "magic"} <= kinds
    assert sum(d != data for d, _ in a) > 190
