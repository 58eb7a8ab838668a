"""The flat-facet metric on any surface: straight chords, vector areas, exact gradients.

:class:`FlatFacets` gives a constraint the metric of :mod:`spherevm.geometry.flat` (see there for
the formulas and why the vector area): listed before the surface's class, it replaces the surface's
``cell_geometry``, ``shape_gradient``, ``edge_lengths`` and ``chord_length`` and asks the surface
only for its pointwise operations: ``normal`` (the sign of each cell's area), ``project_tangent``
(the gradients, ``P_T = I - n n^T`` at each vertex), ``unwrap`` and ``size`` (the nearest images on
a periodic surface). ``Sphere(metric="flat")`` is the sphere so measured.
"""
from __future__ import annotations

from ..device import weighted_bincount
from ..geometry import flat
from ..geometry.flat import cross_rows as _cross_rows
from ..geometry.flat import dot_rows as _dot_rows
from ..geometry.sphere import _norm
from .base import CellMeasures


class FlatGeometry(CellMeasures):
    """Per-cell ``area`` (signed flat areas), ``perimeter`` (sums of chords) and ``area_vector``
    (``(n_cells, 3)``), and per corner ``edge`` ``(3 components, 3 slots, V)``: ``x[vertex_neighbors[v,
    k]] - x[v]`` (nearest image) and its ``length`` ``(3, V)``, and the unit ``normal`` at each vertex
    ``(3, V)``, which the gradient reuses. ``center`` (the surface's cell centres) is computed on first
    use."""

    def __init__(self, area, perimeter, area_vector, edge, length, normal, center):
        self.area, self.perimeter, self.area_vector = area, perimeter, area_vector
        self.edge, self.length, self.normal = edge, length, normal
        self._center = center


def _slots(state):
    """Slot-major corner tables ``(3, V)``, cached per topology: ``neighbors`` (n_k), ``cells`` (the
    corner's cell) and ``apex`` (that cell's first vertex)."""
    def build():
        xp = state.device.xp
        cells = xp.ascontiguousarray(state.vertex_cells.T)
        return dict(neighbors=xp.ascontiguousarray(state.vertex_neighbors.T), cells=cells,
                    apex=xp.ascontiguousarray(state.cell_vertices[cells, 0]), flat=cells.reshape(-1))
    return state.cached((FlatGeometry, "slots"), build, topology=True)


def _per_cell(state, values):
    """Per-corner vectors ``(3 components, 3 slots, V)`` summed into their cells, ``(n_cells, 3)``."""
    cells = _slots(state)["flat"]
    return state.device.xp.stack([weighted_bincount(cells, weights=values[i].reshape(-1),
                                                    minlength=state.n_cells) for i in range(3)], axis=1)


