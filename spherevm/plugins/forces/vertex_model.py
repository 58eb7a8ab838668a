"""The vertex-model energy E = sum_c kA (A_c - A0)^2 + kP (P_c - P0)^2 and its forces."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from ...device import launch, segment_sums, weighted_bincount
from ...constraints.kernels import KERNEL_SURFACES, surface_kernels
from ...kernel_struct import KernelStruct
from ..base import Force, ForceResult
from ..fusion import FusedStage, overrides
from ..parameters import Parameter
from ..rows import saved_field, saved_where

_KERNELS = Path(__file__).with_suffix(".cu")


def _optional_param(name, value):
    return None if value is None else _param(name, value)


def _param(name, value, lower=0.0):
    arr = np.asarray(value, dtype=np.float64)
    if arr.ndim > 1:
        raise ValueError(f"{name} must be a scalar or a per-cell 1-D array, got shape {arr.shape}")
    if not np.all(np.isfinite(arr)) or np.any(arr < lower):
        raise ValueError(f"{name} must be finite and >= {lower}, got {value!r}")
    return arr


class VertexModel(Force):
    """Area and perimeter elasticity of every cell, measured on the constraint surface.

    ``E = sum_c kA (A_c - A0)^2 + kP (P_c - P0)^2``. Forces are minus the surface gradient, gathered
    per vertex from its three corners (:meth:`spherevm.constraints.Sphere.shape_gradient`), so they
    are tangent by construction. :meth:`dimensionless` gives the paper's form.

    Parameters
    ----------
    kA, kP : float or array (n_cells,)
        Area and perimeter stiffness, >= 0.
    A0, P0 : float or array (n_cells,)
        Target area and perimeter."""

    kA = Parameter(_param)
    kP = Parameter(_param)
    A0 = Parameter(_param)
    P0 = Parameter(_param)
    kr = Parameter(_optional_param)
    p0 = Parameter(_optional_param)
    a0 = Parameter(_optional_param)

    def __init__(self, kA=1.0, kP=1.0, A0=1.0, P0=3.8):
        super().__init__()
        self._reduced = False
        self.kA, self.kP, self.A0, self.P0 = kA, kP, A0, P0
        self.kr = self.p0 = self.a0 = None

    @classmethod
    def dimensionless(cls, kr=0.0, p0=3.8, a0=1.0, kP=1.0) -> "VertexModel":
        """The paper's form ``E/(kP <A>) = sum kr (a - a0)^2 + (p - p0)^2``, in the unit of length
        ``sqrt(<A>)`` of each replica, resolved per replica from its mean cell area
        <A> = 4 pi R^2 / N: ensembles of spheres of different sizes share one set of parameters.
        Its ``kr``, ``p0``, ``a0`` and ``kP`` may change later (``kA``, ``A0`` and ``P0`` are not used).

        Parameters
        ----------
        kr : float
            ``kA <A> / kP``.
        p0 : float or array (n_cells,)
            Target shape index ``P0 / sqrt(<A>)``.
        a0 : float
            ``A0 / <A>``.
        kP : float
            The energy unit.

        Returns
        -------
        VertexModel"""
        model = cls(kA=0.0, kP=kP, A0=0.0, P0=0.0)
        model.__dict__.update(_reduced=True, kr=_param("kr", kr), p0=_param("p0", p0), a0=_param("a0", a0))
        return model

    def check_parameters(self):
        """A dimensionless model takes kr, p0 and a0 (with kP); a dimensional one kA, kP, A0, P0."""
        reduced = (self.kr, self.p0, self.a0)
        if self._reduced:
            if any(v is None for v in reduced) or any(np.any(v != 0) for v in (self.kA, self.A0, self.P0)):
                raise ValueError("this VertexModel is dimensionless: set its kr, p0, a0 (and kP); kA, A0 and P0 "
                                 "are not used")
        elif any(v is not None for v in reduced):
            raise ValueError("this VertexModel is dimensional: set its kA, kP, A0 and P0, or build "
                             "VertexModel.dimensionless(kr=..., p0=..., a0=...)")

    def parameters(self, state):
        """Per-cell ``(kA, kP, A0, P0)`` as NumPy arrays of length ``n_cells``."""
        n = state.n_cells
        if self._reduced:
            mean_area = state.mean_cell_area[state.cell_replica_np()]
            values = (self.kr * self.kP / mean_area, self.kP, self.a0 * mean_area, self.p0 * np.sqrt(mean_area))
        else:
            values = (self.kA, self.kP, self.A0, self.P0)
        out = []
        for name, v in zip(("kA", "kP", "A0", "P0"), values):
            v = np.asarray(v, dtype=np.float64)
            if v.ndim == 1 and len(v) != n:
                raise ValueError(f"per-cell {name} has length {len(v)}, but the state has {n} cells")
            out.append(np.broadcast_to(v, (n,)))
        return out

    def energy_scale(self, state):
        """Per replica, the mean over its cells of ``kP <A>`` (the paper's unit of energy, whatever
        kr; ``kA <A>^2`` would vanish at kr = 0), or ``kA <A>^2`` for a cell without perimeter
        stiffness. Minimisers measure their tolerances in it. Cached for the State, as the device
        parameters are (a minimiser asks at every convergence check)."""
        def build():
            kA, kP, _, _ = self.parameters(state)
            rep = state.cell_replica_np()
            area = state.mean_cell_area[rep]
            cell = np.where(kP > 0, kP * area, kA * area * area)
            return np.bincount(rep, weights=cell, minlength=state.n_replicas) / state.cells_per_replica
        return state.cached((self, "energy_scale"), build).copy()

    narrowable = True

    def narrow(self, selection):
        """Per-cell parameters follow the selected cells."""
        saved = self._arrays()
        for name, a in saved.items():
            if a.ndim == 1:
                setattr(self, name, a[selection.cells])
        return saved

    def widen(self, selection, saved):
        for name, a in saved.items():
            setattr(self, name, a)

    def resized(self, change):
        """Per-cell parameters follow their cells: a daughter takes its mother's values."""
        for name, a in self._arrays().items():
            if a.ndim == 1:
                setattr(self, name, a[change.cell_source])

    # Checkpoints: per-cell parameter arrays are state (they follow their cells through divisions
    # and extrusions, so a grown tissue's arrays exist nowhere but here); scalars are the script's.
    def _arrays(self):
        """``{name: array}`` of every parameter in use (the dimensionless ones for such a model)."""
        names = ("kr", "kP", "p0", "a0") if self._reduced else ("kA", "kP", "A0", "P0")
        return {name: getattr(self, name) for name in names}

    def state_to_save(self) -> dict:
        """The per-cell (1-D) parameters, in the State's cell order; scalar ones are not saved."""
        return {name: np.array(a, copy=True) for name, a in self._arrays().items() if a.ndim == 1}

    def restore_state(self, data: dict):
        """Per-cell parameters come back from the checkpoint, replacing what the model was built with
        (whose length fits the tissue before it grew); a parameter the script gives as a scalar stays
        the script's. Each is checked: float64, finite, >= 0, one per cell."""
        n = self._simulation.state.n_cells
        for name, array in self._arrays().items():
            if name not in data or array.ndim == 0:
                continue
            saved = data[name]
            if np.shape(saved) != (n,):
                raise ValueError(f"{saved_where(self, data, name)}: per-cell {name!r} has shape {np.shape(saved)}, but "
                                 f"the State has {n} cells; the checkpoint belongs to another State")
            setattr(self, name, saved_field(self, data, name, np.float64, (n,), low=0).copy())

    def device_parameters(self, state):
        """Per-cell ``(kA, kP, A0, P0)`` on the device, cached for the State they were made for."""
        return state.cached((self, "parameters"), lambda: [state.device.asarray(np.ascontiguousarray(p))
                                                            for p in self.parameters(state)])

    gpu_surfaces = KERNEL_SURFACES
    surface_needs = ("cell_geometry", "shape_gradient", "total_area_np")

    def attach(self, simulation):
        super().attach(simulation)
        self.implementation("compute", simulation.state)   # refuses an unsupported surface now

    def compute(self, state) -> ForceResult:
        return self.implementation("compute", state)(state)

    def cell_terms(self, state, geometry):
        """Per cell, from the surface's ``cell_geometry``: the energy, ``dE/dA`` and ``dE/dP`` (what
        ``shape_gradient`` turns into forces; a force fused with this one passes them on)."""
        kA, kP, A0, P0 = self.device_parameters(state)
        dA_cell = geometry.area - A0
        dP_cell = geometry.perimeter - P0
        return kA * dA_cell ** 2 + kP * dP_cell ** 2, 2.0 * kA * dA_cell, 2.0 * kP * dP_cell

    def _compute_cpu(self, state) -> ForceResult:
        geometry = state.constraint.cell_geometry(state)
        cell_energy, d_area, d_perimeter = self.cell_terms(state, geometry)
        energy = weighted_bincount(state.cell_replica, weights=cell_energy, minlength=state.n_replicas)
        forces = -state.constraint.shape_gradient(state, geometry, d_area, d_perimeter)
        return ForceResult(forces=forces, energy=energy, cell_energy=cell_energy)

    def __repr__(self):
        if self._reduced:
            return f"VertexModel.dimensionless(kr={self.kr}, p0={self.p0}, a0={self.a0}, kP={self.kP})"
        return f"VertexModel(kA={self.kA}, kP={self.kP}, A0={self.A0}, P0={self.P0})"

    def capture_ready(self, simulation, steps):
        """Its two kernels take nothing that changes from step to step: CUDA graphs may hold them."""
        return ()

    #: the fused stage's arguments (vertex_model_stage.cuh): the per-cell parameters on the device
    FUSED_ARGS = KernelStruct("VertexModelArgs", [(name, "const double*") for name in ("kA", "kP", "A0", "P0")])

    def fused_stage(self, simulation, minimizing):
        """vertex_model_stage.cuh: each cell's two coefficients and each vertex's force, the general
        kernels' functions; its vertex force takes another force's gradient (``takes_extra``: the
        bending force's, Bending.fused_combined). None for a subclass that computes something else."""
        if overrides(self, VertexModel, ("compute", "_compute_gpu", "cell_terms", "parameters")):
            return None
        kA, kP, A0, P0 = self.device_parameters(simulation.state)
        return FusedStage("force", "VertexModelStage", '#include "plugins/forces/vertex_model_stage.cuh"',
                          self.FUSED_ARGS, dict(kA=kA, kP=kP, A0=A0, P0=P0),
                          cell_doubles=simulation.state.constraint.device_surface().coef_width, measures=True,
                          takes_extra=True)

    def _compute_gpu(self, state) -> ForceResult:
        """Two fused kernels (vertex_model.cu, compiled for the State's surface): cell geometry and
        energy, then vertex forces."""
        import cupy as cp
        kA, kP, A0, P0 = self.device_parameters(state)
        module, size = surface_kernels(_KERNELS, state)
        nc, nv = state.n_cells, state.n_vertices
        coef, cell_energy = cp.empty((nc, state.constraint.device_surface().coef_width)), cp.empty(nc)
        energy = cp.empty(state.n_replicas)
        launch(module.get_function("vm_cell_geometry"), nc,
               (state.positions, state.cell_vertices, state.cell_sides, state.cell_replica, size,
                np.int32(nc), np.int32(state.max_sides), kA, kP, A0, P0, coef, cell_energy, energy,
                *segment_sums(state, "cells")))
        forces = cp.empty_like(state.positions)
        launch(module.get_function("vm_vertex_forces"), nv,
               (state.positions, state.vertex_neighbors, state.vertex_cells, state.vertex_replica, size,
                np.int32(nv), coef, forces))
        return ForceResult(forces=forces, energy=energy, cell_energy=cell_energy)
