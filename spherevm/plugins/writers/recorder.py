"""Record cell centroids of a live Simulation (log-spaced or on any trigger) for the dynamics analysis.

The Recorder keeps raw arrays (a :class:`Recording`); ``spherevm.analysis.Trajectory.from_recording``
turns them into a Trajectory, so this writer needs nothing from the analysis layer above it.
"""
from __future__ import annotations

import math
import os
from dataclasses import dataclass

import numpy as np

from ...shapes import CENTROID_METHODS, cell_centroids
from ...trigger import OnTimesteps, as_trigger
from ..base import Writer


def log_spaced_times(t_max: int, points_per_decade: int = 10, t_min: int = 1, include_zero: bool = True) -> np.ndarray:
    """Sorted unique integer timesteps, about ``points_per_decade`` per decade from ``t_min`` to ``t_max``.

    The points ``t_min * 10^(k / points_per_decade)`` rounded to integers (duplicates at small t
    dropped, so the first decades hold every integer), always including ``t_min`` and ``t_max``,
    plus 0 (the time origin) when ``include_zero``. Feed them to :class:`Recorder` (add the current
    timestep for a run not starting at 0).
    """
    for name, v in (("t_max", t_max), ("t_min", t_min), ("points_per_decade", points_per_decade)):
        if isinstance(v, bool) or int(v) != v or v < 1:
            raise ValueError(f"{name} must be a positive integer, got {v!r}")
    t_max, t_min, ppd = int(t_max), int(t_min), int(points_per_decade)
    if t_max < t_min:
        raise ValueError(f"t_max ({t_max}) must be >= t_min ({t_min})")
    n = int(math.floor(ppd * math.log10(t_max / t_min) + 1e-9))
    pts = np.rint(t_min * 10.0 ** (np.arange(n + 1) / ppd)).astype(np.int64)
    pts = np.concatenate([[0] if include_zero else [], [t_min], pts, [t_max]]).astype(np.int64)
    pts = pts[(pts <= t_max) & ((pts >= t_min) | (include_zero & (pts == 0)))]
    return np.unique(pts)


@dataclass(frozen=True)
class Recording:
    """Cell centroids recorded over time: what a :class:`Recorder` holds and its CSV file stores.

    timesteps : (T,) int64; centroids : (T, n_cells, 3) float64; cell_replica : (n_cells,) replica
    of each cell; radius : (n_replicas,) sphere radius of each replica (None on other surfaces);
    box : (n_replicas, 2) periodic box (Lx, Ly) of each replica on the plane (None on other
    surfaces); constraint, size : the surface and each replica's size (``State.size``), what the
    analysis needs to measure on the surface and unwrap the centroids across a periodic boundary
    (None where only a radius or a box was read, from a CSV).
    """
    timesteps: np.ndarray
    centroids: np.ndarray
    cell_replica: np.ndarray
    radius: np.ndarray
    box: np.ndarray = None
    constraint: object = None
    size: np.ndarray = None


