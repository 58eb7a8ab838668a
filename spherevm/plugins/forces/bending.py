"""Bending between neighbouring cells: E_b = B sum over neighbouring pairs (i, j) of (1 - n_i . n_j).

The discrete bending energy of the paper's Discussion (eq. ``eq:bending``, after Seung and Nelson).
``n_i`` is the unit area vector of cell ``i`` (:func:`cell_normals`), the pairs are the cells that
share an edge of the trivalent network, each pair counted once.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from ...constraints import Sphere
from ...constraints.base import Constraint
from ...device import array_module, launch, load_module
from ..base import Force, ForceResult

_KERNELS = Path(__file__).with_suffix(".cu")


def _cross(a, b):
    """Cross products of component-major vectors: ``a``, ``b`` of shape (3, ...)."""
    xp = array_module(a, b)
    return xp.stack((a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]))


def _dot(a, b):
    return (a[0] * b[0] + a[1] * b[1]) + a[2] * b[2]


def _difference(state, xb, xa, index):
    """``xb - xa`` for component-major points (3, ...): through the surface's ``unwrap`` (minimum
    images on a periodic plane) where it has one; ``index`` gives each point's replica."""
    d = xb - xa
    constraint = state.constraint
    if type(constraint).unwrap is Constraint.unwrap:
        return d
    xp = state.device.xp
    size = constraint.size(state, index.reshape(-1)).reshape(index.shape + (-1,))
    b, a = xp.moveaxis(xb + 0 * xa, 0, -1), xp.moveaxis(xa + 0 * xb, 0, -1)
    return xp.moveaxis(constraint.unwrap(b, a, size) - a, -1, 0)


def _area_vectors(state, P, topo):
    """Component-major area vectors (3, n_cells) from component-major positions P (3, V)."""
    xp = state.device.xp
    nv = state.n_vertices
    apex = xp.take(P, topo["corner_apex"], axis=1).reshape(3, 3, nv)      # slot-major corners
    nxt = xp.take(P, topo["corner_next"], axis=1).reshape(3, 3, nv)
    rep = topo["corner_replica"]
    rv = _difference(state, P[:, None, :], apex, rep)
    rn = _difference(state, nxt, apex, rep)
    c = _cross(rv, rn).reshape(3, -1)
    cells = topo["corner_cell"]
    return 0.5 * xp.stack([xp.bincount(cells, weights=c[k], minlength=state.n_cells) for k in range(3)])


def _positions(state):
    return state.device.xp.ascontiguousarray(state.positions.T)


def cell_area_vectors(state):
    """The area vector of every cell, ``(n_cells, 3)`` on the state's device.

    ``a_c = 1/2 sum over the edges (x_a -> x_b) of cell c of x_a x x_b``, counter-clockwise seen from
    outside, so ``a_c`` points outwards. It is computed per corner with positions taken relative
    to the cell's first vertex (``x_a x x_b`` summed over a closed polygon does not depend on the
    origin), so small cells keep full relative accuracy, and through the surface's ``unwrap`` so
    that on a periodic plane the polygon is built from minimum images. For a flat polygon ``|a_c|``
    is its area; on the sphere it is the area of the polygon's projection on the plane normal to
    ``a_c`` (the vector area).
    """
    return _area_vectors(state, _positions(state), _topology(state)).T


def cell_normals(state):
    """The unit normal of every cell, ``(n_cells, 3)``: its normalised area vector
    (:func:`cell_area_vectors`), ``n_c = a_c / |a_c|``.

    The one definition of a cell's normal in spherevm (the bending energy uses it). On the sphere,
    for a regular polygon (vertices equally spaced on a circle of the sphere) it is exactly the
    radial direction at the polygon's centre; for any cell it is close to the normalised vertex
    centroid, the two differing at second order in the cell size over R for an irregular cell. On
    a periodic plane it is ``(0, 0, 1)`` for every (counter-clockwise) cell.
    """
    a = _area_vectors(state, _positions(state), _topology(state))
    return (a / state.device.xp.sqrt(_dot(a, a))).T


def neighbor_pairs(state):
    """The pairs of cells sharing at least one edge, each pair once: ``(n_pairs, 2)`` int64 with
    ``i < j``, on the state's device, sorted. Cached with the State per topology version."""
    return _topology(state)["pairs"]


