"""Table writer: loggable quantities per replica as CSV rows, or printed to the terminal."""
from __future__ import annotations

import os
import sys

import numpy as np

from ...logging import Logger
from ..base import Writer
from .arguments import trigger_first

DEFAULT_QUANTITIES = ("timestep", "energy_per_cell", "mean_shape_index", "max_force")


class Table(Writer):
    """One CSV row per replica and trigger: ``timestep, replica, <quantities...>``.

    ``Table(trigger, path=None, quantities=..., logger=None)``: the trigger first, as HOOMD-blue's
    ``hoomd.write.Table(trigger, logger, output)``; HOOMD's positional order with a Logger second
    (``Table(trigger, logger)``, ``Table(trigger, logger, output)``) works too, and ``output=`` is
    another name for ``path``. The older ``Table("log.csv", trigger=100)`` still works with a
    DeprecationWarning. Each row is flushed, so the file is complete up to the last write if the
    run stops.

    Parameters
    ----------
    trigger : Trigger or int
        When to write (default every 1000 steps).
    path : str or path or file, optional
        The CSV file (overwritten at the first write), an open text file (written to, never closed
        here), or None for standard output.
    quantities : sequence of str, optional
        Loggable names; unknown names fail at the first write, before the header.
    logger : Logger, optional
        Instead of ``quantities``.
    output : str or path or file, optional
        HOOMD's name for ``path``."""

    def __init__(self, *args, trigger=None, path=None, quantities=None, logger=None, output=None):
        if len(args) >= 2 and isinstance(args[1], Logger):       # HOOMD: Table(trigger, logger, output)
            if logger is not None:
                raise TypeError("Table() got logger both by position and by keyword")
            args, logger = (args[0],) + args[2:], args[1]
        if output is not None:
            if path is not None:
                raise TypeError("Table() got path and output (HOOMD's name for it); give one")
            path = output
        trigger, path = trigger_first("Table", args, trigger, path, 1000, "path")
        super().__init__(trigger)
        if logger is not None and quantities is not None:
            raise ValueError("give Table either logger= (a spherevm.logging.Logger) or quantities= (names), not both")
        if logger is not None and not isinstance(logger, Logger):
            raise TypeError(f"logger must be a spherevm.logging.Logger, got {type(logger).__name__}")
        if not (path is None or isinstance(path, (str, os.PathLike)) or callable(getattr(path, "write", None))):
            raise TypeError(f"Table: path must be a file path, an open text file or None (standard output), got "
                            f"{type(path).__name__}; HOOMD's order is Table(trigger, logger, output)")
        self.path = path
        self.logger = logger if logger is not None else Logger(DEFAULT_QUANTITIES if quantities is None else quantities)
        self._file = None

    @property
    def quantities(self) -> tuple:
        """The logged columns after ``timestep`` and ``replica``."""
        return tuple(q for q in self.logger.names if q != "timestep")

    def _open(self, simulation):
        if self._file is None:
            self.logger.check(simulation, who="Table writer")
            self._file = (sys.stdout if self.path is None else self.path if hasattr(self.path, "write")
                          else open(self.path, "w"))
            self._file.write(",".join(("timestep", "replica") + self.quantities) + "\n")
        return self._file

    def write(self, simulation, timestep):
        f = self._open(simulation)
        n = simulation.state.n_replicas
        values = self.logger.log(simulation)
        cols = [np.broadcast_to(np.asarray(values[q], dtype=float), (n,)) for q in self.quantities]
        for r in range(n):  # output formatting, not a per-step path
            f.write(",".join([str(timestep), str(r)] + [f"{c[r]:.12g}" for c in cols]) + "\n")
        f.flush()

    def close(self):
        if self._file is not None and self._file is not sys.stdout and self._file is not self.path:
            self._file.close()
        self._file = None
