"""Prove the installed package needs nothing from the checkout: install ridgeloc (not editable) from the committed
sources into a fresh venv outside the checkout, copy one sample flight to another folder and `ridgeloc run` it
there. Prints the wheel's size, what it would have carried from test support, and the flight's table row.

    python scripts/check_installed.py [--venv /tmp/ridgeloc_venv] [--group group1] [--reuse]

--reuse: the venv exists with ridgeloc's dependencies; only ridgeloc itself is reinstalled (--no-deps).
Exit status 0 when the run succeeds from the installed package and the wheel holds no test support.
"""

from __future__ import annotations

import argparse
import csv
import io
import shutil
import subprocess
import sys
import tarfile
import tempfile
from pathlib import Path

import yaml

ROOT = Path(__file__).resolve().parents[1]


def _run(cmd, **kw) -> subprocess.CompletedProcess:
    print("+", " ".join(map(str, cmd)), flush=True)
    return subprocess.run(cmd, check=True, text=True, capture_output=True, **kw)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--venv", type=Path, default=Path(tempfile.gettempdir()) / "ridgeloc_check_venv")
    ap.add_argument("--group", default="group1")
    ap.add_argument("--reuse", action="store_true")
    args = ap.parse_args()
    work = Path(tempfile.mkdtemp(prefix="ridgeloc_check_"))
    # the committed sources only, outside the checkout (a build writes build/ and *.egg-info beside them)
    src = work / "src"
    archive = subprocess.run(["git", "-C", str(ROOT), "archive", "HEAD"], check=True, capture_output=True).stdout
    tarfile.open(fileobj=io.BytesIO(archive)).extractall(src, filter="data")
    python = args.venv / "bin" / "python"
    fresh = not args.reuse or not python.exists()
    if fresh:
        _run([sys.executable, "-m", "venv", "--clear", args.venv])
    wheels = work / "wheels"
    _run([python, "-m", "pip", "wheel", "-q", "--no-deps", "-w", wheels, src])
    wheel = next(wheels.glob("ridgeloc-*.whl"))
    import zipfile

    names = zipfile.ZipFile(wheel).namelist()
    support = [n for n in names if n.endswith(("fuzz_targets.py", "ingest/writers.py")) or n.startswith("tests/")]
    print(f"wheel {wheel.name}: {wheel.stat().st_size / 1e6:.1f} MB, {len(names)} files, test support: {support}")
    if fresh:
        _run([python, "-m", "pip", "install", "-q", wheel])
    else:
        _run([python, "-m", "pip", "install", "-q", "--no-deps", "--force-reinstall", wheel])
    # one sample flight and its config, paths made relative to the copy
    flight = work / "elsewhere" / args.group
    shutil.copytree(ROOT / "sample_data" / args.group, flight / "data")
    doc = yaml.safe_load((ROOT / "configs" / "flights" / f"{args.group}.yaml").read_text())
    doc["files"] = {k: ([f"data/{Path(p).name}" for p in v] if isinstance(v, list) else f"data/{Path(v).name}")
                    for k, v in doc["files"].items()}
    doc["truth_file"] = f"data/{Path(doc['truth_file']).name}"
    (flight / "flight.yaml").write_text(yaml.safe_dump(doc, sort_keys=False))
    where = _run([python, "-c", "import pipeline; print(pipeline.__file__)"], cwd=flight).stdout.strip()
    print(f"pipeline imported from {where}")
    ridgeloc = args.venv / "bin" / "ridgeloc"
    proc = subprocess.run([ridgeloc, "run", "flight.yaml", "-q", "-o", "out", "--no-figures"], cwd=flight,
                          text=True, capture_output=True)
    print(proc.stdout + proc.stderr)
    rows = list(csv.reader((flight / "out" / "table4.csv").open())) if proc.returncode == 0 else []
    for row in rows:
        print(",".join(row))
    ok = proc.returncode == 0 and not support and not where.startswith(str(ROOT)) and where.startswith(
        str(args.venv))
    print("OK: the installed package ran a copied flight outside the checkout" if ok else "FAILED")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
