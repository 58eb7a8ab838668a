"""Built-in writers."""
from .gsd import GSD, write_gsd
from .recorder import Recorder
from .table import Table

__all__ = ["GSD", "Recorder", "Table", "write_gsd"]
