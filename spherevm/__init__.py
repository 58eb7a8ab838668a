"""spherevm: vertex models of confluent tissue on curved surfaces, on the CPU or an NVIDIA GPU.

Submodules and the top-level names load on first use (PEP 562: ``svm.init``, ``svm.Simulation``
import what they need when first touched), so ``import spherevm`` costs nothing and the
``spherevm`` command does all its heavy imports inside ``main``, where a Ctrl-C during start-up
ends in one line (exit status 130) instead of a traceback.
"""
import importlib

__version__ = "0.1.0"

_NAMES = {"Simulation": "simulation", "State": "state", "write_gsd": "plugins.writers"}

__all__ = ["Simulation", "State", "analysis", "constraints", "device", "geometry", "gsdio", "init", "plugins",
           "shapes", "topology", "trigger", "__version__"]


def __getattr__(name):
    """``spherevm.<submodule>`` or one of the top-level names, imported on first use."""
    if name in _NAMES:
        value = getattr(importlib.import_module(f".{_NAMES[name]}", __name__), name)
        globals()[name] = value
        return value
    if not name.startswith("_"):
        try:
            return importlib.import_module(f".{name}", __name__)
        except ModuleNotFoundError as exc:
            if exc.name != f"{__name__}.{name}":
                raise
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__():
    return sorted(set(globals()) | set(__all__))
