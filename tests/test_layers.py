"""The import graph: layers point down only and no module imports itself back (issue: the house).

Every ``import`` in ``spherevm/`` is read from the source (top-level and inside functions alike),
resolved to a spherevm module and checked against the layer table below, so a later change cannot
bring back a circle or an upward import.
"""
import ast
import pathlib

import pytest

ROOT = pathlib.Path(__file__).resolve().parent.parent / "spherevm"

# Lowest first. A module may import from its own layer's lower entries only as the graph allows
# (circles are checked separately) and from any lower layer.
LAYERS = [
    ["geometry", "device", "kernel_struct", "validation", "random", "trigger", "logging", "provenance", "progress",
     "gsdrecover"],
    ["constraints"],
    ["simplicity", "topology", "folding", "growth"],
    ["state"],
    ["shapes", "gsdio", "init", "init_plane", "init_surface"],
    ["plugins", "testing"],
    ["operations", "plan", "minimization", "tissue_steps", "graphs"],
    ["runs", "checkpoints", "simulation"],
    ["analysis", "protocols", "sweeps", "export", "render", "ovito"],
    ["cli", "__main__"],
]
RANK = {name: i for i, names in enumerate(LAYERS) for name in names}
MAX_LINES = 500


def modules():
    for path in sorted(ROOT.rglob("*.py")):
        parts = path.relative_to(ROOT.parent).with_suffix("").parts
        name = ".".join(parts[:-1] if parts[-1] == "__init__" else parts)
        yield name, path


def imported(name, path):
    """spherevm modules that ``name`` imports (absolute names, the package prefix included)."""
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    out = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            out.update(a.name for a in node.names if a.name.split(".")[0] == "spherevm")
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")
                base = base[:len(base) - node.level + 1]
                target = ".".join(base + ([node.module] if node.module else []))
            else:
                target = node.module or ""
            if target.split(".")[0] != "spherevm":
                continue
            # ``from . import x`` imports the submodule x when there is one
            for alias in node.names:
                sub = f"{target}.{alias.name}"
                out.add(sub if _exists(sub) else target)
    return out


def _exists(dotted):
    rel = pathlib.Path(*dotted.split(".")[1:])
    return (ROOT / rel).with_suffix(".py").exists() or (ROOT / rel / "__init__.py").exists()


def layer(module):
    parts = module.split(".")
    return None if len(parts) < 2 else RANK.get(parts[1])


GRAPH = {name: imported(name, path) for name, path in modules()}


def test_every_module_has_a_layer():
    missing = sorted(m for m in GRAPH if m != "spherevm" and layer(m) is None)
    assert not missing, f"add these to LAYERS in tests/test_layers.py: {missing}"


@pytest.mark.parametrize("name", sorted(m for m in GRAPH if m != "spherevm"))
def test_imports_point_down(name):
    up = sorted(t for t in GRAPH[name] if t != "spherevm" and layer(t) is not None and layer(t) > layer(name))
    assert not up, f"{name} (layer {layer(name)}) imports from a higher layer: {up}"


def test_no_import_circles():
    graph = {m: {t for t in ts if t in GRAPH and t != m and not m.startswith(t + ".")} for m, ts in GRAPH.items()}
    graph.pop("spherevm")
    state, stack = {}, []

    def visit(m):
        state[m] = "open"
        stack.append(m)
        for t in sorted(graph.get(m, ())):
            if state.get(t) == "open":
                raise AssertionError("import circle: " + " -> ".join(stack[stack.index(t):] + [t]))
            if t not in state:
                visit(t)
        stack.pop()
        state[m] = "done"

    for m in sorted(graph):
        if m not in state:
            visit(m)


@pytest.mark.parametrize("name", sorted(GRAPH))
def test_modules_stay_small(name):
    path = dict(modules())[name]
    n = len(path.read_text().splitlines())
    assert n <= MAX_LINES, f"{path.relative_to(ROOT.parent)} has {n} lines (at most {MAX_LINES}): split it by concept"


def test_the_checker_sees_lazy_and_absolute_imports(tmp_path):
    """The walker must catch an import inside a function, relative or absolute."""
    (tmp_path / "m.py").write_text("def f():\n    from ..simulation import Simulation\n    import spherevm.cli\n")
    assert imported("spherevm.constraints.m", tmp_path / "m.py") == {"spherevm.simulation", "spherevm.cli"}
