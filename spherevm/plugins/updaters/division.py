"""Cell division: chosen cells are cut in two through their centre (see docs/growth.md)."""
from __future__ import annotations

import math

import numpy as np

from ... import growth
from ... import random as rng
from ...validation import integer
from ..base import Updater


def _rate(name, value):
    """A finite, non-negative float; ValueError naming ``name`` otherwise."""
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a finite number >= 0, got {value!r}") from None
    if not math.isfinite(v) or v < 0:
        raise ValueError(f"{name} must be a finite number >= 0, got {value!r}")
    return v


def cpu_only(op, simulation):
    """Refuse a State on the GPU: the table surgery runs on the host only (for now)."""
    if simulation.state.device.is_gpu:
        raise ValueError(f"{type(op).__name__} runs on the CPU only for now (it changes the numbers of cells and "
                         "vertices on the host); use Simulation(device='cpu')")


def follow(simulation, change):
    """After a resize: every operation's per-cell and per-vertex data follows
    (:meth:`Operation.resized`), cached forces go stale, the integrator forgets the moved vertices."""
    if change is None:
        return
    for op in simulation.operations:
        op.resized(change)
    simulation.state_changed()
    integrator = simulation.operations.integrator
    if integrator is not None and len(change.moved):
        integrator.reset_vertices(simulation.state.device.asarray(change.moved))


def active_cells(simulation, cells):
    """``cells`` of the replicas the integrator still moves (all when there is no integrator)."""
    integrator = simulation.operations.integrator
    if integrator is None or len(cells) == 0:
        return cells
    return cells[integrator.active[simulation.state.cell_replica_np()[cells]]]


