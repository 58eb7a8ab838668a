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

from spherevm.constraints import Sphere
from spherevm.geometry import geodesic_length, geodesic_length_gradient
from spherevm.kernel_struct import KernelStruct
from spherevm.plugins import Force, ForceResult, FusedStage

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


#: The kernel of docs/plugins.md ("Faster on the GPU"): the force through line_tension_force, which
#: the fused stage calls too, so both give the same bits.
KERNEL = r"""#include "geometry/sphere.cuh"
#include "device_common.cuh"

// The line tension's force on vertex v: minus the surface gradient of tension R times its three
// geodesic edge lengths (pos indexed by global vertex index, vn the vertex_neighbors table). Not
// inlined, so that the kernel below and the fused stage run the same instructions: inlined, the
// compiler would share work with the kernel's energy loop and round differently.
__device__ __noinline__ vec3 line_tension_force(const double* pos, const int* vn, long v, double R,
                                                   double tension)
{
    vec3 x = load3(pos, v);
    vec3 a = normalize3(x);
    vec3 g = v3(0.0, 0.0, 0.0);
    for (int k = 0; k < 3; ++k)
        g = g + geodesic_length_gradient(a, normalize3(load3(pos, vn[3 * v + k])));
    return (-tension * R / norm3(x)) * g;
}

extern "C" __global__ void line_tension(
    const double* __restrict__ pos, const int* __restrict__ vertex_neighbors,
    const int* __restrict__ vertex_replica, const double* __restrict__ radius, int n_vertices,
    double tension, double* __restrict__ forces, double* __restrict__ corner_energy,
    double* __restrict__ replica_energy, const int* __restrict__ vertex_start, int n_replicas,
    double* __restrict__ scratch, unsigned int* __restrict__ count)
{
    long v = (long)blockIdx.x * blockDim.x + threadIdx.x;
    int rep = -1;
    double e = 0.0;
    if (v < n_vertices) {
        rep = vertex_replica[v];
        double R = radius[rep];
        vec3 a = normalize3(load3(pos, v));
        for (int k = 0; k < 3; ++k) {               // the vertex's three edges, each seen from both ends
            vec3 b = normalize3(load3(pos, vertex_neighbors[3 * v + k]));
            double half = 0.5 * tension * (R * geodesic_length(a, b));
            corner_energy[3 * v + k] = half;
            e += half;
        }
        store3(forces, v, line_tension_force(pos, vertex_neighbors, v, R, tension));
    }
    // the replica's energy: every thread of the block calls it (rep = -1 past the last vertex)
    segment_sum(e, rep, SegmentSum{vertex_start, n_replicas, scratch, count}, replica_energy);
}
"""

#: The fused stage (docs/plugins.md, "Making your plugin fusable"): the vertex part only.
STAGE = KERNEL + r"""
struct LineTensionStage {
    LineTensionArgs a;
    __device__ __forceinline__ vec3 vertex(const double* pos, const int* vn, const int*, long v, double R,
                                           const double*, KeptNorm) const
    {
        return line_tension_force(pos, vn, v, R, a.tension);
    }
};
"""


class FastLineTension(LineTension):
    """:class:`LineTension` with its GPU kernel (forces and energies in one launch, no per-cell
    energies on the GPU) and a fused stage, so it runs in the fused small-tissue steps."""

    gpu_surfaces = (Sphere,)
    FUSED_ARGS = KernelStruct("LineTensionArgs", [("tension", "double")])

    def compute(self, state) -> ForceResult:
        return self.implementation("compute", state)(state)

    def _compute_cpu(self, state):
        return LineTension.compute(self, state)

    def _compute_gpu(self, state):
        import cupy as cp
        from spherevm.device import launch, load_source, segment_sums
        nv = state.n_vertices
        forces, corner, energy = cp.empty_like(state.positions), cp.empty((nv, 3)), cp.empty(state.n_replicas)
        launch(load_source(KERNEL).get_function("line_tension"), nv,
               (state.positions, state.vertex_neighbors, state.vertex_replica, state.radius, np.int32(nv),
                np.float64(self.tension), forces, corner, energy, *segment_sums(state, "vertices")))
        return ForceResult(forces=forces, energy=energy)

    def capture_ready(self, simulation, steps):
        return ()     # one kernel whose arguments do not change from step to step

    def fused_stage(self, simulation, minimizing):
        if not isinstance(simulation.state.constraint, Sphere):
            return None
        return FusedStage("force", "LineTensionStage", STAGE, self.FUSED_ARGS, {"tension": self.tension})

    def __repr__(self):
        return f"FastLineTension(tension={self.tension})"
