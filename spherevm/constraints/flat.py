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
from ..geometry.sphere import _cross, _norm
from .base import CellMeasures


class FlatGeometry(CellMeasures):
    """Per-cell ``area`` (signed flat areas), ``perimeter`` (sums of chords) and ``area_vector``
    (``(n_cells, 3)``), and the per-corner ``edge`` ``(V, 3, 3)``: ``x[vertex_neighbors[v, k]] -
    x[v]`` (nearest image), which the gradient reuses. ``center`` (the surface's cell centres) is
    computed on first use."""

    def __init__(self, area, perimeter, area_vector, edge, center):
        self.area, self.perimeter, self.area_vector, self.edge = area, perimeter, area_vector, edge
        self._center = center


def _per_cell(state, values):
    """Per-corner vectors ``(V, 3 slots, 3)`` summed into their cells, ``(n_cells, 3)``."""
    cells = state.vertex_cells.reshape(-1)
    return state.device.xp.stack([weighted_bincount(cells, weights=values[..., i].reshape(-1),
                                                    minlength=state.n_cells) for i in range(3)], axis=1)


class FlatFacets:
    """The flat-facet metric, for a :class:`~spherevm.constraints.Constraint` subclass that lists
    this class first (``class FlatSphere(FlatFacets, Sphere)``).

    Corner (v, k) lies in cell ``vertex_cells[v, k]``, whose boundary runs from v to ``n_k =
    vertex_neighbors[v, k]`` and arrives at v from ``n_{k+1}``: the corner owns that cell's edge
    ``v -> n_k``, and the edge borders cells k and k - 1.
    """

    def _corner_edges(self, state):
        """``(edge, size)``: ``x[n_k] - x[v]`` per corner ``(V, 3, 3)`` (nearest images) and the
        vertices' surface sizes shaped to broadcast against it."""
        x = state.positions
        size = self.size(state, state.vertex_replica)[:, None]
        return self.unwrap(x[state.vertex_neighbors], x[:, None], size) - x[:, None], size

    def cell_geometry(self, state, area_vectors: bool = False, metric: bool = True) -> FlatGeometry:
        """Flat areas, chord perimeters and vector areas of every cell (the two flags of
        :meth:`Sphere.cell_geometry` change nothing: all three come together).

        Per corner (v, k), with ``r = x_v - x_0`` (``x_0`` the cell's first vertex, nearest image)
        and ``e = x_{n_k} - x_v``, the vector area gains ``r x e / 2`` (= ``(x_v - x_0) x (x_{n_k}
        - x_0) / 2``) and the perimeter ``|e|``. The area is ``|a|`` signed by ``a . sum_v n(x_v)``,
        the surface normals at the cell's vertices (:func:`spherevm.geometry.flat.signed_area`)."""
        x = state.positions
        edge, size = self._corner_edges(state)
        apex = state.cell_vertices[state.vertex_cells, 0]
        r = x[:, None] - self.unwrap(x[apex], x[:, None], size)
        vector = _per_cell(state, 0.5 * _cross(r, edge))
        normals = state.device.xp.broadcast_to(self.normal(x, size[:, 0])[:, None], edge.shape)
        perimeter = weighted_bincount(state.vertex_cells.reshape(-1), weights=_norm(edge).reshape(-1),
                                      minlength=state.n_cells)
        return FlatGeometry(area=flat.signed_area(vector, _per_cell(state, normals)), perimeter=perimeter,
                            area_vector=vector, edge=edge, center=lambda: self.cell_centers(state))

    def shape_gradient(self, state, geometry: FlatGeometry, d_area, d_perimeter, d_area_vector=None):
        """Surface gradient (V, 3) of ``sum_c d_area[c] A_c + d_perimeter[c] P_c + d_area_vector[c] . a_c``
        (a term whose coefficients are None is left out).

        The signed area ``A = s |a|`` (s = +-1, constant away from ``a . n = 0``) has ``dA = (a / A) .
        da``, so areas and area vectors enter through one per-cell vector ``w = d_area a / A +
        d_area_vector`` (0 for a cell of zero area, the minimal-norm subgradient); cell k at v adds
        ``(x_{n_k} - x_{n_{k+1}}) x w / 2`` (:func:`~spherevm.geometry.flat.vector_area_gradient`).
        The edge ``v -> n_k`` adds ``(d_perimeter[k] + d_perimeter[k - 1])`` times ``-e/|e|``.
        Projected on the tangent plane at each vertex (``project_tangent``)."""
        xp = state.device.xp
        vc, edge = state.vertex_cells, geometry.edge
        terms = []                                                # per corner (V, 3, 3)
        if d_area is not None or d_area_vector is not None:
            w = xp.zeros((state.n_cells, 3)) if d_area_vector is None else d_area_vector
            if d_area is not None:
                area = geometry.area
                per_area = xp.where(area != 0, d_area, 0.0) / xp.where(area != 0, area, 1.0)
                w = w + per_area[:, None] * geometry.area_vector
            terms.append(flat.vector_area_gradient(xp.roll(edge, -1, axis=1), edge, w[vc]))
        if d_perimeter is not None:
            p = d_perimeter[vc]
            terms.append((p + xp.roll(p, 1, axis=1))[..., None] * flat.chord_gradient(edge))
        if not terms:
            return xp.zeros((state.n_vertices, 3))
        corners = sum(terms)
        # three slices added: a strided sum over the slot axis took several times longer
        return self.project_tangent(state.positions, corners[:, 0] + corners[:, 1] + corners[:, 2],
                                    self.size(state, state.vertex_replica))

    def edge_lengths(self, state, u, v):
        """Chord lengths ``|x[v] - x[u]|`` of the edges (u[i], v[i]) (nearest images)."""
        x = state.positions
        return _norm(self.unwrap(x[v], x[u], self.size(state, state.vertex_replica[u])) - x[u])

    def chord_length(self, length, size):
        """The chord of an edge of ``length``: the length itself (lengths are chords)."""
        return length
