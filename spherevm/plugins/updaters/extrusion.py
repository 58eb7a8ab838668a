"""T2 extrusion: small triangular cells are removed, their three vertices merged into one."""
from __future__ import annotations

import numpy as np

from ... import growth
from ..base import Updater
from ..parameters import Parameter
from .division import _optional_rate, active_cells, by_area, follow, tally


def _extrusion_rule(name, value):
    if not callable(value) and value != "area":
        raise ValueError(f"rule must be 'area' or a callable rule(simulation) -> cell ids, got {value!r}")
    return value


class Extrusion(Updater):
    """Remove (T2) the triangular cells a rule selects: their three vertices merge into one at
    their centroid, joining the three neighbours, which lose a side each.

    Only triangles are extruded (the standard T2): a selected cell with more sides is refused and
    counted (``"not_triangle"``; T1s must first take its sides), as are a triangle with a
    three-sided neighbour or neighbours that are not three distinct cells (``"neighbours"``) and one
    whose removal would fold a neighbour (``"fold"``). Counters per replica: ``last_extrusions``,
    ``total_extrusions``, ``refused[reason]``. Only replicas the integrator still moves are touched.
    Sits minimisations out, and runs on both devices, as :class:`~spherevm.plugins.updaters.Division`.

    Parameters
    ----------
    rule : {"area"} or callable
        "area": every cell with area below ``area_threshold * <A>`` (its replica's <A>); a callable
        ``rule(simulation) -> cell ids`` (global indices).
    area_threshold : float
        For ``rule="area"``.
    trigger : Trigger or int"""

    narrowable = True
    in_minimize = False
    gpu_surfaces = None
    surface_needs = ("normal", "project_normal", "cell_geometry", "total_area_np", "polygon_area")
    per_replica = ("last_extrusions", "total_extrusions", "refusals")
    checkpoint_fields = per_replica

    rule = Parameter(_extrusion_rule)
    area_threshold = Parameter(_optional_rate)

    def __init__(self, rule="area", area_threshold=None, trigger=1):
        super().__init__(trigger)
        self.rule, self.area_threshold = rule, area_threshold

    def check_parameters(self):
        """The area rule needs ``area_threshold``."""
        if self.rule == "area" and self.area_threshold is None:
            raise ValueError("rule='area' needs area_threshold (cells with A < area_threshold * <A> are removed)")

    def attach(self, simulation):
        super().attach(simulation)
        n = simulation.state.n_replicas
        self.last_extrusions = np.zeros(n, np.int64)
        self.total_extrusions = np.zeros(n, np.int64)
        self.refusals = np.zeros((n, len(growth.EXTRUSION_REASONS)), np.int64)

    @property
    def refused(self):
        """Refusals per reason (``growth.EXTRUSION_REASONS``), each per replica."""
        return {reason: self.refusals[:, k] for k, reason in enumerate(growth.EXTRUSION_REASONS)}

    def choose(self, simulation):
        """Global ids of the cells to remove now (smallest area first for the area rule)."""
        state = simulation.state
        if callable(self.rule):
            cells = np.asarray(self.rule(simulation), dtype=np.int64).reshape(-1)
            if len(cells) and (cells.min() < 0 or cells.max() >= state.n_cells):
                raise IndexError(f"rule returned cell ids outside 0..{state.n_cells - 1}")
            _, first = np.unique(cells, return_index=True)
            return cells[np.sort(first)]
        return by_area(state, self.area_threshold, above=False)

    def update(self, simulation, timestep):
        state = simulation.state
        n = state.n_replicas
        cells = active_cells(simulation, self.choose(simulation))
        self.last_extrusions = np.zeros(n, np.int64)
        if len(cells) == 0:
            return
        rep = state.cell_replica_np()[cells]
        editor = growth.Editor(state)
        outcome = [editor.extrude(c) for c in cells.tolist()]
        self.last_extrusions = tally(outcome, rep, growth.EXTRUSION_REASONS, self.refusals)
        self.total_extrusions += self.last_extrusions
        follow(simulation, growth.apply(state, editor))

    @property
    def loggables(self):
        return {"extrusion_last": lambda sim: self.last_extrusions.copy(),
                "extrusion_total": lambda sim: self.total_extrusions.copy(),
                "extrusion_refused": lambda sim: self.refusals.sum(axis=1)}

    def __repr__(self):
        rule = self.rule if not callable(self.rule) else getattr(self.rule, "__name__", "callable")
        return f"Extrusion(rule={rule!r}, area_threshold={self.area_threshold})"
