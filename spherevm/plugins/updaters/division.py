"""Cell division: chosen cells are cut in two through their centre (see docs/growth.md).

Both devices run the same table surgery on the host (:mod:`spherevm.growth`): divisions are rare
events, so on the steps they happen the few arrays needed come to the host, the network is edited
there and the State is refilled on the device (``State.resize``, with capacity); every operation's
per-cell and per-vertex data follows through ``Operation.resized``. On the other steps a pass costs
one small read-back on the GPU (the rate rule's Philox draws and the area rule's comparison run on
the device; only the ids of the chosen cells, usually none, come back).
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from ... import growth
from ... import random as rng
from ...device import launch, load_module
from ...validation import integer
from ..base import Updater
from ..parameters import Parameter
from ..rows import saved_field

_KERNELS = Path(__file__).with_suffix(".cu")


def _rate(name, value):
    """A finite, non-negative float; ValueError naming ``name`` otherwise."""
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a finite number >= 0, got {value!r}") from None
    if not math.isfinite(v) or v < 0:
        raise ValueError(f"{name} must be a finite number >= 0, got {value!r}")
    return v


def by_area(state, threshold, above):
    """Global ids of the cells whose area is above (``above``) or below ``threshold`` times their
    replica's <A>, the farthest from it first. Compared on the State's device; only the chosen
    ids (and their ratios) come back to the host."""
    dev = state.device
    xp = dev.xp
    ratio = state.constraint.cell_geometry(state).area / xp.asarray(state.mean_cell_area)[state.cell_replica]
    cells = dev.to_numpy(xp.flatnonzero(ratio > threshold if above else ratio < threshold))
    if len(cells) == 0:
        return cells.astype(np.int64)
    r = dev.to_numpy(ratio[xp.asarray(cells)])
    return cells[np.argsort(-r if above else r, kind="stable")].astype(np.int64)


def tally(outcome, rep, reasons, refusals):
    """Per replica, the successes among ``outcome`` (a string is a refusal reason); adds the
    refusals to ``refusals`` (n_replicas, len(reasons)) in place."""
    n = len(refusals)
    for k, reason in enumerate(reasons):
        hit = np.array([o == reason for o in outcome], dtype=bool)
        refusals[:, k] += np.bincount(rep[hit], minlength=n)
    done = np.array([not isinstance(o, str) for o in outcome], dtype=bool)
    return np.bincount(rep[done], minlength=n).astype(np.int64)


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


def _optional_rate(name, value):
    return None if value is None else _rate(name, value)


def _division_rule(name, value):
    if not callable(value) and value not in ("rate", "area"):
        raise ValueError(f"rule must be 'rate', 'area' or a callable rule(simulation) -> cell ids, got {value!r}")
    return value


def _division_axis(name, value):
    if not callable(value) and value not in ("hertwig", "random"):
        raise ValueError(f"axis must be 'hertwig', 'random' or a callable axis(simulation, cells), got {value!r}")
    return value


class Division(Updater):
    """Divide cells chosen by a rule, each through its centre across a chosen axis.

    Only replicas the integrator still moves (``integrator.active``) divide. Refusals (see
    :mod:`spherevm.growth`) are counted per replica and reason in ``refused``; ``lineage`` (one per
    cell, initially the cell's index at attach) is inherited by daughters. Sits minimisations out
    (``in_minimize = False``): ``Simulation.minimize`` quenches the tissue at its N, and the time it
    takes does not count for the rate rule. The GPU path chooses the same cells as the CPU (the same
    Philox draws). See docs/growth.md.

    Parameters
    ----------
    rule : {"rate", "area"} or callable
        "rate": every cell divides with probability ``1 - exp(-rate * elapsed)`` per pass,
        ``elapsed`` the time since the last pass (steps times ``dt``), a Philox draw keyed by
        ``(simulation.seed, STREAM_DIVISION, timestep, cell id)``. "area": every cell whose area
        exceeds ``area_threshold * <A>`` (its replica's <A>). A callable ``rule(simulation) -> cell
        ids`` (global indices) of the user's choice.
    rate : float
        For ``rule="rate"``: divisions per cell per unit time.
    area_threshold : float
        For ``rule="area"``.
    axis : {"hertwig", "random"} or callable
        The spindle (the cut runs perpendicular to it through the centre): "hertwig", the cell's
        long axis (the largest eigenvector of its vertex gyration tensor in the tangent plane);
        "random", a uniform angle (the cell's second Philox draw); a callable
        ``axis(simulation, cells) -> (n, 3)`` directions (projected on the tangent plane).
    max_cells : int, optional
        A replica stops growing at this many cells (the cells chosen first by the rule divide:
        smallest draw, largest area, or the callable's order).
    dt : float, optional
        Time per step for the rate rule (default: the integrator's ``dt``, else 1).
    trigger : Trigger or int"""

    narrowable = True
    in_minimize = False
    gpu_surfaces = None           # the surgery runs on the host for every surface
    surface_needs = ("normal", "project_normal", "cell_geometry", "total_area_np", "polygon_area")
    per_cell = ("lineage",)
    per_replica = ("last_divisions", "total_divisions", "refusals")
    checkpoint_fields = ("lineage",) + per_replica

    rule = Parameter(_division_rule)
    rate = Parameter(_optional_rate)
    area_threshold = Parameter(_optional_rate)
    axis = Parameter(_division_axis)
    max_cells = Parameter(lambda name, value: None if value is None else integer(name, value, minimum=1))
    dt = Parameter(_optional_rate)

    def __init__(self, rule="rate", rate=None, area_threshold=None, axis="hertwig", max_cells=None, dt=None,
                 trigger=1):
        super().__init__(trigger)
        self.rule, self.rate, self.area_threshold, self.axis = rule, rate, area_threshold, axis
        self.max_cells = max_cells
        self.dt = dt
        self.lineage = None

    def check_parameters(self):
        """The rule's own parameter is given: ``rate`` for "rate", ``area_threshold`` for "area"."""
        if self.rule == "rate" and self.rate is None:
            raise ValueError("rule='rate' needs rate (divisions per cell per unit time)")
        if self.rule == "area" and self.area_threshold is None:
            raise ValueError("rule='area' needs area_threshold (cells with A > area_threshold * <A> divide)")

    def attach(self, simulation):
        super().attach(simulation)
        state = simulation.state
        n = state.n_replicas
        self._rate_cells = self.implementation("rate_cells", state)
        self.lineage = np.arange(state.n_cells, dtype=np.int64)
        self.last_divisions = np.zeros(n, np.int64)
        self.total_divisions = np.zeros(n, np.int64)
        self.refusals = np.zeros((n, len(growth.DIVISION_REASONS)), np.int64)
        self._last = simulation.timestep

    @property
    def refused(self):
        """Refusals per reason (``growth.DIVISION_REASONS``), each per replica."""
        return {reason: self.refusals[:, k] for k, reason in enumerate(growth.DIVISION_REASONS)}

    def state_to_save(self) -> dict:
        """Lineage, counters, refusals and the rate rule's clock (the timestep of the last pass)."""
        return dict(super().state_to_save(), clock=np.array([self._last], dtype=np.int64))

    def restore_state(self, data: dict):
        super().restore_state(data)
        self._last = int(saved_field(self, data, "clock", np.int64, (1,))[0])

    def after_minimize(self, simulation):
        """The minimisation's iterations are not time for the rate rule."""
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
            return by_area(state, self.area_threshold, above=True)
        steps = max(timestep - self._last, 1)
        p = -math.expm1(-self.rate * steps * self._time_step(simulation))
        if not p > 0:
            return np.zeros(0, np.int64)
        cells = self._rate_cells(simulation, timestep, p)
        u = self._draws(simulation, timestep, cells)[:, 0]
        return cells[np.argsort(u, kind="stable")]

    def _rate_cells_cpu(self, simulation, timestep, p):
        """Cells whose draw 0 is below ``p``, in index order."""
        u = self._draws(simulation, timestep, np.arange(simulation.state.n_cells))[:, 0]
        return np.flatnonzero(u < p)

    def _rate_cells_gpu(self, simulation, timestep, p):
        """The same cells, drawn on the device (bitwise the same uniforms, division.cu); one
        read-back of their ids."""
        import cupy as cp
        n = simulation.state.n_cells
        chosen = cp.empty(n, dtype=cp.uint8)
        launch(load_module(_KERNELS).get_function("division_draws"), n,
               (np.uint32(simulation.seed), np.uint64(timestep), np.int32(n), np.float64(p), chosen))
        return cp.flatnonzero(chosen).get().astype(np.int64)

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
            given = np.asarray(state.device.to_numpy(self.axis(simulation, cells)), dtype=np.float64)
            if given.shape != (len(cells), 3):
                raise ValueError(f"Division: the axis function returned shape {given.shape}; it must return one "
                                 f"3-D direction per cell to divide, shape ({len(cells)}, 3)")
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
        self.last_divisions = tally(outcome, rep, growth.DIVISION_REASONS, self.refusals)
        self.total_divisions += self.last_divisions
        follow(simulation, growth.apply(state, editor))

    @property
    def loggables(self):
        return {
            "division_last": lambda sim: self.last_divisions.copy(),
            "division_total": lambda sim: self.total_divisions.copy(),
            "division_refused": lambda sim: self.refusals.sum(axis=1),
            "division_lineages": lambda sim: np.array([len(np.unique(self.lineage[a:b])) for a, b in
                                                       zip(sim.state.cell_start[:-1], sim.state.cell_start[1:])]),
        }

    def __repr__(self):
        rule = self.rule if not callable(self.rule) else getattr(self.rule, "__name__", "callable")
        return (f"Division(rule={rule!r}, rate={self.rate}, area_threshold={self.area_threshold}, "
                f"axis={self.axis if isinstance(self.axis, str) else 'callable'!r}, max_cells={self.max_cells})")
