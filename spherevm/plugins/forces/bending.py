"""Bending between neighbouring cells: E_b = B sum over neighbouring pairs (i, j) of (1 - n_i . n_j).

The discrete bending energy of the paper's Discussion (eq. ``eq:bending``, after Seung and Nelson).
``n_i`` is the unit area vector of cell ``i`` (:func:`cell_normals`), the pairs are the cells that
share an edge of the trivalent network, each pair counted once.

The energy is a function of the cells' area vectors, which the surface measures
(``constraint.cell_geometry(state, area_vectors=True)``) and differentiates
(``constraint.shape_gradient(..., d_area_vector=...)``) as it does areas and perimeters: with the
vertex model attached as well, one pass over the corners serves both (:meth:`Bending.combined`).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from ...constraints.kernels import BENDING_SURFACES, FUSED_BENDING_SURFACES, surface_kernels
from ...constraints.cell_rows import cell_blocks, fold, row_table
from ...constraints.corners import in_parallel
from ...device import array_module, launch, segment_sums, weighted_bincount
from ...kernel_struct import KernelStruct
from ..base import Force, ForceResult
from ..fusion import FusedStage, overrides
from ..parameters import Parameter
from .vertex_model import VertexModel

_KERNELS = Path(__file__).with_suffix(".cu")


def _dot(a, b):
    """Dot products of component-major vectors (3, n): one fused pass."""
    return array_module(a, b).einsum("ij,ij->j", a, b)


def cell_area_vectors(state):
    """The area vector of every cell, ``(n_cells, 3)`` on the state's device, as the surface
    measures it (``constraint.cell_geometry(state, area_vectors=True)``).

    ``a_c = 1/2 sum over the edges (x_a -> x_b) of cell c of x_a x x_b``, counter-clockwise seen from
    outside, so ``a_c`` points outwards. On the sphere the vertices are taken on the sphere
    (``R x/|x|``, as for the vertex model's areas and perimeters), per corner relative to the cell's
    first vertex (the sum does not depend on the origin for a closed polygon), so small cells keep
    full relative accuracy; ``|a_c|`` is the area of the polygon's projection on the plane normal to
    ``a_c`` (the vector area). On a periodic plane it is ``(0, 0, A_c)``.
    """
    return state.constraint.cell_geometry(state, area_vectors=True, metric=False).area_vector


def cell_normals(state):
    """The unit normal of every cell: its normalised area vector (:func:`cell_area_vectors`),
    ``n_c = a_c / |a_c|``, the one definition of a cell's normal in spherevm.

    On the sphere, for a regular polygon it is exactly the radial direction at the polygon's
    centre; for any cell it is close to the normalised vertex centroid (they differ at second
    order in the cell size over R). On a periodic plane it is ``(0, 0, 1)``.

    Parameters
    ----------
    state : State

    Returns
    -------
    array (n_cells, 3)
        On the State's device."""
    a = cell_area_vectors(state).T
    return (a / state.device.xp.sqrt(_dot(a, a))).T


def neighbor_pairs(state):
    """The pairs of cells sharing at least one edge, each pair once: ``(n_pairs, 2)`` int64 with
    ``i < j``, on the state's device, sorted. Cached with the State per topology version."""
    return _topology(state)["pairs"]


def _build_topology(state):
    xp = state.device.xp
    vc = state.vertex_cells.astype(xp.int64)
    n = state.n_cells
    # the edge v -> vn[v, k] borders cells vc[v, k] and vc[v, k - 1]
    a, b = vc.reshape(-1), xp.roll(vc, 1, axis=1).reshape(-1)
    lo, hi = xp.minimum(a, b), xp.maximum(a, b)
    keep = lo != hi
    keys = xp.unique(lo[keep] * n + hi[keep])
    pairs = xp.stack((keys // n, keys % n), axis=1)
    if state.device.is_gpu:
        return dict(pairs=pairs)
    # the NumPy path's pass over the pairs: per block of cells, each cell's neighbours as a table
    # (head the cell itself), each pair seen from both of its cells
    ends = np.concatenate((pairs, pairs[:, ::-1]))
    ends = ends[np.argsort(ends[:, 0], kind="stable")]
    count = np.bincount(ends[:, 0], minlength=n)
    start = np.concatenate(([0], np.cumsum(count)))
    rows = [dict(row_table(count[c0:c1], ends[start[c0]:start[c1], 1], np.arange(c0, c1)), c0=c0, c1=c1)
            for c0, c1 in cell_blocks(state)]
    return dict(pairs=pairs, rows=rows)


def _topology(state):
    return state.cached((Bending, "topology"), lambda: _build_topology(state), topology=True)


def _cell_terms(state, B_cell, area_vector):
    """Per cell, from the area vectors ``(n_cells, 3)``: the energy (half of each of its pairs) and
    ``dE/da_c`` ``(3, n_cells)``, over the neighbour pairs, in blocks of cells on all cores.

    With ``d = n_i - n_j``, ``E = B sum_pairs |d|^2 / 2``, each pair once; ``dE/dn_i = B s_i`` with
    ``s_i = sum_j (n_i - n_j)``, and through ``n = a/|a|``, ``dE/da_i = B (I - n n^T) s_i / |a_i|``.
    Each cell sums over its own row of neighbours (:mod:`spherevm.constraints.cell_rows`), so a
    pair's ``d`` is worked out by both its cells (``n_j - n_i`` is exactly ``-(n_i - n_j)``).
    """
    a = area_vector.T
    norm = np.sqrt(np.einsum("ij,ij->j", a, a))
    n = a / norm
    energy, d_area_vector = np.empty(state.n_cells), np.empty((3, state.n_cells))

    def cells(rows):
        c0, c1 = rows["c0"], rows["c1"]
        ends = n.take(rows["table"], axis=1, mode="clip")        # (3, 1 + width, rows): n_i, then its n_j
        d = np.subtract(ends[:, :1], ends[:, 1:], out=ends[:, 1:])
        sums = np.empty((4, d.shape[2]))
        d.sum(axis=1, out=sums[:3])
        np.einsum("ijk,ijk->k", d, d, out=sums[3])
        s, own, B = fold(sums, rows), n[:, c0:c1], B_cell[c0:c1]
        np.multiply(0.25 * B, s[3], out=energy[c0:c1])
        s = s[:3]
        s -= np.einsum("ij,ij->j", s, own) * own
        np.multiply(B / norm[c0:c1], s, out=d_area_vector[:, c0:c1])

    in_parallel(cells, _topology(state)["rows"])
    return energy, d_area_vector


def _bending_stiffness(name, value):
    arr = np.asarray(value, dtype=np.float64) if not isinstance(value, str) else None
    if arr is None or arr.ndim > 1:
        raise ValueError(f"Bending: B must be a scalar or a per-replica 1-D array of numbers, got {value!r}")
    if arr.size == 0 or not np.all(np.isfinite(arr)) or np.any(arr < 0):
        raise ValueError(f"Bending: B must be finite and >= 0, got {value!r}")
    return arr


def _facets(state) -> bool:
    """Whether ``state``'s surface measures cells with flat facets on the device (per-cell vertex-model
    coefficients (dE/dA a / A, dE/dP): DeviceSurface.coef_width 4)."""
    return state.constraint.device_surface().coef_width == 4


class Bending(Force):
    """``E_b = B sum over neighbouring cell pairs (i, j) of (1 - n_i . n_j)``, each pair once.

    ``n_i`` is the unit area vector of cell ``i`` (:func:`cell_normals`); two cells are neighbours
    when they share an edge. ``1 - n_i . n_j`` is evaluated as ``|n_i - n_j|^2 / 2`` (no
    cancellation for nearly parallel normals). Forces are minus the surface gradient, tangent to the
    surface; ``cell_energy`` gives each cell half of each of its pairs. On the sphere, for small
    cells, ``1 - n_i . n_j ~ r_ij^2 / 2R^2`` with ``r_ij`` the geodesic distance between the cells'
    centres. On a periodic plane every normal is ``(0, 0, 1)``: energy and forces are zero.
    See docs/bending.md.

    Parameters
    ----------
    B : float or array (n_replicas,)
        An energy (in the dimensionless model, in units of ``kP <A>``), finite and >= 0.
    trigger : optional
        Not used (forces are evaluated whenever the integrator needs them)."""

    narrowable = True
    gpu_surfaces = BENDING_SURFACES
    surface_needs = ("cell_geometry", "shape_gradient")

    B = Parameter(_bending_stiffness)

    def __init__(self, B=0.0, trigger=None):
        super().__init__(trigger)
        self.B = B

    def check_parameters(self):
        """A per-replica B must have one value per replica of the attached State."""
        if self._simulation is not None:
            self.per_replica_B(self._simulation.state)

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
        """``B`` per replica and per cell on the state's device, cached for the State."""
        def build():
            B = state.device.asarray(self.per_replica_B(state))
            return B, B[state.cell_replica]
        return state.cached((self, "B"), build)

    def attach(self, simulation):
        super().attach(simulation)
        self.per_replica_B(simulation.state)                 # a wrong length is refused now
        self.implementation("compute", simulation.state)     # and an unsupported surface

    def compute(self, state) -> ForceResult:
        return self.implementation("compute", state)(state)

    def capture_ready(self, simulation, steps):
        """Its kernels (alone or fused) read nothing back and take nothing that changes from step to
        step; the neighbours are walked from the State's arrays, so T1 flips need no rebuild: CUDA
        graphs may hold them."""
        return ()

    def combined(self, other, state):
        """With a :class:`VertexModel`: both forces from one pass over the corners (NumPy: one
        ``cell_geometry`` with area vectors, one ``shape_gradient`` of both forces' terms; CUDA: the
        vertex model's kernels with the bending terms fused in, bending.cu). None for other forces,
        subclasses of VertexModel included (they may compute something else)."""
        if type(other) is not VertexModel:
            return None
        return self.implementation("combined", state)(other, state)

    #: the fused stage's arguments (bending_stage.cuh): B per cell on the device
    FUSED_ARGS = KernelStruct("BendingArgs", [("B", "const double*")])

    def fused_stage(self, simulation, minimizing):
        """bending_stage.cuh, alone: each cell's normal, each cell's term over its neighbours (the
        stage's second per-cell part) and each vertex's force, bending.cuh's functions as
        bending.cu's kernels call them. None off the sphere, or for a subclass that computes
        something else."""
        return self._stage(simulation, extra=False)

    def fused_combined(self, other, simulation, minimizing):
        """With a :class:`VertexModel` (where :meth:`combined` pairs them): the same stage as an extra
        of the vertex model's, its gradient added inside the vertex model's vertex force, as
        vm_bending_vertex_forces adds it."""
        return self._stage(simulation, extra=True) if type(other) is VertexModel else None

    def _stage(self, simulation, extra):
        if not isinstance(simulation.state.constraint, FUSED_BENDING_SURFACES) or \
                overrides(self, Bending, ("compute", "_compute_gpu", "combined", "_combined_gpu")):
            return None
        return FusedStage("force", "BendingStage", '#include "plugins/forces/bending_stage.cuh"', self.FUSED_ARGS,
                          dict(B=self._device_B(simulation.state)[1]), cell_doubles=4, measures=True,
                          neighbour_doubles=3, extra=extra)

    def _compute_cpu(self, state) -> ForceResult:
        geometry = state.constraint.cell_geometry(state, area_vectors=True, metric=False)
        cell_energy, d_area_vector = _cell_terms(state, self._device_B(state)[1], geometry.area_vector)
        energy = weighted_bincount(state.cell_replica, weights=cell_energy, minlength=state.n_replicas)
        forces = -state.constraint.shape_gradient(state, geometry, None, None, d_area_vector.T)
        return ForceResult(forces=forces, energy=energy, cell_energy=cell_energy)

    def _combined_cpu(self, model, state) -> ForceResult:
        geometry = state.constraint.cell_geometry(state, area_vectors=True)
        cell_energy, d_area, d_perimeter = model.cell_terms(state, geometry)
        bending_energy, d_area_vector = _cell_terms(state, self._device_B(state)[1], geometry.area_vector)
        cell_energy += bending_energy                     # the vertex model's own array
        energy = weighted_bincount(state.cell_replica, weights=cell_energy, minlength=state.n_replicas)
        forces = -state.constraint.shape_gradient(state, geometry, d_area, d_perimeter, d_area_vector.T)
        return ForceResult(forces=forces, energy=energy, cell_energy=cell_energy)

    def _compute_gpu(self, state) -> ForceResult:
        """Three kernels (bending.cu): area vectors and normals per cell; energy and dE/da per cell
        over its neighbours; forces per vertex over its three corners."""
        import cupy as cp
        if _facets(state):
            return self._facets_gpu(None, state)
        module = surface_kernels(_KERNELS, state)[0]
        nc, nv = state.n_cells, state.n_vertices
        normal, inv_area = cp.empty((nc, 3)), cp.empty(nc)
        launch(module.get_function("bending_cell_normals"), nc,
               (state.positions, state.cell_vertices, state.cell_sides, np.int32(nc), np.int32(state.max_sides),
                normal, inv_area))
        cell_energy, energy = cp.empty(nc), cp.empty(state.n_replicas)
        w = self._cell_terms_gpu(state, module, normal, inv_area, cell_energy, energy, "bending_cell_terms")
        forces = cp.empty_like(state.positions)
        launch(module.get_function("bending_vertex_forces"), nv,
               (state.positions, state.vertex_neighbors, state.vertex_cells, np.int32(nv), w, forces))
        return ForceResult(forces=forces, energy=energy, cell_energy=cell_energy)

    def _combined_gpu(self, model, state) -> ForceResult:
        """Three kernels where the vertex model alone has two: its cell kernel also writes the
        normals (and leaves the per-replica sum), the bending cell kernel adds its energies to the
        vertex model's and sums both, and the vertex model's vertex kernel adds the bending gradient
        before its tangent projection."""
        import cupy as cp
        if _facets(state):
            return self._facets_gpu(model, state)
        kA, kP, A0, P0 = model.device_parameters(state)
        module, size = surface_kernels(_KERNELS, state)
        nc, nv = state.n_cells, state.n_vertices
        coef, cell_energy, energy = cp.empty((nc, 2)), cp.empty(nc), cp.empty(state.n_replicas)
        normal, inv_area = cp.empty((nc, 3)), cp.empty(nc)
        launch(module.get_function("vm_bending_cell_geometry"), nc,
               (state.positions, state.cell_vertices, state.cell_sides, state.cell_replica, size,
                np.int32(nc), np.int32(state.max_sides), kA, kP, A0, P0, coef, cell_energy, normal, inv_area))
        w = self._cell_terms_gpu(state, module, normal, inv_area, cell_energy, energy, "bending_cell_terms_add")
        forces = cp.empty_like(state.positions)
        launch(module.get_function("vm_bending_vertex_forces"), nv,
               (state.positions, state.vertex_neighbors, state.vertex_cells, state.vertex_replica, size,
                np.int32(nv), coef, w, forces))
        return ForceResult(forces=forces, energy=energy, cell_energy=cell_energy)

    def _facets_gpu(self, model, state) -> ForceResult:
        """On a surface of flat facets (the implicit surfaces: per-cell coefficients (dE/dA a / A,
        dE/dP), Surface::coef_width 4): the vertex model's cell kernel where ``model`` is given, each
        cell's normal from its vector area (bending_facet_normals), the bending terms over the
        neighbours added to its energies, dE/da = 2 w added to the coefficients, and the vertex
        model's vertex kernel (Implicit::vertex_force: the flat-facet gradient of both)."""
        import cupy as cp
        module, size = surface_kernels(_KERNELS, state)
        nc, nv = state.n_cells, state.n_vertices
        coef, cell_energy, energy = cp.zeros((nc, 4)), cp.empty(nc), cp.empty(state.n_replicas)
        normal, inv_area = cp.empty((nc, 3)), cp.empty(nc)
        if model is not None:
            kA, kP, A0, P0 = model.device_parameters(state)
            launch(module.get_function("vm_bending_cell_geometry"), nc,
                   (state.positions, state.cell_vertices, state.cell_sides, state.cell_replica, size,
                    np.int32(nc), np.int32(state.max_sides), kA, kP, A0, P0, coef, cell_energy, normal, inv_area))
        launch(module.get_function("bending_facet_normals"), nc,
               (state.positions, state.cell_vertices, state.cell_sides, state.cell_replica, size, np.int32(nc),
                np.int32(state.max_sides), normal, inv_area))
        w = self._cell_terms_gpu(state, module, normal, inv_area, cell_energy, energy,
                                 "bending_cell_terms" if model is None else "bending_cell_terms_add")
        coef[:, :3] += 2.0 * w
        forces = cp.empty_like(state.positions)
        launch(module.get_function("vm_bending_vertex_forces"), nv,
               (state.positions, state.vertex_neighbors, state.vertex_cells, state.vertex_replica, size,
                np.int32(nv), coef, w, forces))
        return ForceResult(forces=forces, energy=energy, cell_energy=cell_energy)

    def _cell_terms_gpu(self, state, module, normal, inv_area, cell_energy, energy, kernel):
        """The per-cell kernel over the neighbours (found from the State's arrays: no table to rebuild
        after T1 flips): energies into ``cell_energy`` and ``energy``; returns the per-cell vectors
        the vertex kernels take (``dE/da / 2``, (n_cells, 3))."""
        import cupy as cp
        nc = state.n_cells
        w = cp.empty((nc, 3))
        launch(module.get_function(kernel), nc,
               (normal, inv_area, state.cell_vertices, state.cell_sides, state.vertex_cells, np.int32(nc),
                np.int32(state.max_sides), state.cell_replica, self._device_B(state)[0], w, cell_energy, energy,
                *segment_sums(state, "cells")))
        return w

    @property
    def loggables(self):
        return {"bending_energy": lambda sim: self.energy(sim.state)}

    def __repr__(self):
        B = float(self.B) if self.B.ndim == 0 else self.B.tolist()
        return f"Bending(B={B})"
