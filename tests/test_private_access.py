"""No module reads or writes another object's private attributes (the house's seams are public).

Every ``x._name`` in ``spherevm/`` is read from the source: it is allowed where ``x`` is ``self``,
``cls`` or ``super()``, or where the enclosing class defines ``_name`` itself (another instance of
the same class, as ``State.concatenate`` reads other States). Anything else reaches into an object
of another class, which must offer what is wanted publicly instead.
"""
import ast
import pathlib

ROOT = pathlib.Path(__file__).resolve().parent.parent / "spherevm"
#: public methods of namedtuples (an underscore only keeps them apart from the fields)
NAMEDTUPLE = {"_make", "_replace", "_asdict", "_fields"}


def _defined(cls_node):
    """Private names a class defines: methods, class attributes and ``self._x = ...`` assignments."""
    names = set()
    for node in ast.walk(cls_node):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            names.add(node.name)
        elif isinstance(node, ast.Attribute) and isinstance(node.ctx, ast.Store) \
                and isinstance(node.value, ast.Name) and node.value.id == "self":
            names.add(node.attr)
        elif isinstance(node, ast.Name) and isinstance(node.ctx, ast.Store):
            names.add(node.id)
    return names


def reaches(source: str):
    """``(line, expression)`` of every private attribute reached on another class's object."""
    tree = ast.parse(source)
    out = []

    def visit(node, own):
        if isinstance(node, ast.ClassDef):
            own = _defined(node)
        if isinstance(node, ast.Attribute) and node.attr.startswith("_") and not node.attr.startswith("__"):
            v = node.value
            mine = (isinstance(v, ast.Name) and v.id in ("self", "cls")) or \
                (isinstance(v, ast.Call) and isinstance(v.func, ast.Name) and v.func.id == "super")
            if not mine and node.attr not in own and node.attr not in NAMEDTUPLE:
                out.append((node.lineno, ast.unparse(node)))
        for child in ast.iter_child_nodes(node):
            visit(child, own)

    visit(tree, set())
    return out


def test_no_module_reaches_into_another_objects_private_attributes():
    found = [f"{path.relative_to(ROOT.parent)}:{line}: {expr}"
             for path in sorted(ROOT.rglob("*.py")) for line, expr in reaches(path.read_text())]
    assert not found, "private attributes reached from outside their class:\n" + "\n".join(found)


def test_the_check_sees_a_reach():
    planted = "class Runner:\n    def go(self, sim):\n        sim._updated_at = 3\n        return sim._step()\n"
    assert [e for _, e in reaches(planted)] == ["sim._updated_at", "sim._step"]
    same_class = "class State:\n    def _arrays(self):\n        pass\n    def join(self, other):\n        return other._arrays()\n"
    assert reaches(same_class) == []
