"""Write a demo run output folder: six synthetic groups shaped like the paper's Table 3, solved by every
estimator (the generator is test support: tests/support/synthetic.py).

    python scripts/demo_run.py [OUTDIR]     # default out/demo
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT), str(ROOT / "tests")]  # this checkout's pipeline; test support (support.synthetic)

from support.synthetic import demo_run  # noqa: E402

if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("outdir", nargs="?", default="out/demo", help="the run folder to write (default out/demo)")
    demo_run(ap.parse_args().outdir)