def _build_topology(state):
    xp = state.device.xp
    vn = state.vertex_neighbors.astype(xp.int64)
    vc = state.vertex_cells.astype(xp.int64)
    n = state.n_cells
    # the edge v -> vn[v, k] borders cells vc[v, k] and vc[v, k - 1]
    a, b = vc.reshape(-1), xp.roll(vc, 1, axis=1).reshape(-1)
    lo, hi = xp.minimum(a, b), xp.maximum(a, b)
    keep = lo != hi
    keys = xp.unique(lo[keep] * n + hi[keep])
    pairs = xp.stack((keys // n, keys % n), axis=1)
    # per cell, its neighbours (CSR, both directions), for the GPU's per-cell kernel
    both_i = xp.concatenate((pairs[:, 0], pairs[:, 1]))
    both_j = xp.concatenate((pairs[:, 1], pairs[:, 0]))
    order = xp.argsort(both_i * n + both_j)
    start = xp.zeros(n + 1, dtype=xp.int64)
    start[1:] = xp.cumsum(xp.bincount(both_i, minlength=n))
    corner_cell = xp.ascontiguousarray(vc.T).reshape(-1)                  # slot-major corners
    return dict(pairs=pairs, pair_replica=state.cell_replica[pairs[:, 0]],
                start=start.astype(xp.int32), neighbors=both_j[order].astype(xp.int32),
                both_i=both_i[order], both_j=both_j[order], corner_cell=corner_cell,
                corner_next=xp.ascontiguousarray(vn.T).reshape(-1),
                corner_apex=state.cell_vertices[:, 0].astype(xp.int64)[corner_cell],
                corner_replica=xp.tile(state.vertex_replica, 3).reshape(3, -1))


def _topology(state):
    return state.cached((Bending, "topology"), lambda: _build_topology(state), topology=True)


class Bending(Force):
    """``E_b = B sum over neighbouring cell pairs (i, j) of (1 - n_i . n_j)``, each pair once.

    ``n_i`` is the unit area vector of cell ``i`` (:func:`cell_normals`); two cells are neighbours
    when they share an edge. ``B`` is an energy (in the dimensionless model, in units of
    ``kP <A>``): a scalar, or one value per replica (length ``n_replicas``), finite and ``>= 0``.

    ``1 - n_i . n_j`` is evaluated as ``|n_i - n_j|^2 / 2`` (no cancellation for nearly parallel
    normals). Forces are minus the gradient with respect to the vertex positions, projected on the
    tangent plane of the surface. ``cell_energy`` gives each cell half of each of its pairs. On the
    sphere, for small cells, ``1 - n_i . n_j ~ r_ij^2 / 2R^2`` with ``r_ij`` the geodesic distance
    between the cells' centres. On a periodic plane every normal is ``(0, 0, 1)``: energy and forces
    are zero.
    """

    narrowable = True
    gpu_surfaces = (Sphere,)
    surface_needs = ("project_tangent",)

    def __init__(self, B=0.0, trigger=None):
        super().__init__(trigger)
        arr = np.asarray(B, dtype=np.float64) if not isinstance(B, str) else None
        if arr is None or arr.ndim > 1:
            raise ValueError(f"Bending: B must be a scalar or a per-replica 1-D array of numbers, got {B!r}")
        if arr.size == 0 or not np.all(np.isfinite(arr)) or np.any(arr < 0):
            raise ValueError(f"Bending: B must be finite and >= 0, got {B!r}")
        self.B = arr

    def per_replica_B(self, state):
        """``B`` for each replica, NumPy ``(n_replicas,)``; raises ValueError for a wrong length."""
        if self.B.ndim == 1 and len(self.B) != state.n_replicas:
            raise ValueError(f"Bending: per-replica B has length {len(self.B)}, but the state has "
                             f"{state.n_replicas} replicas")
        return np.broadcast_to(self.B, (state.n_replicas,)).copy()

    def narrow(self, selection):
        """A per-replica B follows the selected replicas."""
        saved = self.B
        if self.B.ndim == 1:
            self.B = self.B[np.asarray(selection.replicas)]
        return saved

    def widen(self, selection, saved):
        self.B = saved

    def _device_B(self, state):
        key = (self, "B", self.B.tobytes(), self.B.shape)
        return state.cached(key, lambda: state.device.asarray(self.per_replica_B(state)))

    def attach(self, simulation):
        super().attach(simulation)
        self.per_replica_B(simulation.state)                 # a wrong length is refused now
        self.implementation("compute", simulation.state)     # and an unsupported surface

    def compute(self, state) -> ForceResult:
        return self.implementation("compute", state)(state)

    def _compute_cpu(self, state) -> ForceResult:
        xp = state.device.xp
        B = self._device_B(state)
        topo = _topology(state)
        nc, nv = state.n_cells, state.n_vertices
        P = _positions(state)
        a = _area_vectors(state, P, topo)                                # (3, C)
        norm = xp.sqrt(_dot(a, a))
        n = a / norm
        # every pair from both ends (CSR order): d = n_i - n_j
        i, j = topo["both_i"], topo["both_j"]
        d = xp.take(n, i, axis=1) - xp.take(n, j, axis=1)
        Bc = B[state.cell_replica]
        # E = B sum_pairs |n_i - n_j|^2 / 2; each cell takes half of each of its pairs
        cell_energy = 0.25 * Bc * xp.bincount(i, weights=_dot(d, d), minlength=nc)
        energy = xp.bincount(state.cell_replica, weights=cell_energy, minlength=state.n_replicas)
        # dE/dn_i = B sum_j (n_i - n_j); through n = a/|a|: g_i = (I - n n^T) dE/dn_i / |a_i|
        sm = xp.stack([xp.bincount(i, weights=d[k], minlength=nc) for k in range(3)])
        g = (Bc / norm) * (sm - _dot(sm, n) * n)
        # a_c depends on its vertex v through (x_next - x_prev) x g_c / 2 per corner:
        # in cell vc[v, k] the next vertex is vn[v, k], the previous vn[v, k + 1]
        nxt = xp.take(P, topo["corner_next"], axis=1).reshape(3, 3, nv)
        rel = _difference(state, nxt, P[:, None, :], topo["corner_replica"])
        chord = rel - xp.roll(rel, -1, axis=1)
        gc = xp.take(g, topo["corner_cell"], axis=1).reshape(3, 3, nv)
        grad = 0.5 * _cross(chord, gc).sum(axis=1)                      # (3, V)
        forces = -state.constraint.project_tangent(state.positions, xp.ascontiguousarray(grad.T))
        return ForceResult(forces=forces, energy=energy, cell_energy=cell_energy)

    def _compute_gpu(self, state) -> ForceResult:
        """Three kernels (bending.cu): area vectors and normals per cell; energy and dE/da per cell
        over its neighbours; forces per vertex over its three corners."""
        import cupy as cp
        B = self._device_B(state)
        topo = _topology(state)
        module = load_module(_KERNELS)
        nc, nv = state.n_cells, state.n_vertices
        normal, inv_area = cp.empty((nc, 3)), cp.empty(nc)
        launch(module.get_function("bending_cell_normals"), nc,
               (state.positions, state.cell_vertices, state.cell_sides, np.int32(nc), np.int32(state.max_sides),
                normal, inv_area))
        g, cell_energy = cp.empty((nc, 3)), cp.empty(nc)
        energy = cp.zeros(state.n_replicas)
        launch(module.get_function("bending_cell_terms"), nc,
               (normal, inv_area, topo["start"], topo["neighbors"], state.cell_replica, B, np.int32(nc),
                g, cell_energy, energy))
        forces = cp.empty_like(state.positions)
        launch(module.get_function("bending_vertex_forces"), nv,
               (state.positions, state.vertex_neighbors, state.vertex_cells, np.int32(nv), g, forces))
        return ForceResult(forces=forces, energy=energy, cell_energy=cell_energy)

    @property
    def loggables(self):
        return {"bending_energy": lambda sim: self.energy(sim.state)}

    def __repr__(self):
        B = float(self.B) if self.B.ndim == 0 else self.B.tolist()
        return f"Bending(B={B})"
