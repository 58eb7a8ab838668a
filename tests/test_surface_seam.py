"""Nothing outside ``spherevm/constraints/`` branches on which surface a State is on: generic code
asks the constraint (docs/surfaces.md, "What a surface provides").

Every module's source is read: outside ``constraints/`` none may test an object against a surface
class (``isinstance``/``issubclass`` with, or a comparison to, ``Sphere``, ``PeriodicPlane``, ...:
every subclass of :class:`~spherevm.constraints.Constraint`, and the kernels' ``GeodesicSphere``),
compare anything with a surface's name (``"sphere"``, ``"periodic_plane"``, or the command line's
``"plane"``), tell the surface by whether a State's ``radius`` or ``box`` is None, read the retired
``size_name``, or ask ``hasattr`` for a surface's method. The one
exception: a user's ``surface`` option (a string typed on the command line or in a sweep spec,
``surface == "plane"``) may be compared with the names it takes.
"""
import ast
import pathlib

from spherevm.constraints import Constraint

ROOT = pathlib.Path(__file__).resolve().parent.parent / "spherevm"
#: modules allowed to branch for now, and why (each entry must still branch, or leave the list)
ALLOWED = {"analysis/curvature.py": "gaussian_curvature's formula per surface, to become a method of each "
                                    "constraint once the Torus and GaussianBump stubs are real surfaces"}


def _subclasses(cls):
    return {cls}.union(*(_subclasses(sub) for sub in cls.__subclasses__()))


SURFACES = _subclasses(Constraint) - {Constraint}
#: class names that stand for a surface
CLASSES = {c.__name__ for c in SURFACES} | {"GeodesicSphere"}
#: names a surface goes by (its ``name``, and the command line's "plane")
NAMES = {c.name for c in SURFACES} | {"plane"}
#: the State's views of a sphere's or a plane's size (None on other surfaces)
SIZES = {"radius", "box", "radius_np", "box_np"}
#: methods some surface has and the base does not
METHODS = {n for c in SURFACES for n in vars(c) if not n.startswith("__")} - set(dir(Constraint))


def _named(node) -> str:
    """The identifier a Name or Attribute ends in ("" for anything else)."""
    return node.id if isinstance(node, ast.Name) else node.attr if isinstance(node, ast.Attribute) else ""


def branches(source: str):
    """``(line, expression)`` of every test of which surface something is on."""
    out = []
    for node in ast.walk(ast.parse(source)):
        found = False
        if isinstance(node, ast.Call) and _named(node.func) in ("isinstance", "issubclass") and len(node.args) == 2:
            kinds = node.args[1].elts if isinstance(node.args[1], ast.Tuple) else [node.args[1]]
            found = any(_named(k) in CLASSES for k in kinds)
        elif isinstance(node, ast.Call) and _named(node.func) == "hasattr" and len(node.args) == 2:
            found = isinstance(node.args[1], ast.Constant) and node.args[1].value in METHODS
        elif isinstance(node, ast.Compare):
            sides = [node.left, *node.comparators]
            option = any(_named(s) == "surface" for s in sides)
            none = any(isinstance(s, ast.Constant) and s.value is None for s in sides)
            sized = any(_named(s.func if isinstance(s, ast.Call) else s) in SIZES and not isinstance(s, ast.Name)
                        for s in sides)
            found = any(_named(s) in CLASSES for s in sides) or none and sized or not option and any(
                isinstance(s, ast.Constant) and s.value in NAMES for s in sides)
        elif isinstance(node, ast.Attribute) and node.attr == "size_name":
            found = True
        if found:
            out.append((node.lineno, ast.unparse(node)))
    return out


def test_no_module_outside_constraints_branches_on_the_surface():
    inside = ROOT / "constraints"
    found = [f"{path.relative_to(ROOT.parent)}:{line}: {expr}" for path in sorted(ROOT.rglob("*.py"))
             if inside not in path.parents and path.relative_to(ROOT).as_posix() not in ALLOWED
             for line, expr in branches(path.read_text())]
    assert not found, "surface branches outside spherevm/constraints/ (ask the constraint instead):\n" + "\n".join(found)
    stale = [name for name in ALLOWED if (ROOT / name).exists() and not branches((ROOT / name).read_text())]
    assert not stale, f"allowed to branch but no longer does: {stale}; take it off ALLOWED"


def test_the_check_sees_a_branch():
    planted = ("from .constraints import PeriodicPlane, Sphere\n"
               "def f(state, args):\n"
               "    if isinstance(state.constraint, (Sphere, int)):\n"
               "        return state.radius\n"
               "    if type(state.constraint) is PeriodicPlane or state.constraint.name == 'periodic_plane':\n"
               "        return getattr(state, state.constraint.size_name)\n"
               "    if hasattr(state.constraint, 'unwrapped_cells') or state.box_np() is None:\n"
               "        return radius is None\n"
               "        return 1\n"
               "    return args.surface == 'plane'\n")
    assert sorted(e for _, e in branches(planted)) == sorted([
        "isinstance(state.constraint, (Sphere, int))", "type(state.constraint) is PeriodicPlane",
        "state.constraint.name == 'periodic_plane'", "state.constraint.size_name",
        "hasattr(state.constraint, 'unwrapped_cells')", "state.box_np() is None"])
