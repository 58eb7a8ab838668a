"""A line tension on every edge: ``E = Lambda * sum over edges of the geodesic edge length``.

A complete spherevm Force plugin in one file, as walked through in ``docs/plugins.md``. It is
registered through the entry-point group ``spherevm.plugins`` (see ``pyproject.toml`` beside it)::

    [project.entry-points."spherevm.plugins"]
    line_tension = "spherevm_line_tension:LineTension"

No edge list is needed: the trivalent network lists every edge twice in ``vertex_neighbors``, once
from each end (``v -> vertex_neighbors[v, k]``). Summing the directed lengths and halving gives the
energy, and each vertex's force is minus the gradient of its own three edge lengths, read straight
from its row: no scatter, no Python loop, and nothing to rebuild after a T1 changes the topology.
The same code runs on NumPy and CuPy arrays (it only uses ``xp`` and the geometry primitives).
"""
from __future__ import annotations

import numpy as np

from spherevm.geometry import geodesic_length, geodesic_length_gradient
from spherevm.plugins import Force, ForceResult

__version__ = "0.1"


class LineTension(Force):
    """Line tension ``Lambda`` (energy per unit length) on every edge of the cell network.

    ``E_r = Lambda * sum_{edges of replica r} R_r * theta_e`` with ``theta_e`` the angle the edge
    subtends at the sphere's centre. Forces are minus the surface gradient (tangent to the sphere).
    Each cell is credited half of every edge it borders, ``Lambda P_c / 2``, as its cell energy.

    With ``VertexModel`` (kP) this shifts the preferred perimeter: ``kP (P - P0)^2 + Lambda P / 2 =
    kP (P - P0 + Lambda / (4 kP))^2 + const``.
    """

    narrowable = True   # it keeps no per-replica data: minimize may narrow

    def __init__(self, tension=1.0, trigger=None):
        super().__init__(trigger)
        value = float(tension)
        if not np.isfinite(value):
            raise ValueError(f"tension must be finite, got {tension!r}")
        self.tension = value

    def compute(self, state) -> ForceResult:
        xp = state.device.xp
        pos = state.positions                                  # (V, 3) on the device
        r = xp.sqrt((pos * pos).sum(axis=1))                   # |x| per vertex
        unit = pos / r[:, None]
        radius = state.radius[state.vertex_replica]            # sphere radius per vertex
        a = unit[:, None, :]                                   # (V, 1, 3): the vertex itself
        b = unit[state.vertex_neighbors]                       # (V, 3, 3): its three neighbours
        lengths = radius[:, None] * geodesic_length(a, b)      # (V, 3): each edge seen from both ends

        # energy: every edge appears twice among the directed lengths
        half = 0.5 * self.tension * lengths
        energy = xp.bincount(xp.repeat(state.vertex_replica, 3), weights=half.reshape(-1),
                             minlength=state.n_replicas)
        # the directed edge v -> vertex_neighbors[v, k] borders cell vertex_cells[v, k] (on its left)
        cell_energy = xp.bincount(state.vertex_cells.reshape(-1), weights=half.reshape(-1),
                                  minlength=state.n_cells)

        # forces: d(R theta)/dx_v = (R / |x_v|) * g, with g the unit-sphere gradient, already tangent
        g = geodesic_length_gradient(a, b).sum(axis=1)         # (V, 3)
        forces = -self.tension * (radius / r)[:, None] * g
        return ForceResult(forces=forces, energy=energy, cell_energy=cell_energy)

    @property
    def loggables(self):
        return {"line_tension_energy": lambda sim: self.energy(sim.state)}

    def __repr__(self):
        return f"LineTension(tension={self.tension})"
