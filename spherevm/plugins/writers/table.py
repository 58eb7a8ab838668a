"""Table writer: loggable quantities per replica as CSV rows, or printed to the terminal."""
from __future__ import annotations

import sys

import numpy as np

from ...logging import Logger
from ..base import Writer
from .arguments import trigger_first

DEFAULT_QUANTITIES = ("timestep", "energy_per_cell", "mean_shape_index", "max_force")


class Table(Writer):
    """One CSV row per replica and trigger: ``timestep, replica, <quantities...>``.

    ``Table(trigger, path=None, quantities=..., logger=None)``: the trigger first, as HOOMD-blue's
    ``hoomd.write.Table(trigger, logger)`` (the older ``Table("log.csv", trigger=100)`` still works
    with a DeprecationWarning). Each row is flushed, so the file is complete up to the last write
    if the run stops.

    Parameters
    ----------
    trigger : Trigger or int
        When to write (default every 1000 steps).
    path : str or path, optional
        The CSV file; None writes to standard output.
    quantities : sequence of str, optional
        Loggable names; unknown names fail at the first write, before the header.
    logger : Logger, optional
        Instead of ``quantities``."""

    def __init__(self, *args, trigger=None, path=None, quantities=None, logger=None):
        trigger, path = trigger_first("Table", args, trigger, path, 1000, "path")
        super().__init__(trigger)
        if logger is not None and quantities is not None:
            raise ValueError("give Table either logger= (a spherevm.logging.Logger) or quantities= (names), not both")
        if logger is not None and not isinstance(logger, Logger):
            raise TypeError(f"logger must be a spherevm.logging.Logger, got {type(logger).__name__}")
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
            self._file = sys.stdout if self.path is None else open(self.path, "w")
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
        if self._file is not None and self._file is not sys.stdout:
            self._file.close()
        self._file = None
