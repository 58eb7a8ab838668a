"""The flat periodic box: a rectangle ``[0, Lx) x [0, Ly)`` at z = 0 per replica, with minimum images."""
from __future__ import annotations

import numpy as np

from ..device import array_module
from .base import Constraint


def _wrap(xp, x, box):
    """``x`` (..., 2) into ``[0, L)`` per component (``box`` broadcasts against it)."""
    w = x - box * xp.floor(x / box)
    return xp.where(w >= box, w - box, w)      # x just below 0 can round up to L


def minimum_image(d, box):
    """The periodic image of the in-plane displacement ``d`` (..., 2) with components in ``[-L/2, L/2]``."""
    xp = array_module(d)
    return d - box * xp.rint(d / box)


class PlaneGeometry:
    """Per-cell area and perimeter, and the per-corner edge vectors that the gradient reuses.

    ``edge`` (V, 3 slots, 2) is the minimum image of ``x[vertex_neighbors[v, k]] - x[v]``, ``length``
    its length. ``center`` (the vertex centroid of each cell, unwrapped about the cell's first vertex
    and wrapped back into the box, ``(n_cells, 3)``) is computed on first use."""

    def __init__(self, area, perimeter, edge, length, center):
        self.area, self.perimeter, self.edge, self.length = area, perimeter, edge, length
        self._center = center

    @property
    def center(self):
        if callable(self._center):
            self._center = self._center()
        return self._center


