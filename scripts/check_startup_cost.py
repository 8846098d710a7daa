"""The CPU a refused config costs: `ridgeloc check` on a flight config with an unknown key, in a fresh process,
against a bare interpreter (docs/architecture.md, "Layers": heavy modules are imported inside functions so that
the command line starts without them).

    python scripts/check_startup_cost.py [--repeat 7]

Prints the median user+system CPU seconds of each child process (resource.getrusage of the children, so the
machine's load matters less than for wall time), what `ridgeloc check` said, and where its imports go: one more
run under `python -X importtime`, its modules' own import times summed by top-level package (wall time, inflated
by the tracing; the shares are what to read). Exit status 1 if the config was not refused.
"""

from __future__ import annotations

import argparse
import collections
import resource
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
BAD_CONFIG = """name: refused
files:
  telemetry: flight.tlog
camera:
  fx_px: 1000.0
not_a_key: 1
"""


def child_cpu_s(cmd: list[str], cwd: Path) -> tuple[float, subprocess.CompletedProcess]:
    """(user + system CPU seconds of `cmd` run to completion, its result)."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    proc = subprocess.run(cmd, cwd=cwd, capture_output=True, text=True)
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime), proc


def import_shares(cmd: list[str], cwd: Path) -> tuple[float, list[tuple[str, float]]]:
    """(total self import time s, [(top-level package, share of it)] largest first) of `cmd` under -X importtime."""
    proc = subprocess.run([cmd[0], "-X", "importtime", *cmd[1:]], cwd=cwd, capture_output=True, text=True)
    by_package: collections.Counter = collections.Counter()
    for line in proc.stderr.splitlines():
        if line.startswith("import time:") and "self [us]" not in line:
            self_us, _, name = line[len("import time:"):].split("|")
            by_package[name.strip().split(".")[0]] += int(self_us)
    total = sum(by_package.values())
    return total / 1e6, [(k, v / total) for k, v in by_package.most_common()]


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=7, help="runs of each command (the median is printed)")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        config = Path(tmp) / "flight.yaml"
        config.write_text(BAD_CONFIG)
        (Path(tmp) / "flight.tlog").write_bytes(b"")
        commands = {"python (bare)": [sys.executable, "-c", "pass"],
                    "ridgeloc check (refused config)": [sys.executable, "-m", "pipeline", "check", str(config)]}
        cpu: dict[str, list[float]] = {name: [] for name in commands}
        last = None
        for _ in range(args.repeat):  # interleaved, so that a change of load touches every command alike
            for name, cmd in commands.items():
                s, proc = child_cpu_s(cmd, ROOT)
                cpu[name].append(s)
                if name.startswith("ridgeloc"):
                    last = proc
        total_s, shares = import_shares(commands["ridgeloc check (refused config)"], ROOT)
    for name, values in cpu.items():
        print(f"{name:34s} median {statistics.median(values):.2f} s CPU  (min {min(values):.2f}, max "
              f"{max(values):.2f}, {len(values)} runs)")
    said = (last.stderr.strip().splitlines() or ["(nothing)"])[-1]
    print(f"ridgeloc check exit status {last.returncode}: {said}")
    top = ", ".join(f"{k} {v:.0%}" for k, v in shares[:5])
    both = sum(v for k, v in shares if k in ("numpy", "scipy"))
    print(f"its imports under -X importtime: {total_s:.2f} s; by package: {top}; numpy + scipy {both:.0%}")
    return 0 if last.returncode != 0 else 1


if __name__ == "__main__":
    sys.exit(main())
