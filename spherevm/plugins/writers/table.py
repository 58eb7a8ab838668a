"""Table writer: loggable quantities per replica as CSV rows, or printed to the terminal."""
from __future__ import annotations

import sys

import numpy as np

from ..base import Writer

DEFAULT_QUANTITIES = ("timestep", "energy_per_cell", "mean_shape_index", "max_force")


class Table(Writer):
    """One CSV row per replica and trigger: ``timestep, replica, <quantities...>``.

    ``path=None`` writes to standard output. Each row is flushed, so the file is complete up to
    the last write if the run stops.
    """

    def __init__(self, path=None, quantities=DEFAULT_QUANTITIES, trigger=1000):
        super().__init__(trigger)
        self.path = path
        self.quantities = tuple(q for q in quantities if q != "timestep")
        self._file = None

    def _open(self):
        if self._file is None:
            self._file = sys.stdout if self.path is None else open(self.path, "w")
            self._file.write(",".join(("timestep", "replica") + self.quantities) + "\n")
        return self._file

    def write(self, simulation, timestep):
        f = self._open()
        n = simulation.state.n_replicas
        cols = [np.broadcast_to(np.asarray(simulation.log(q), dtype=float), (n,)) for q in self.quantities]
        for r in range(n):  # output formatting, not a per-step path
            f.write(",".join([str(timestep), str(r)] + [f"{c[r]:.12g}" for c in cols]) + "\n")
        f.flush()

    def close(self):
        if self._file is not None and self._file is not sys.stdout:
            self._file.close()
        self._file = None
