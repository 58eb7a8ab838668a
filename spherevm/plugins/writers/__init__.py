"""Built-in writers."""
from .gsd import GSD
from .table import Table

__all__ = ["GSD", "Table"]
