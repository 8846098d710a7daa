"""The layer contract of `pipeline/` (docs/architecture.md): a module imports only from its own unit (a top-level
module or subpackage of `pipeline`) or from a unit in a lower layer, never from a sibling in its own layer nor
from above, and no chain of imports between modules closes on itself. Every `import` counts, the ones inside
functions too (an import deferred into a function still couples the two modules and hides a cycle). Read with
`ast` from the source, so nothing is imported to check it."""

from __future__ import annotations

import ast
import itertools
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

# Lowest first. Units in one layer are independent of each other.
LAYERS: list[tuple[str, tuple[str, ...]]] = [
    ("base", ("pipeline", "errors", "atomic", "progress")),
    ("TAK: CoT events, data packages, sending", ("tak",)),
    ("config schema and simple files", ("config_schema", "frames_csv")),
    ("solve options", ("solve_options",)),
    ("targets", ("targets",)),
    ("config", ("flight_config",)),
    ("geometry", ("geometry",)),
    ("readers and pure stages", ("ingest", "track", "solve")),
    ("observation file", ("observation_file",)),
    ("the answer rule", ("answer",)),
    ("synchronisation and results", ("intrinsics", "sync", "results", "simulate", "synth", "terrain")),
    ("flight", ("flight",)),
    ("clock estimate", ("clock_estimate",)),
    ("check", ("check",)),
    ("flight config from files", ("autoconfig",)),
    ("per-target stages", ("target_stage",)),
    ("report", ("report",)),
    ("photo error model", ("photo_errors",)),
    ("photo flights", ("locate",)),
    ("run", ("run",)),
    ("batch", ("batch",)),
    ("commands", ("commands",)),
    ("cli", ("cli",)),
    ("entry point", ("__main__",)),
]

# Known upward imports, each with its reason; an entry that no longer occurs fails the test (delete it then).
EXCEPTIONS: dict[tuple[str, str], str] = {
}


def module_name(path: Path, package_root: Path) -> str:
    parts = list(path.relative_to(package_root.parent).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts = parts[:-1]
    return ".".join(parts)


def import_graph(package_root: Path) -> dict[str, set[str]]:
    """{module: modules of the package it imports, anywhere in its body}. `from a import b` counts as an import of
    `a.b` when that is a module, else of `a`."""
    top = package_root.name
    modules = {module_name(p, package_root): p for p in package_root.rglob("*.py")}
    graph: dict[str, set[str]] = {}
    for name, path in modules.items():
        package = name if path.name == "__init__.py" else name.rpartition(".")[0]
        found = set()
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if isinstance(node, ast.Import):
                found.update(a.name for a in node.names)
            elif isinstance(node, ast.ImportFrom):
                if node.level:
                    base = package.split(".")[: len(package.split(".")) - node.level + 1]
                    target = ".".join(base + ([node.module] if node.module else []))
                else:
                    target = node.module or ""
                for a in node.names:
                    found.add(f"{target}.{a.name}" if f"{target}.{a.name}" in modules else target)
        graph[name] = {m for m in found if m == top or m.startswith(top + ".")}
    return graph


def unit(module: str) -> str:
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else parts[0]


def layer_violations(graph: dict[str, set[str]], layers) -> list[tuple[str, str, str]]:
    """(importer, imported, why) for every import of a sibling unit in the same layer or of a higher layer."""
    rank = {u: i for i, (_, units) in enumerate(layers) for u in units}
    out = []
    for a, targets in sorted(graph.items()):
        for b in sorted(targets):
            ua, ub = unit(a), unit(b)
            if ua == ub:
                continue
            if ua not in rank or ub not in rank:
                out.append((a, b, f"unit {(ua if ua not in rank else ub)!r} has no layer"))
            elif rank[ub] > rank[ua]:
                out.append((a, b, f"upward: {layers[rank[ua]][0]} -> {layers[rank[ub]][0]}"))
            elif rank[ub] == rank[ua]:
                out.append((a, b, f"sibling in layer {layers[rank[ua]][0]}"))
    return out


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan), each sorted."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    counter = itertools.count()
    found = []

    def visit(v: str) -> None:
        index[v] = low[v] = next(counter)
        stack.append(v)
        on_stack.add(v)
        for w in graph.get(v, ()):
            if w not in graph:
                continue
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                found.append(sorted(comp))

    limit = sys.getrecursionlimit()
    sys.setrecursionlimit(max(limit, 10 * len(graph) + 100))
    try:
        for v in sorted(graph):
            if v not in index:
                visit(v)
    finally:
        sys.setrecursionlimit(limit)
    return found


@pytest.fixture(scope="module")
def graph():
    return import_graph(ROOT / "pipeline")


def test_every_unit_has_a_layer(graph):
    named = {u for _, units in LAYERS for u in units}
    assert sorted({unit(m) for m in graph} - named) == []
    assert sorted(named - {unit(m) for m in graph}) == []


def test_no_import_goes_up_or_sideways(graph):
    found = layer_violations(graph, LAYERS)
    unexpected = [f"{a} imports {b} ({why})" for a, b, why in found if (a, b) not in EXCEPTIONS]
    assert unexpected == []
    stale = sorted(set(EXCEPTIONS) - {(a, b) for a, b, _ in found})
    assert stale == [], "these exceptions no longer occur: delete them from EXCEPTIONS"


def test_no_import_cycle(graph):
    assert cycles(graph) == []


def test_the_contract_catches_an_upward_import_in_a_function_and_a_cycle(tmp_path):
    pkg = tmp_path / "pkg"
    (pkg / "low").mkdir(parents=True)
    (pkg / "__init__.py").write_text("")
    (pkg / "low" / "__init__.py").write_text("")
    (pkg / "low" / "a.py").write_text("def f():\n    from pkg.high import g\n    return g\n")
    (pkg / "low" / "b.py").write_text("from . import a\n")
    (pkg / "high.py").write_text("from pkg.low import b\n\ndef g():\n    return b\n")
    g = import_graph(pkg)
    assert g["pkg.low.a"] == {"pkg.high"} and g["pkg.low.b"] == {"pkg.low.a"}
    layers = [("base", ("pkg",)), ("low", ("low",)), ("high", ("high",))]
    assert layer_violations(g, layers) == [("pkg.low.a", "pkg.high", "upward: low -> high")]
    assert cycles(g) == [["pkg.high", "pkg.low.a", "pkg.low.b"]]
    assert layer_violations(g, [("base", ("pkg",)), ("both", ("low", "high"))])[0][2] == "sibling in layer both"
