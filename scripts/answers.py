"""The answers of a finished run against the truth and the other methods (issue 38's figures).

    python scripts/answers.py OUT            # OUT: a `ridgeloc run -o OUT` folder of flights with a known truth

Per target: the answer's method, its 3D error, the median of the other methods' errors and the bound
2 x median + 5 m, whether the truth lies inside the answer's CE90 circle, and the category; then the share of
targets inside CE90 and whether every answer is within its bound. Reads targets.csv and estimates.csv only.
"""

from __future__ import annotations

import csv
import sys
from pathlib import Path


def main(argv: list[str]) -> int:
    if len(argv) != 1:
        print(__doc__)
        return 2
    out = Path(argv[0])
    try:
        answers = list(csv.DictReader((out / "targets.csv").open(newline="")))
        estimates = list(csv.DictReader((out / "estimates.csv").open(newline="")))
    except OSError as exc:
        print(f"answers.py: {out}: not a finished run folder ({exc.strerror}: {exc.filename})", file=sys.stderr)
        return 1
    inside, within, n = 0, 0, 0
    print(f"{'target':26s}{'method':8s}{'error m':>9s}{'others median':>15s}{'bound':>8s}{'horiz m':>9s}"
          f"{'CE90 m':>8s}  in CE90  category")
    for a in answers:
        if a["status"] != "located" or not a["error_m"]:
            print(f"{a['name']:26s}{a['status']}: {a['reason'][:80]}")
            continue
        others = sorted(float(e["error_m"]) for e in estimates if e["group"] == a["group"]
                        and e["target"] == (a["target"] or "") and e["method"] != a["method"] and e["error_m"])
        med = others[len(others) // 2] if len(others) % 2 else 0.5 * sum(others[len(others) // 2 - 1:][:2])
        bound = 2 * med + 5 if others else float("inf")
        err, horiz, ce90 = float(a["error_m"]), float(a["error_horizontal_m"]), float(a["ce90_m"])
        n += 1
        inside += horiz <= ce90
        within += err <= bound
        print(f"{a['name']:26s}{a['method']:8s}{err:9.1f}{med:15.1f}{bound:8.1f}{horiz:9.1f}{ce90:8.1f}  "
              f"{'yes' if horiz <= ce90 else 'NO':7s}  {a['tle_category']}")
    print(f"\n{n} located targets with a truth: {within} within 2 x the others' median + 5 m, "
          f"{inside} ({100 * inside / max(n, 1):.0f} %) inside their CE90 circle")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
