"""The flat periodic box: a rectangle ``[0, Lx) x [0, Ly)`` at z = 0 per replica, with minimum images."""
from __future__ import annotations

import numpy as np

from ..device import array_module
from .base import CellMeasures, Constraint, DeviceSurface


def _wrap(xp, x, box):
    """``x`` (..., 2) into ``[0, L)`` per component (``box`` broadcasts against it)."""
    w = x - box * xp.floor(x / box)
    return xp.where(w >= box, w - box, w)      # x just below 0 can round up to L


def minimum_image(d, box):
    """The periodic image of the in-plane displacement ``d`` (..., 2) with components in ``[-L/2, L/2]``."""
    xp = array_module(d)
    return d - box * xp.rint(d / box)


#: Relative size of a cell's closing sum (the sum of its minimum-image edges) that counts as open.
OPEN_TOLERANCE = 1e-9


class PlaneGeometry(CellMeasures):
    """Per-cell area and perimeter, and the per-corner edge vectors that the gradient reuses.

    ``edge`` (2 components, 3 slots, V) is the minimum image of ``x[vertex_neighbors[v, k]] - x[v]``,
    ``length`` (3, V) its length (component- and slot-major: every NumPy call runs on contiguous rows). ``center`` (the vertex centroid of each cell, unwrapped about the cell's first vertex
    and wrapped back into the box, ``(n_cells, 3)``) is computed on first use."""

    def __init__(self, area, perimeter, edge, length, center):
        self.area, self.perimeter, self.edge, self.length = area, perimeter, edge, length
        self._center = center

    @property
    def area_vector(self):
        """``(0, 0, A_c)`` per cell, ``(n_cells, 3)``: the vector area of a polygon in the plane."""
        xp = array_module(self.area)
        out = xp.zeros((len(self.area), 3))
        out[:, 2] = self.area
        return out

#: the periodic plane's device code (geometry/surface.cuh's functions on minimum images)
DEVICE_SURFACE = DeviceSurface('#include "constraints/plane.cuh"', "PlaneSurface")


