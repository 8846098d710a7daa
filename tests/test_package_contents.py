"""The installed package needs nothing from the checkout: no module under pipeline/ builds a path that leaves
the package from its own file (the repository root, configs/, sample_data/, tests/) or names ../shared, and the
test support (fuzz targets, test-only writers, the noisy-scene generators of tests and benchmarks) lives in
tests/support/. scripts/check_installed.py proves it on a real wheel (a fresh venv outside the checkout,
`ridgeloc run` on a copied sample flight)."""

from __future__ import annotations

import ast
import re
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "pipeline"
MODULES = sorted(PACKAGE.rglob("*.py"))


def _leaves_package(node: ast.AST, depth: int) -> bool:
    """`Path(__file__)...parents[n]` or `.parent` chains that climb `depth` or more folders above the module's."""
    text = ast.unparse(node)
    if "__file__" not in text:
        return False
    m = re.search(r"\.parents\[(\d+)\]", text)
    up = int(m.group(1)) + 1 if m else text.count(".parent")
    return up > depth


@pytest.mark.parametrize("path", MODULES, ids=lambda p: p.relative_to(PACKAGE).as_posix())
def test_no_module_reaches_out_of_the_package(path):
    depth = len(path.relative_to(PACKAGE).parts)  # pipeline/a.py: 1 (its folder is the package), a/b.py: 2
    tree = ast.parse(path.read_text())
    for node in ast.walk(tree):
        if isinstance(node, (ast.Attribute, ast.Subscript)) and _leaves_package(node, depth):
            pytest.fail(f"{path.name}:{node.lineno}: {ast.unparse(node)} leaves the installed package")
        if isinstance(node, ast.Constant) and isinstance(node.value, str) and re.search(r"\.\./shared|^shared/",
                                                                                         node.value):
            pytest.fail(f"{path.name}:{node.lineno}: names the checkout's shared folder: {node.value[:60]!r}")


def test_the_checker_sees_a_path_out_of_the_package():
    assert _leaves_package(ast.parse('Path(__file__).resolve().parents[2] / "configs"').body[0].value, 2)
    assert not _leaves_package(ast.parse('Path(__file__).resolve().parents[1]').body[0].value, 2)
    assert _leaves_package(ast.parse('Path(__file__).parent.parent / "x"').body[0].value, 1)
    assert not _leaves_package(ast.parse('Path(__file__).resolve().parent / "assets"').body[0].value, 1)


def test_test_support_is_not_in_the_package():
    assert not (PACKAGE / "fuzz_targets.py").exists() and not (PACKAGE / "ingest" / "writers.py").exists()
    assert (PACKAGE.parent / "tests" / "support" / "fuzz_targets.py").is_file()
    assert not (PACKAGE / "solve" / "scenes.py").exists() and not (PACKAGE / "report" / "synthetic.py").exists()
    assert (PACKAGE.parent / "tests" / "support" / "scenes.py").is_file()
    assert (PACKAGE.parent / "tests" / "support" / "synthetic.py").is_file()