class Recorder(Writer):
    """A writer that keeps the cell centroids of a running Simulation in memory (and optionally a CSV).

    :meth:`recording` returns what was recorded; ``spherevm.analysis.Trajectory.from_recording``
    makes it a Trajectory. A Recorder attached to a simulation already at t > 0 records the current
    configuration at once when its trigger fires at t, so the run keeps its time origin; the same
    timestep is not recorded twice. Cells must keep their number: a Recorder belongs to one State.

    Parameters
    ----------
    trigger : Trigger, int or sequence of int
        When to record: a :class:`~spherevm.trigger.Trigger`, an int period, or a sequence of
        timesteps (made an :class:`~spherevm.trigger.OnTimesteps`); :meth:`log_spaced` builds the
        usual log-spaced one.
    csv : str or path, optional
        Every recorded frame appends rows ``timestep,cell,replica,x,y,z`` (the file is overwritten
        at the first write and flushed after every frame).
    method : {"area", "vertex"}
        The centroid definition (see :func:`~spherevm.analysis.cell_centroids`)."""

    def __init__(self, trigger=None, csv=None, method: str = "area"):
        if trigger is None:
            raise ValueError("trigger is required: a Trigger, an int period, a sequence of timesteps, "
                             "or use Recorder.log_spaced(t_max)")
        super().__init__(as_trigger(trigger))
        if method not in CENTROID_METHODS:
            raise ValueError(f"method must be one of {CENTROID_METHODS}, got {method!r}")
        if csv is not None and (not isinstance(csv, (str, os.PathLike)) or not os.fspath(csv)):
            raise ValueError(f"csv must be a file path or None, got {csv!r}")
        self.csv = None if csv is None else os.fspath(csv)
        self.method = method
        self._times, self._centroids = [], []
        self._cell_replica = self._surface = self._cell_start = None
        self._file = None

    @classmethod
    def log_spaced(cls, t_max: int, points_per_decade: int = 10, start: int = 0, **kwargs) -> "Recorder":
        """Record at ``start`` and at ``start + t`` for ``t`` in :func:`log_spaced_times(t_max, points_per_decade)`."""
        return cls(OnTimesteps(int(start) + log_spaced_times(t_max, points_per_decade)), **kwargs)

    # ------------------------------------------------------------------ operation hooks
    def attach(self, simulation):
        super().attach(simulation)
        t = simulation.timestep
        if t > 0 and simulation.state is not None and self.trigger(t):
            self.write(simulation, t)

    def write(self, simulation, timestep):
        timestep = int(timestep)
        if self._times and self._times[-1] == timestep:
            return
        state = simulation.state
        if self._cell_start is None:
            self._cell_start = np.array(state.cell_start, copy=True)
            self._cell_replica = state.cell_replica_np().copy()
            self._surface = (state.constraint, state.size_np(), state.radius_np(), state.box_np())   # host copies
        elif not np.array_equal(self._cell_start, state.cell_start):
            raise ValueError(f"Recorder: the state at timestep {timestep} has {state.n_cells} cells in "
                             f"{state.n_replicas} replicas, not the {int(self._cell_start[-1])} cells recorded "
                             "so far; use a new Recorder for a new State")
        if self._times and timestep < self._times[-1]:
            raise ValueError(f"Recorder: timestep {timestep} comes before the last recorded one "
                             f"({self._times[-1]}); use a new Recorder after resetting the timestep")
        c = cell_centroids(state, method=self.method)
        self._times.append(timestep)
        self._centroids.append(c)
        if self.csv is not None:
            self._write_csv(timestep, c)

    def record(self, simulation):
        """Record the current configuration now (at ``simulation.timestep``), whatever the trigger."""
        self.write(simulation, simulation.timestep)

    def _write_csv(self, timestep, c):
        if self._file is None:
            self._file = open(self.csv, "w")
            self._file.write("timestep,cell,replica,x,y,z\n")
        n = len(c)
        block = np.column_stack([np.full(n, timestep), np.arange(n), self._cell_replica])
        lines = [f"{int(t)},{int(i)},{int(r)},{x:.17g},{y:.17g},{z:.17g}"
                 for (t, i, r), (x, y, z) in zip(block.tolist(), c.tolist())]  # formatting only
        self._file.write("\n".join(lines) + "\n")
        self._file.flush()

    def flush(self):
        if self._file is not None:
            self._file.flush()

    def close(self):
        if self._file is not None:
            self._file.close()
            self._file = None

    def detach(self):
        self.close()
        super().detach()

    # ------------------------------------------------------------------ results
    @property
    def timesteps(self) -> np.ndarray:
        """Timesteps recorded so far."""
        return np.array(self._times, dtype=np.int64)

    def __len__(self):
        return len(self._times)

    def recording(self) -> Recording:
        """The centroids recorded so far (copies)."""
        if not self._times:
            raise RuntimeError("Recorder has recorded nothing yet: append it to sim.operations.writers and run")
        constraint, size, radius, box = self._surface
        return Recording(self.timesteps, np.stack(self._centroids), self._cell_replica.copy(),
                         None if radius is None else radius.copy(), None if box is None else box.copy(),
                         constraint, size.copy())

    @staticmethod
    def read_csv(path, box=None) -> Recording:
        """The Recording in a Recorder CSV (radius from the centroids' distance to the centre).

        A CSV recorded on the periodic plane does not hold the box: pass it as ``box`` (a side, a
        pair (Lx, Ly), or one pair per replica), e.g. ``state.box_np()``."""
        data = np.loadtxt(path, delimiter=",", skiprows=1, ndmin=2)
        times, first = np.unique(data[:, 0], return_index=True)
        n_cells = int(data[:, 1].max()) + 1
        if len(data) != len(times) * n_cells:
            raise ValueError(f"{path!r}: expected {n_cells} rows per timestep, found {len(data)} rows for "
                             f"{len(times)} timesteps")
        order = np.lexsort((data[:, 1], data[:, 0]))
        data = data[order]
        cent = data[:, 3:6].reshape(len(times), n_cells, 3)
        rep = data[:n_cells, 2].astype(np.int64)
        if box is not None:
            n_rep = int(rep.max()) + 1
            b = np.asarray(box, dtype=np.float64)
            b = np.broadcast_to(np.repeat(b, 2) if b.size == 1 else b.reshape(-1, 2), (n_rep, 2)).copy()
            return Recording(times.astype(np.int64), cent, rep, None, b)
        r = np.linalg.norm(cent[0], axis=1)
        radius = np.bincount(rep, weights=r) / np.bincount(rep)
        return Recording(times.astype(np.int64), cent, rep, radius)

    def __repr__(self):
        return f"Recorder(trigger={self.trigger!r}, csv={self.csv!r}, method={self.method!r}, frames={len(self)})"