class PeriodicPlane(Constraint):
    """A flat rectangular periodic box per replica (``State.size``, ``(n_replicas, 2)`` = (Lx, Ly)).

    Positions are stored wrapped into ``[0, Lx) x [0, Ly)`` with z = 0. Edges are minimum images, so
    a cell may straddle the boundary; perimeters are sums of Euclidean edge lengths and areas the
    shoelace formula on each polygon unwrapped edge by edge from its first vertex. Normal ``(0, 0, 1)``; P_T
    drops z, P_N sets z = 0 and wraps. The network on a periodic plane is a torus: V - E + F = 0,
    and the cells tile the box (total area Lx Ly). Edges must be shorter than half the box.
    """

    name = "periodic_plane"
    size_shape = (2,)
    size_names = ("Lx", "Ly")
    drawing = "box"
    rigid_motions = ("translations",)
    euler_characteristic = 0

    # ------------------------------------------------------------------ pointwise
    def normal(self, x, size=None):
        xp = array_module(x)
        n = xp.zeros_like(x)
        n[..., 2] = 1.0
        return n

    def project_tangent(self, x, v, size=None):
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

    def device_surface(self):
        """PlaneSurface (constraints/plane.cuh): minimum images in each replica's box."""
        return DEVICE_SURFACE

    def chord_length(self, length, box):
        return length

    def distance_to_surface(self, x, box):
        return array_module(x).abs(x[..., 2])

    def total_area_np(self, box):
        b = np.asarray(box, dtype=np.float64)
        return b[..., 0] * b[..., 1]

    def draw_points(self, points, box):
        """The points as they are: unwrapped about their cell, in the plane."""
        return points

    def replica_spacing(self, box, cell_width) -> float:
        """1.1 of the widest box plus twice the widest cell: cells unwrapped across the box edge
        reach out of it by up to a cell."""
        return 1.1 * np.asarray(box)[:, 0].max() + 2 * cell_width

    def hoomd_box(self, box):
        """The largest replica's box in HOOMD's 2D convention (Lz = 0, centred on the origin)."""
        lx, ly = np.asarray(box).max(axis=0)
        return 2, np.array([lx, ly, 0.0, 0.0, 0.0, 0.0])

    def particle_origin(self, box):
        """Half the largest box: HOOMD's box is centred on the origin, the State's starts there."""
        lx, ly = np.asarray(box).max(axis=0)
        return np.array([lx / 2, ly / 2, 0.0])

    def length_scale(self, box):
        xp = array_module(box)
        return xp.sqrt(box[..., 0] * box[..., 1])

    def unwrap(self, x, reference, box):
        out = x.copy()
        out[..., :2] = reference[..., :2] + minimum_image(x[..., :2] - reference[..., :2], box)
        out[..., 2] = x[..., 2]
        return out

    def unwrap_path(self, centroids, box):
        """Frame 0 as stored, then the cumulative sum of the minimum images of the frame-to-frame
        displacements (``box`` per point, ``(n, 2)``)."""
        out = np.array(centroids, dtype=np.float64, copy=True)
        if len(out) > 1:
            step = minimum_image(np.diff(out[..., :2], axis=0), box)
            out[1:, :, :2] = out[0, :, :2] + np.cumsum(step, axis=0)
        return out

    def geodesic_distance(self, a, b, box):
        """The straight distance ``|b - a|`` (of unwrapped points)."""
        return np.linalg.norm(b - a, axis=-1)

    def triangle_area(self, a, b, c, box):
        """Half the z-component of ``(b - a) x (c - a)``, with ``b`` and ``c`` the images nearest ``a``."""
        u = minimum_image(b[..., :2] - a[..., :2], box)
        v = minimum_image(c[..., :2] - a[..., :2], box)
        return 0.5 * (u[..., 0] * v[..., 1] - u[..., 1] * v[..., 0])

    def orientation_points(self, x, reference=None, size=None):
        """``(x, y, 1)``: ``(a x b) . c`` is twice the signed area of the triangle a, b, c."""
        p = x if reference is None else self.unwrap(x, reference, size)
        out = np.ones(p.shape[:-1] + (3,))
        out[..., :2] = p[..., :2]
        return out

    def edge_points(self, state, sides):
        """Each polygon unwrapped from its first vertex along its minimum-image edges."""
        _, valid, e, r = self.unwrapped_cells(state)
        valid, e, r = (state.device.to_numpy(a) for a in (valid, e, r))
        return self.orientation_points(r[valid]), self.orientation_points(r[valid] + e[valid])

    def open_cells(self, state):
        """Cells whose minimum-image edges do not add up to zero: an edge of theirs reached half the
        box, and its minimum image jumped to another image. For each the slot of its edge longest
        along the box (relative to the box side), the one that jumped."""
        _, valid, e, _ = self.unwrapped_cells(state)
        e = state.device.to_numpy(e)
        box = self.size_np(state)[state.cell_replica_np()]                          # (C, 2)
        closing = np.abs(e.sum(axis=1)) / box                                         # (C, 2)
        bad = np.flatnonzero((closing > OPEN_TOLERANCE).any(axis=1))
        reach = (np.abs(e[bad]) / box[bad, None, :]).max(axis=2)                     # (bad, W)
        return bad, np.argmax(reach, axis=1)

    def cover_error(self, state, areas, replica, total, surface) -> str:
        return (f"the cells cover an area {total:.12g}, but the box's is {surface:.12g}; some cell wraps around "
                "the box or overlaps another")

    def gaussian_curvature(self, x, box=None):
        """0."""
        return np.zeros(np.shape(x)[:-1])

    def polygon_area(self, points, box) -> float:
        """The shoelace area of the unwrapped polygon (x, y)."""
        x, y = points[:, 0], points[:, 1]
        return 0.5 * float((x * np.roll(y, -1) - np.roll(x, -1) * y).sum())

    def outside_box(self, x, box):
        """Mask of the points not stored in ``[0, Lx) x [0, Ly)``."""
        return ((x[..., :2] < 0) | (x[..., :2] >= box)).any(axis=-1)

    def displacement(self, state, u, v):
        """Minimum-image in-plane vectors ``x[v] - x[u]``, (n, 2)."""
        pos = state.positions
        return minimum_image(pos[v, :2] - pos[u, :2], state.size[state.vertex_replica[u]])

    def edge_lengths(self, state, u, v):
        d = self.displacement(state, u, v)
        return array_module(d).sqrt((d * d).sum(axis=-1))

    # ------------------------------------------------------------------ cells
    # Corner (v, k) lies in cell vertex_cells[v, k], whose boundary runs counter-clockwise from v to
    # n_k = vertex_neighbors[v, k] (and arrives at v from n_{k+1}): it owns that cell's edge v -> n_k.
    @staticmethod
    def _tables(state):
        """Per State and topology, a dict: ``box`` the boxes as ``(2, 1, 1)`` when all replicas share
        one (a cheaper broadcast, the same numbers) or per vertex ``(2, 1, V)``; ``neighbors``,
        ``cells`` and ``cells_before`` (the cell before slot k, ``vertex_cells[v, k - 1]``) slot-major
        ``(3, V)``; ``slot`` ``(W, C)``: for slot j of cell c the corner ``k V + v`` (slot-major) owning
        the edge from vertex j to vertex j + 1, ``3 V`` (a zero edge) in padding; ``valid`` ``(C, W)``
        the real slots; ``first`` ``(C, 1)`` the cells' first vertices. Rebuilt when ``state.size`` is
        replaced (after editing it in place, call ``state.clear_cache()``)."""
        def build():
            xp = state.device.xp
            cv, sides, vc, nv = state.cell_vertices, state.cell_sides, state.vertex_cells, state.n_vertices
            valid = xp.arange(cv.shape[1])[None, :] < sides[:, None]
            v = xp.where(valid, cv, 0)
            k = xp.argmax(vc[v] == xp.arange(state.n_cells)[:, None, None], axis=2)
            one = bool((state.size == state.size[:1]).all())
            box = state.size[0][:, None, None] if one else state.size[state.vertex_replica].T[:, None, :]
            cells = xp.ascontiguousarray(vc.T)
            return dict(box=xp.ascontiguousarray(box), neighbors=xp.ascontiguousarray(state.vertex_neighbors.T),
                        cells=cells, cells_before=cells[[2, 0, 1]],
                        slot=xp.ascontiguousarray(xp.where(valid, k * nv + v, 3 * nv).T), valid=valid,
                        first=cv[:, :1], source=state.size)
        tables = state.cached(("plane", "tables"), build, topology=True)
        if tables["source"] is not state.size:
            state.clear_cache()
            tables = state.cached(("plane", "tables"), build, topology=True)
        return tables

    def corner_edges(self, state):
        """The minimum image of ``x[vertex_neighbors[v, k]] - x[v]`` per corner, ``(2, 3, V)``."""
        xp = state.device.xp
        t = self._tables(state)
        pos, vn = state.positions, t["neighbors"]
        d = xp.empty((2,) + vn.shape)
        for axis in (0, 1):
            x = pos[:, axis]
            xp.subtract(x[vn], x, out=d[axis])
        return d - t["box"] * xp.rint(d / t["box"])

    def _slot_edges(self, state, edge):
        """The cells' edges and unwrapped vertices ``(2, W, C)``: ``e[:, j, c]`` the edge from vertex j
        to j + 1 of cell c (zero in padding), read from the corner edges ``edge``, and
        ``r[:, j, c] = sum_{i<j} e[:, i, c]``, formed as the running sum minus ``e[:, j]`` (one
        vectorised step per slot, in the slot order the CUDA kernel sums in)."""
        xp = state.device.xp
        flat = xp.concatenate([edge.reshape(2, -1), xp.zeros((2, 1))], axis=1)
        e = xp.take(flat, self._tables(state)["slot"], axis=1)
        running = e.copy()
        for j in range(1, e.shape[1]):
            xp.add(running[:, j - 1], e[:, j], out=running[:, j])
        return e, running - e

    def unwrapped_cells(self, state, edge=None):
        """Each polygon unwrapped edge by edge from its first vertex: ``(first, valid, e, r)`` with
        ``first`` (C, 1) the first vertices, ``valid`` (C, W) the real slots of the padded table,
        ``e`` (C, W, 2) the minimum-image edges along the cell (zero in padding; from the corner
        edges ``edge``, computed if not given) and ``r`` (C, W, 2) vertex j about vertex 0
        (``sum_{i<j} e_i``). ``e`` and ``r`` are views of component- and slot-major arrays."""
        t = self._tables(state)
        e, r = self._slot_edges(state, self.corner_edges(state) if edge is None else edge)
        return t["first"], t["valid"], e.transpose(2, 1, 0), r.transpose(2, 1, 0)

    def cell_geometry(self, state, area_vectors: bool = False, metric: bool = True) -> PlaneGeometry:
        """Areas (shoelace) and perimeters, each polygon unwrapped edge by edge from its first vertex:
        vertex j sits at ``sum_{i<j} e_i`` with ``e_i`` the minimum-image edges along the cell, so only
        edges, not whole cells, need to be shorter than half the box. Every edge's minimum image is
        taken once, per corner, and read by the cells' slots; sums run in slot order (as in
        geometry/plane.cuh). Area vectors (``(0, 0, A_c)``) come with the areas: the two flags of
        :meth:`Sphere.cell_geometry` change nothing here."""
        xp = state.device.xp
        t = self._tables(state)
        edge = self.corner_edges(state)                                     # (2, 3, V)
        e, r = self._slot_edges(state, edge)                                # (2, W, C)
        area = 0.5 * (r[0] * e[1] - r[1] * e[0]).sum(axis=0)
        length = xp.sqrt(edge[0] * edge[0] + edge[1] * edge[1])
        perimeter = xp.concatenate([length.reshape(-1), xp.zeros(1)])[t["slot"]].sum(axis=0)

        def center():       # the expression of cell_centroids(method="vertex"), bit for bit
            mean = (xp.where(t["valid"][..., None], r.transpose(2, 1, 0), 0.0).sum(axis=1)
                    / state.cell_sides[:, None].astype(xp.float64))
            out = xp.zeros((state.n_cells, 3))
            out[:, :2] = _wrap(xp, state.positions[t["first"][:, 0], :2] + mean, state.size[state.cell_replica])
            return out

        return PlaneGeometry(area=area, perimeter=perimeter, edge=edge, length=length, center=center)

    def cell_centers(self, state):
        """Vertex centroid of each cell (unwrapped, then wrapped into the box), ``(n_cells, 3)``."""
        return self.cell_geometry(state).center

    def cell_centroids(self, state, method: str):
        """Each polygon unwrapped edge by edge from its first vertex (vertex j at ``sum_{i<j} e_i``,
        ``e_i`` the minimum-image edges, as for its area), so a cell straddling the boundary is whole.
        ``method="area"``: the centroid of the polygon's area, ``sum_i (r_i + r_{i+1}) (r_i x r_{i+1}) / 6A``;
        a cell of non-positive area falls back to the vertex centroid. ``"vertex"``: the mean of the
        unwrapped vertices. The point is then wrapped back into ``[0, Lx) x [0, Ly)``, z = 0."""
        xp = state.device.xp
        pos, sides = state.positions[:, :2], state.cell_sides
        box = state.size[state.cell_replica]
        first, valid, e, r = self.unwrapped_cells(state)
        mean = xp.where(valid[..., None], r, 0.0).sum(axis=1) / sides[:, None].astype(xp.float64)
        centre = mean
        if method == "area":
            r1 = r + e                                                      # vertex j + 1
            cross = r[..., 0] * r1[..., 1] - r[..., 1] * r1[..., 0]         # padding rows do not count
            cross = xp.where(valid, cross, 0.0)
            area = 0.5 * cross.sum(axis=1)
            ok = area > 0
            c = ((r + r1) * cross[..., None]).sum(axis=1) / (6.0 * xp.where(ok, area, 1.0))[:, None]
            centre = xp.where(ok[:, None], c, mean)
        out = xp.zeros((state.n_cells, 3))
        out[:, :2] = _wrap(xp, pos[first[:, 0]] + centre, box)
        return out

    def cell_normals(self, state):
        """``(0, 0, 1)`` for every cell."""
        return self.normal(state.device.xp.zeros((state.n_cells, 3)))

    def shape_gradient(self, state, geometry: PlaneGeometry, d_area, d_perimeter, d_area_vector=None):
        """Gradient (V, 3), z = 0, of ``sum_c d_area[c] A_c + d_perimeter[c] P_c + d_area_vector[c] . a_c``.

        The area vector is ``(0, 0, A_c)``: its term adds the z component of ``d_area_vector`` to
        ``d_area`` (either of ``d_area``, ``d_perimeter`` may be None when the energy lacks it).

        At vertex v, with edges ``e_k`` to its neighbours and cells ``C_k`` between ``e_k`` and
        ``e_{k+1}``: ``dA(C_k)/dx_v = rot(e_k - e_{k+1}) / 2`` with ``rot(x, y) = (y, -x)`` (the
        shoelace formula) and ``dP(C_k)/dx_v = -(e_k/|e_k| + e_{k+1}/|e_{k+1}|)``. Collected per
        edge: ``sum_k (a[C_k] - a[C_{k-1}]) rot(e_k) / 2 - (p[C_k] + p[C_{k-1}]) e_k / |e_k|``.
        """
        xp = state.device.xp
        t = self._tables(state)
        zero = xp.zeros(state.n_cells)
        d_area = zero if d_area is None else d_area
        d_area = d_area if d_area_vector is None else d_area + d_area_vector[:, 2]
        d_perimeter = zero if d_perimeter is None else d_perimeter
        a, a_before = d_area[t["cells"]], d_area[t["cells_before"]]        # (3, V)
        p, p_before = d_perimeter[t["cells"]], d_perimeter[t["cells_before"]]
        ex, ey = geometry.edge
        alpha = 0.5 * (a - a_before)
        beta = (p + p_before) / xp.maximum(geometry.length, 1e-300)
        gx = alpha * ey - beta * ex
        gy = -alpha * ex - beta * ey
        out = xp.zeros((state.n_vertices, 3))
        out[:, 0] = gx[0] + gx[1] + gx[2]
        out[:, 1] = gy[0] + gy[1] + gy[2]
        return out

    def __repr__(self):
        return "PeriodicPlane()"