class FlatFacets:
    """The flat-facet metric, for a :class:`~spherevm.constraints.Constraint` subclass that lists
    this class first (``class FlatSphere(FlatFacets, Sphere)``).

    Corner (v, k) lies in cell ``vertex_cells[v, k]``, whose boundary runs from v to ``n_k =
    vertex_neighbors[v, k]`` and arrives at v from ``n_{k+1}``: the corner owns that cell's edge
    ``v -> n_k``, and the edge borders cells k and k - 1. Corner arrays are component- and
    slot-major, ``(3, 3, V)``: every NumPy call runs on contiguous rows (measured 1.5 times faster
    than ``(V, 3, 3)`` at 65,536 cells).
    """

    def nearest_images(self, d, size):
        """Differences ``d`` ``(3, ..., V)`` (component-major; ``size`` per vertex ``(V, ...)``) taken
        to their nearest periodic images, in place: none here (a surface without images)."""
        return d

    def cell_geometry(self, state, area_vectors: bool = False, metric: bool = True) -> FlatGeometry:
        """Flat areas, chord perimeters and vector areas of every cell (the two flags of
        :meth:`Sphere.cell_geometry` change nothing: all three come together).

        Per corner (v, k), with ``r = x_v - x_0`` (``x_0`` the cell's first vertex, nearest image)
        and ``e = x_{n_k} - x_v``, the vector area gains ``r x e / 2`` (= ``(x_v - x_0) x (x_{n_k}
        - x_0) / 2``) and the perimeter ``|e|``. The area is ``|a|`` signed by ``a . sum_v n(x_v)``,
        the surface normals at the cell's vertices (:func:`spherevm.geometry.flat.signed_area`)."""
        xp = state.device.xp
        t = _slots(state)
        size = self.size(state, state.vertex_replica)
        comp = xp.ascontiguousarray(state.positions.T)
        edge = self.nearest_images(comp[:, t["neighbors"]] - comp[:, None, :], size)
        r = self.nearest_images(comp[:, None, :] - comp[:, t["apex"]], size)
        vector = _per_cell(state, 0.5 * _cross_rows(r, edge))
        normal = xp.ascontiguousarray(self.normal(state.positions, size).T)
        length = xp.sqrt(_dot_rows(edge, edge))
        perimeter = weighted_bincount(t["flat"], weights=length.reshape(-1), minlength=state.n_cells)
        reference = _per_cell(state, xp.broadcast_to(normal[:, None, :], edge.shape))
        return FlatGeometry(area=flat.signed_area(vector, reference), perimeter=perimeter, area_vector=vector,
                            edge=edge, length=length, normal=normal, center=lambda: self.cell_centers(state))

    def shape_gradient(self, state, geometry: FlatGeometry, d_area, d_perimeter, d_area_vector=None):
        """Surface gradient (V, 3) of ``sum_c d_area[c] A_c + d_perimeter[c] P_c + d_area_vector[c] . a_c``
        (a term whose coefficients are None is left out).

        The signed area ``A = s |a|`` (s = +-1, constant away from ``a . n = 0``) has ``dA = (a / A) .
        da``, so areas and area vectors enter through one per-cell vector ``w = d_area a / A +
        d_area_vector`` (0 for a cell of zero area, the minimal-norm subgradient); cell k at v adds
        ``(x_{n_k} - x_{n_{k+1}}) x w / 2`` (:func:`~spherevm.geometry.flat.vector_area_gradient`).
        The edge ``v -> n_k`` adds ``(d_perimeter[k] + d_perimeter[k - 1])`` times ``-e/|e|``.
        Projected on the tangent plane at each vertex, ``P_T = I - n n^T`` with the normals of
        ``geometry``."""
        xp = state.device.xp
        cells, edge = _slots(state)["cells"], geometry.edge
        corners = None                                            # per corner (3, 3, V)
        if d_area is not None or d_area_vector is not None:
            w = xp.zeros((state.n_cells, 3)) if d_area_vector is None else d_area_vector
            if d_area is not None:
                area = geometry.area
                per_area = xp.where(area != 0, d_area, 0.0) / xp.where(area != 0, area, 1.0)
                w = w + per_area[:, None] * geometry.area_vector
            w = xp.ascontiguousarray(w.T)[:, cells]
            corners = 0.5 * _cross_rows(edge - xp.roll(edge, -1, axis=1), w)
        if d_perimeter is not None:
            p = d_perimeter[cells]
            coefficient = -(p + xp.roll(p, 1, axis=0)) / xp.where(geometry.length > 0, geometry.length, 1.0)
            chords = coefficient * edge
            corners = chords if corners is None else corners + chords
        if corners is None:
            return xp.zeros((state.n_vertices, 3))
        g, n = corners[:, 0] + corners[:, 1] + corners[:, 2], geometry.normal
        return (g - _dot_rows(g, n) * n).T

    def edge_lengths(self, state, u, v):
        """Chord lengths ``|x[v] - x[u]|`` of the edges (u[i], v[i]) (nearest images)."""
        x = state.positions
        return _norm(self.unwrap(x[v], x[u], self.size(state, state.vertex_replica[u])) - x[u])

    def chord_length(self, length, size):
        """The chord of an edge of ``length``: the length itself (lengths are chords)."""
        return length
