"""The HTML docs build with warnings as errors, and the API reference's objects document their
parameters and what they return.

``sphinx-build -W`` reads every page of docs/ (Markdown through myst-parser) and the API reference
(docs/api.md: autodoc, NumPy-style docstrings through napoleon), so a docstring that docutils cannot
read, or a page that links nowhere, fails here. Every class and function that docs/api.md names,
and every method it lists under ``:members:``, has a ``Parameters`` section when it takes
arguments (a class: when its own constructor does), and a ``Returns`` (or ``Yields``) section when
it returns a value.
"""
import ast
import importlib
import inspect
import pathlib
import re
import subprocess
import sys
import textwrap

import pytest

ROOT = pathlib.Path(__file__).resolve().parent.parent
API = ROOT / "docs" / "api.md"


def test_docs_build_without_warnings(tmp_path):
    pytest.importorskip("sphinx", reason="needs sphinx (pip install -e '.[docs]')")
    pytest.importorskip("myst_parser", reason="needs myst-parser (pip install -e '.[docs]')")
    done = subprocess.run([sys.executable, "-m", "sphinx", "-W", "--keep-going", "-q", "-b", "html",
                           "-d", str(tmp_path / "doctrees"), str(ROOT / "docs"), str(tmp_path / "html")],
                          capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-5000:]
    api = (tmp_path / "html" / "api.html").read_text()
    assert 'id="spherevm.Simulation.minimize"' in api          # autodoc ran, not just the Markdown
    assert (tmp_path / "html" / "performance.html").exists()


def _resolve(dotted):
    parts = dotted.split(".")
    for k in range(len(parts), 0, -1):
        try:
            obj = importlib.import_module(".".join(parts[:k]))
        except ImportError:
            continue
        for attr in parts[k:]:
            obj = getattr(obj, attr)
        return obj
    raise ImportError(dotted)


def documented():
    """(name, object) of every class, function and listed method of docs/api.md."""
    text = API.read_text()
    out = []
    for m in re.finditer(r"\.\. auto(class|function):: (\S+)((?:\n   :[^\n]*(?:\n {13}[^\n]*)*)*)", text):
        name = m.group(2)
        obj = _resolve(name)
        out.append((name, obj))
        members = re.search(r":members:([^:]*)", m.group(3))
        if members and members.group(1).strip():
            for member in re.split(r"[,\s]+", members.group(1).strip()):
                attr = inspect.getattr_static(obj, member)
                if not isinstance(attr, property):
                    out.append((f"{name}.{member}", getattr(obj, member)))
    return out


def _takes_arguments(func):
    params = list(inspect.signature(func).parameters.values())
    return any(p.name not in ("self", "cls") for p in params)


def _returns_value(func):
    source = textwrap.dedent(inspect.getsource(func))
    tree = ast.parse(source).body[0]
    for node in ast.walk(tree):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda)) and node is not tree:
            continue
        if isinstance(node, ast.Return) and node.value is not None and not (
                isinstance(node.value, ast.Constant) and node.value.value is None):
            return True
    return False


def _has_section(doc, *names):
    return any(re.search(rf"^{name}\n-{{3,}}", doc, re.M) for name in names)


@pytest.mark.parametrize("name,obj", documented(), ids=[n for n, _ in documented()])
def test_api_objects_document_parameters_and_returns(name, obj):
    doc = inspect.getdoc(obj) or ""
    if inspect.isclass(obj):
        # its own constructor's arguments (an inherited one is documented with its base class)
        if "__init__" in vars(obj) and _takes_arguments(obj.__init__):
            assert _has_section(doc, "Parameters"), f"{name}: the class docstring has no Parameters section"
        return
    func = inspect.unwrap(obj)
    if _takes_arguments(func):
        assert _has_section(doc, "Parameters"), f"{name}: no Parameters section"
    if _returns_value(func):
        assert _has_section(doc, "Returns", "Yields"), f"{name}: no Returns section"
