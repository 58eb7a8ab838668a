"""Plugins: forces, integrators, updaters, writers; built-in or found through entry points.

Third-party packages register classes under the entry-point group ``spherevm.plugins``::

    [project.entry-points."spherevm.plugins"]
    line_tension = "my_package.tension:LineTension"

``spherevm.plugins.load("line_tension")`` then returns the class, and ``available()`` lists every
plugin by name, the built-ins included.
"""
from __future__ import annotations

from importlib.metadata import entry_points

from . import forces, integrators, updaters, writers
from .base import Force, ForceResult, Integrator, Operation, Updater, Writer

ENTRY_POINT_GROUP = "spherevm.plugins"

BUILTINS = {
    "vertex_model": forces.VertexModel,
    "fire": integrators.FIRE,
    "t1": updaters.T1,
    "gsd": writers.GSD,
    "table": writers.Table,
}


def _entry_points():
    return {ep.name: ep for ep in entry_points(group=ENTRY_POINT_GROUP)}


def available() -> dict:
    """Every plugin name with its kind (force, integrator, updater, writer) or 'unloaded'."""
    out = {name: _kind(cls) for name, cls in BUILTINS.items()}
    for name in _entry_points():
        out.setdefault(name, "entry point")
    return out


def _kind(cls):
    for kind, base in (("force", Force), ("integrator", Integrator), ("updater", Updater), ("writer", Writer)):
        if isinstance(cls, type) and issubclass(cls, base):
            return kind
    return "unknown"


def load(name: str):
    """The plugin class registered under ``name`` (built-in first, then entry points)."""
    if name in BUILTINS:
        return BUILTINS[name]
    eps = _entry_points()
    if name not in eps:
        known = sorted(set(BUILTINS) | set(eps))
        raise ValueError(f"no spherevm plugin named {name!r}; available: {known}")
    cls = eps[name].load()
    if _kind(cls) == "unknown":
        raise TypeError(f"plugin {name!r} ({cls!r}) must subclass spherevm.plugins.Force, Integrator, "
                        "Updater or Writer")
    return cls


__all__ = ["ENTRY_POINT_GROUP", "Force", "ForceResult", "Integrator", "Operation", "Updater", "Writer",
           "available", "forces", "integrators", "load", "updaters", "writers"]
