"""Built-in updaters."""
from .t1 import T1

__all__ = ["T1"]