class PeriodicPlane(Constraint):
    """A flat rectangular periodic box per replica (``State.box``, ``(n_replicas, 2)`` = (Lx, Ly)).

    Positions are stored wrapped into ``[0, Lx) x [0, Ly)`` with z = 0. Edges are minimum images, so
    a cell may straddle the boundary; perimeters are sums of Euclidean edge lengths and areas the
    shoelace formula on each polygon unwrapped edge by edge from its first vertex. Normal ``(0, 0, 1)``; P_T
    drops z, P_N sets z = 0 and wraps. The network on a periodic plane is a torus: V - E + F = 0,
    and the cells tile the box (total area Lx Ly). Edges must be shorter than half the box.
    """

    name = "periodic_plane"
    size_name = "box"
    euler_characteristic = 0

    # ------------------------------------------------------------------ pointwise
    def normal(self, x):
        xp = array_module(x)
        n = xp.zeros_like(x)
        n[..., 2] = 1.0
        return n

    def project_tangent(self, x, v):
        out = v.copy()
        out[..., 2] = 0.0
        return out

    def project_normal(self, x, box):
        xp = array_module(x)
        out = xp.zeros_like(x)
        out[..., :2] = _wrap(xp, x[..., :2], xp.asarray(box))
        return out

    def geodesic_offset(self, x, direction, distance, box):
        """The straight step ``x + distance direction``, wrapped into the box."""
        return self.project_normal(x + distance[..., None] * direction, box)

    def chord_length(self, length, box):
        return length

    def distance_to_surface(self, x, box):
        return array_module(x).abs(x[..., 2])

    def total_area_np(self, box):
        b = np.asarray(box, dtype=np.float64)
        return b[..., 0] * b[..., 1]

    def length_scale(self, box):
        xp = array_module(box)
        return xp.sqrt(box[..., 0] * box[..., 1])

    def unwrap(self, x, reference, box):
        out = x.copy()
        out[..., :2] = reference[..., :2] + minimum_image(x[..., :2] - reference[..., :2], box)
        out[..., 2] = x[..., 2]
        return out

    def triangle_area(self, a, b, c, box):
        """Half the z-component of ``(b - a) x (c - a)``, with ``b`` and ``c`` the images nearest ``a``."""
        u = minimum_image(b[..., :2] - a[..., :2], box)
        v = minimum_image(c[..., :2] - a[..., :2], box)
        return 0.5 * (u[..., 0] * v[..., 1] - u[..., 1] * v[..., 0])

    def outside_box(self, x, box):
        """Mask of the points not stored in ``[0, Lx) x [0, Ly)``."""
        return ((x[..., :2] < 0) | (x[..., :2] >= box)).any(axis=-1)

    def displacement(self, state, u, v):
        """Minimum-image in-plane vectors ``x[v] - x[u]``, (n, 2)."""
        pos = state.positions
        return minimum_image(pos[v, :2] - pos[u, :2], state.box[state.vertex_replica[u]])

    def edge_lengths(self, state, u, v):
        d = self.displacement(state, u, v)
        return array_module(d).sqrt((d * d).sum(axis=-1))

    # ------------------------------------------------------------------ cells
    # Corner (v, k) lies in cell vertex_cells[v, k], whose boundary runs counter-clockwise from v to
    # n_k = vertex_neighbors[v, k] (and arrives at v from n_{k+1}): it owns that cell's edge v -> n_k.
    @staticmethod
    def unwrapped_cells(state):
        """Each polygon unwrapped edge by edge from its first vertex: ``(first, valid, e, r)`` with
        ``first`` (C, 1) the first vertices, ``valid`` (C, W) the real slots of the padded table,
        ``e`` (C, W, 2) the minimum-image edges along the cell (zero in padding) and ``r`` (C, W, 2)
        vertex j about vertex 0 (``sum_{i<j} e_i``)."""
        xp = state.device.xp
        pos = state.positions[:, :2]
        cv, sides = state.cell_vertices, state.cell_sides
        col = xp.arange(cv.shape[1])[None, :]
        valid = col < sides[:, None]
        first = cv[:, :1]
        cur = xp.where(valid, cv, first)                                   # padding -> the first vertex
        nxt = xp.where(valid, xp.take_along_axis(cv, (col + 1) % sides[:, None], axis=1), first)
        e = minimum_image(pos[nxt] - pos[cur], state.box[state.cell_replica][:, None, :])   # (C, W, 2)
        return first, valid, e, xp.cumsum(e, axis=1) - e

    def cell_geometry(self, state) -> PlaneGeometry:
        """Areas (shoelace) and perimeters, each polygon unwrapped edge by edge from its first vertex:
        vertex j sits at ``sum_{i<j} e_i`` with ``e_i`` the minimum-image edges along the cell, so only
        edges, not whole cells, need to be shorter than half the box."""
        xp = state.device.xp
        pos = state.positions[:, :2]
        sides = state.cell_sides
        first, valid, e, r = self.unwrapped_cells(state)
        area = 0.5 * (r[..., 0] * e[..., 1] - r[..., 1] * e[..., 0]).sum(axis=1)
        perimeter = xp.sqrt((e * e).sum(axis=-1)).sum(axis=1)
        box_v = state.box[state.vertex_replica][:, None, :]
        edge = minimum_image(pos[state.vertex_neighbors] - pos[:, None, :], box_v)   # (V, 3, 2) per corner
        length = xp.sqrt((edge * edge).sum(axis=-1))

        def center():
            mean = xp.where(valid[..., None], r, 0.0).sum(axis=1) / sides[:, None].astype(xp.float64)
            out = xp.zeros((state.n_cells, 3))
            out[:, :2] = _wrap(xp, pos[first[:, 0]] + mean, state.box[state.cell_replica])
            return out

        return PlaneGeometry(area=area, perimeter=perimeter, edge=edge, length=length, center=center)

    def cell_centers(self, state):
        """Vertex centroid of each cell (unwrapped, then wrapped into the box), ``(n_cells, 3)``."""
        return self.cell_geometry(state).center

    def shape_gradient(self, state, geometry: PlaneGeometry, d_area, d_perimeter):
        """Gradient (V, 3), z = 0, of ``sum_c d_area[c] A_c + d_perimeter[c] P_c``.

        At vertex v, with edges ``e_k`` to its neighbours and cells ``C_k`` between ``e_k`` and
        ``e_{k+1}``: ``dA(C_k)/dx_v = rot(e_k - e_{k+1}) / 2`` with ``rot(x, y) = (y, -x)`` (the
        shoelace formula) and ``dP(C_k)/dx_v = -(e_k/|e_k| + e_{k+1}/|e_{k+1}|)``. Collected per
        edge: ``sum_k (a[C_k] - a[C_{k-1}]) rot(e_k) / 2 - (p[C_k] + p[C_{k-1}]) e_k / |e_k|``.
        """
        xp = state.device.xp
        vc = state.vertex_cells
        a, p = d_area[vc], d_perimeter[vc]                                  # (V, 3)
        a_before, p_before = xp.roll(a, 1, axis=1), xp.roll(p, 1, axis=1)
        e = geometry.edge
        alpha = 0.5 * (a - a_before)
        beta = (p + p_before) / xp.maximum(geometry.length, 1e-300)
        out = xp.zeros((state.n_vertices, 3))
        out[:, 0] = (alpha * e[..., 1] - beta * e[..., 0]).sum(axis=1)
        out[:, 1] = (-alpha * e[..., 0] - beta * e[..., 1]).sum(axis=1)
        return out

    def __repr__(self):
        return "PeriodicPlane()"
