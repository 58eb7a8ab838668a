"""Built-in integrators."""
from .fire import FIRE

__all__ = ["FIRE"]
