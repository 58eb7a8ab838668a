"""Plugins: forces, integrators, updaters, writers, all found through entry points.

Every plugin, built-in or third-party, is registered the same way, under the entry-point group
``spherevm.plugins`` (the built-ins in spherevm's own ``pyproject.toml``)::

    [project.entry-points."spherevm.plugins"]
    line_tension = "my_package.tension:LineTension"

``spherevm.plugins.load("line_tension")`` then returns the class, ``available()`` lists every
plugin by name with its kind, and ``describe()`` adds where each comes from.
"""
from __future__ import annotations

from importlib.metadata import entry_points

from . import forces, integrators, updaters, writers
from ..validation import did_you_mean
from .base import Force, ForceResult, Integrator, Operation, Updater, Writer
from .fusion import FusedStage
from .minimizer import Minimizer
from .parameters import Parameter

ENTRY_POINT_GROUP = "spherevm.plugins"
KINDS = (("force", Force), ("integrator", Integrator), ("updater", Updater), ("writer", Writer))


def kind_of(obj) -> str:
    """``"force"``, ``"integrator"``, ``"updater"`` or ``"writer"`` for a plugin class or instance,
    else ``"unknown"``."""
    cls = obj if isinstance(obj, type) else type(obj)
    for kind, base in KINDS:
        if issubclass(cls, base):
            return kind
    return "unknown"


def _entry_points() -> dict:
    """Entry points by name; a name registered more than once maps to all of its registrations."""
    out = {}
    for ep in entry_points(group=ENTRY_POINT_GROUP):
        out.setdefault(ep.name, []).append(ep)
    return out


def load(name: str):
    """The plugin class registered under ``name``."""
    eps = _entry_points()
    if name not in eps:
        raise ValueError(f"no spherevm plugin named {name!r}; available: {sorted(eps)}")
    if len({ep.value for ep in eps[name]}) > 1:
        raise ValueError(f"plugin name {name!r} is registered more than once: "
                         f"{', '.join(ep.value for ep in eps[name])}; uninstall one of them")
    cls = eps[name][0].load()
    if kind_of(cls) == "unknown":
        raise TypeError(f"plugin {name!r} ({cls!r}) must subclass spherevm.plugins.Force, Integrator, "
                        "Updater or Writer")
    return cls


def _one_line(exc) -> str:
    text = str(exc).strip().splitlines()
    return f"{type(exc).__name__}: {text[0] if text else ''}"


def describe() -> list:
    """One row ``(name, kind, source)`` per registered plugin, sorted by name; ``source`` is the
    entry point's ``module:Class`` and its distribution. A plugin that fails to load is listed with
    kind ``"broken: <error>"`` rather than breaking the listing."""
    rows = []
    for name, registered in sorted(_entry_points().items()):
        ep = registered[0]
        source = ep.value
        dist = getattr(ep, "dist", None)
        if dist is not None:
            source += f"  ({dist.metadata['Name']} {dist.version})"
        try:
            kind = kind_of(load(name))
        except Exception as exc:  # a broken third-party plugin must not hide the others
            kind = f"broken: {_one_line(exc)}"
        rows.append((name, kind, source))
    return rows


def parameters_of(cls) -> str:
    """A plugin class's constructor parameters, as ``inspect.signature`` shows them (no ``self``)."""
    import inspect
    try:
        sig = inspect.signature(cls)
    except (TypeError, ValueError):
        return ""
    return ", ".join(str(p) for p in sig.parameters.values() if p.name != "trigger")


def build_force(name: str, params=None):
    """An instance of the force registered as ``name``, built with ``params`` (a dict) by its own
    constructor. ValueError names the plugin (and the parameter) on bad input."""
    params = dict(params or {})
    cls = load(name)
    if kind_of(cls) != "force":
        raise ValueError(f"plugin {name!r} is a {kind_of(cls)}, not a force")
    import inspect
    try:
        sig = inspect.signature(cls)
        unknown = [k for k in params if k not in sig.parameters]
    except (TypeError, ValueError):
        unknown = []
    if unknown:
        raise ValueError(f"force {name!r} has no parameter {unknown[0]!r}{did_you_mean(unknown[0], sig.parameters)}; "
                         f"its parameters: {parameters_of(cls)}")
    try:
        return cls(**params)
    except (ValueError, TypeError) as exc:
        raise ValueError(f"force {name!r}: {exc}") from None


def available() -> dict:
    """Every registered plugin name with its kind (see :func:`describe`)."""
    return {name: kind for name, kind, _ in describe()}


__all__ = ["ENTRY_POINT_GROUP", "Force", "ForceResult", "FusedStage", "Integrator", "Minimizer", "Operation", "Parameter",
           "Updater", "Writer",
           "available", "build_force", "describe", "forces", "integrators", "kind_of", "load", "parameters_of", "updaters", "writers"]
