"""Built-in integrators."""
from .brownian import Active, Brownian
from .fire import FIRE

__all__ = ["Active", "Brownian", "FIRE"]
