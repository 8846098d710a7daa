"""scripts/README.md lists every script once, and every document it says cites a script does cite it."""

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _rows() -> dict[str, list[str]]:
    rows = {}
    for line in (ROOT / "scripts" / "README.md").read_text().splitlines():
        m = re.match(r"\| `([a-z_0-9]+\.py)` \|.*\| ([^|]+) \|$", line)
        if m:
            assert m.group(1) not in rows, f"{m.group(1)} listed twice"
            rows[m.group(1)] = [d.strip() for d in m.group(2).split(",")]
    return rows


def test_every_script_has_one_row():
    listed = set(_rows())
    present = {p.name for p in (ROOT / "scripts").glob("*.py")}
    assert listed == present, (sorted(present - listed), sorted(listed - present))


def test_the_documents_named_cite_the_script():
    for script, docs in _rows().items():
        for doc in docs:
            text = (ROOT / doc).read_text()
            assert f"scripts/{script}" in text or re.search(rf"\b{re.escape(script)}\b", text), (script, doc)
