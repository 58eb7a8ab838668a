"""The quick loop, ``python -m pytest -m "not slow"``: it still imports every spherevm module, and
tests/slow.txt (the long tests that conftest.py marks ``slow``) names tests that exist."""
import ast
import importlib
import pathlib
import pkgutil
import re

import pytest

import spherevm
import conftest
from conftest import SLOW_LIST, slow_ids

TESTS = pathlib.Path(__file__).resolve().parent
MODULES = sorted(m.name for m in pkgutil.walk_packages(spherevm.__path__, "spherevm."))


@pytest.mark.parametrize("name", MODULES)
def test_every_module_imports(name):
    assert importlib.import_module(name).__name__ == name


def test_modules_are_found():
    """The walk sees the package's modules (a broken walk would make the test above vacuous)."""
    files = {p for p in (TESTS.parent / "spherevm").rglob("*.py")}
    assert len(MODULES) == len(files) - 1          # every file but the package's own __init__.py


def _functions(path):
    return {node.name for node in ast.walk(ast.parse(path.read_text()))
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef))}


def test_slow_list_names_existing_tests():
    ids = slow_ids()
    assert len(ids) > 50
    missing = []
    for nodeid in sorted(ids):
        path, _, test = nodeid.partition("::")
        function = re.sub(r"\[.*\]$", "", test)
        file = TESTS.parent / path
        if not file.is_file() or function not in _functions(file):
            missing.append(nodeid)
    assert not missing, f"{SLOW_LIST} names tests that do not exist (renamed or removed?): {missing}"


def test_slow_list_reads_ids_and_skips_comments(tmp_path):
    listed = tmp_path / "slow.txt"
    listed.write_text("# a comment\n\ntests/test_a.py::test_b[1-x]  # 0.7 s\ntests/test_c.py::test_d\n")
    assert slow_ids(listed) == {"tests/test_a.py::test_b[1-x]", "tests/test_c.py::test_d"}


class _Item:
    def __init__(self, nodeid):
        self.nodeid, self.keywords = nodeid, {}

    def add_marker(self, mark):
        self.keywords[mark.name] = mark


def test_listed_tests_get_the_slow_marker():
    listed, other = sorted(slow_ids())[0], "tests/test_quick_loop.py::test_modules_are_found"
    items = [_Item(listed), _Item(other)]
    conftest.pytest_collection_modifyitems(None, items)
    assert "slow" in items[0].keywords and "slow" not in items[1].keywords
