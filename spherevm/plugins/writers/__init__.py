"""Built-in writers."""
from .gsd import GSD
from .recorder import Recorder
from .table import Table

__all__ = ["GSD", "Recorder", "Table"]