class Division(Updater):
    """Divide cells chosen by a rule, each through its centre across a chosen axis.

    Rules (``rule``), built in:

    * ``"rate"``: every cell divides with probability ``1 - exp(-rate * elapsed)`` per pass, where
      ``elapsed`` is the time since the last pass (steps times ``dt``; ``dt`` defaults to the
      integrator's ``dt``, else 1). The draw is Philox, keyed by ``(simulation.seed,
      STREAM_DIVISION, timestep, cell id)``, so CPU and GPU would agree;
    * ``"area"``: every cell whose area exceeds ``area_threshold * <A>`` (its replica's <A>);
    * a callable ``rule(simulation) -> cell ids`` (global indices) of the user's choice.

    Axes (``axis``, the spindle: the cut runs perpendicular to it through the centre):

    * ``"hertwig"`` (default): the cell's long axis, the eigenvector of the largest eigenvalue of
      its vertex gyration tensor in the tangent plane at its centre (Hertwig's rule);
    * ``"random"``: a uniform angle in the tangent plane, the second Philox draw of the cell;
    * a callable ``axis(simulation, cells) -> (n, 3)`` directions (projected on the tangent plane).

    ``max_cells``: a replica stops growing at this many cells (the cells chosen first by the rule
    divide: smallest draw, largest area, or the callable's order). Only replicas the integrator
    still moves (``integrator.active``) divide. Refusals (see :mod:`spherevm.growth`) are counted
    per replica and reason in ``refused``; ``lineage`` (one per cell, initially the cell's index at
    attach) is inherited by daughters. Not narrowable: ``Simulation.minimize`` steps the whole
    State while a Division is attached. CPU only for now.
    """

    narrowable = False
    gpu_surfaces = ()
    surface_needs = ("normal", "project_normal", "cell_geometry", "total_area_np")
    per_cell = ("lineage",)

    def __init__(self, rule="rate", rate=None, area_threshold=None, axis="hertwig", max_cells=None, dt=None,
                 trigger=1):
        super().__init__(trigger)
        if not callable(rule) and rule not in ("rate", "area"):
            raise ValueError(f"rule must be 'rate', 'area' or a callable rule(simulation) -> cell ids, got {rule!r}")
        if rule == "rate":
            if rate is None:
                raise ValueError("rule='rate' needs rate (divisions per cell per unit time)")
            rate = _rate("rate", rate)
        if rule == "area":
            if area_threshold is None:
                raise ValueError("rule='area' needs area_threshold (cells with A > area_threshold * <A> divide)")
            area_threshold = _rate("area_threshold", area_threshold)
        if not callable(axis) and axis not in ("hertwig", "random"):
            raise ValueError(f"axis must be 'hertwig', 'random' or a callable axis(simulation, cells), got {axis!r}")
        self.rule, self.rate, self.area_threshold, self.axis = rule, rate, area_threshold, axis
        self.max_cells = None if max_cells is None else integer("max_cells", max_cells, minimum=1)
        self.dt = None if dt is None else _rate("dt", dt)
        self.lineage = None

    def attach(self, simulation):
        super().attach(simulation)
        cpu_only(self, simulation)
        state = simulation.state
        n = state.n_replicas
        self.lineage = np.arange(state.n_cells, dtype=np.int64)
        self.last_divisions = np.zeros(n, np.int64)
        self.total_divisions = np.zeros(n, np.int64)
        self.refused = {reason: np.zeros(n, np.int64) for reason in growth.DIVISION_REASONS}
        self._last = simulation.timestep

    # ------------------------------------------------------------------ choosing
    def _time_step(self, simulation):
        if self.dt is not None:
            return self.dt
        return float(getattr(simulation.operations.integrator, "dt", 1.0))

    def choose(self, simulation, timestep):
        """Global ids of the cells to divide now, in priority order (before ``max_cells``)."""
        state = simulation.state
        if callable(self.rule):
            cells = np.asarray(self.rule(simulation), dtype=np.int64).reshape(-1)
            if len(cells) and (cells.min() < 0 or cells.max() >= state.n_cells):
                raise IndexError(f"rule returned cell ids outside 0..{state.n_cells - 1}")
            return np.unique(cells) if len(np.unique(cells)) != len(cells) else cells
        if self.rule == "area":
            area = state.constraint.cell_areas_np(state)
            ratio = area / state.mean_cell_area[state.cell_replica_np()]
            cells = np.flatnonzero(ratio > self.area_threshold)
            return cells[np.argsort(-ratio[cells], kind="stable")]
        steps = max(timestep - self._last, 1)
        p = -math.expm1(-self.rate * steps * self._time_step(simulation))
        u = self._draws(simulation, timestep, np.arange(state.n_cells))[:, 0]
        cells = np.flatnonzero(u < p)
        return cells[np.argsort(u[cells], kind="stable")]

    @staticmethod
    def _draws(simulation, timestep, cells):
        return rng.uniform(simulation.seed, rng.STREAM_DIVISION, int(timestep), np.asarray(cells, np.int64), 2)

    def _cap(self, state, cells):
        if self.max_cells is None or len(cells) == 0:
            return cells
        rep = state.cell_replica_np()[cells]
        room = np.maximum(self.max_cells - state.cells_per_replica, 0)
        rank = np.zeros(len(cells), np.int64)          # position of each cell among its replica's chosen
        for r in np.unique(rep):
            rank[rep == r] = np.arange((rep == r).sum())
        return cells[rank < room[rep]]

    # ------------------------------------------------------------------ the pass
    def update(self, simulation, timestep):
        state = simulation.state
        n = state.n_replicas
        cells = self._cap(state, active_cells(simulation, self.choose(simulation, timestep)))
        self._last = timestep
        self.last_divisions = np.zeros(n, np.int64)
        if len(cells) == 0:
            return
        rep = state.cell_replica_np()[cells]
        editor = growth.Editor(state)
        if callable(self.axis):
            given = np.asarray(self.axis(simulation, cells), dtype=np.float64).reshape(len(cells), 3)
        elif self.axis == "random":
            angles = rng.TWO_PI * self._draws(simulation, timestep, cells)[:, 1]
        outcome = []
        for i, c in enumerate(cells.tolist()):
            if callable(self.axis):
                m = editor.tangent(c, given[i])
            elif self.axis == "random":
                m = editor.angle_axis(c, angles[i])
            else:
                m = editor.long_axis(c)
            outcome.append(editor.divide(c, m))
        done = np.array([not isinstance(o, str) for o in outcome])
        for reason in growth.DIVISION_REASONS:
            hit = np.array([o == reason for o in outcome], dtype=bool)
            self.refused[reason] += np.bincount(rep[hit], minlength=n)
        self.last_divisions = np.bincount(rep[done], minlength=n).astype(np.int64)
        self.total_divisions += self.last_divisions
        follow(simulation, growth.apply(state, editor))

    @property
    def loggables(self):
        return {
            "division_last": lambda sim: self.last_divisions.copy(),
            "division_total": lambda sim: self.total_divisions.copy(),
            "division_refused": lambda sim: sum(self.refused.values()),
            "division_lineages": lambda sim: np.array([len(np.unique(self.lineage[a:b])) for a, b in
                                                       zip(sim.state.cell_start[:-1], sim.state.cell_start[1:])]),
        }

    def __repr__(self):
        rule = self.rule if not callable(self.rule) else getattr(self.rule, "__name__", "callable")
        return (f"Division(rule={rule!r}, rate={self.rate}, area_threshold={self.area_threshold}, "
                f"axis={self.axis if isinstance(self.axis, str) else 'callable'!r}, max_cells={self.max_cells})")
