"""Many Brownian steps of small tissues in one launch: a thread block (or a cluster of them) per
tissue (tissue_steps.cu).

Inside CUDA graphs (:mod:`spherevm.graphs`) a small tissue's Brownian step with T1 is still seven
kernels of a few microseconds each (T1's memset and three kernels, the vertex model's two, the
move), and the GPU idles between them: about 0.03 ms a step for 8 tissues of 1,024 cells on an
H200, whatever the size below ~1e4 cells. Here one launch runs a whole stretch of steps (up to the
next check or write): each tissue's block (or cluster of blocks, for tissues of more than
VERTICES_PER_BLOCK vertices) keeps its positions, forces, cell coefficients and T1 claims in shared
memory and runs the phases of every step one after another, with a barrier between them.

The trajectory is the general kernels' bit for bit: every phase calls the same device function
(``vertex_model.cuh``, ``t1_pass.cuh``, ``brownian.cuh``) with the same global indices, so the
Philox draws, the flips (lowest edge index wins) and the arithmetic are the same. The tests compare
the two paths' positions, topology and counters exactly (``tests/test_tissue_steps.py``).

It serves ``Simulation.run`` (not ``minimize``) where :func:`why_not` finds nothing against it:
the GPU, a sphere or periodic plane, a :class:`~spherevm.plugins.integrators.Brownian` integrator
(not Active), one :class:`~spherevm.plugins.forces.VertexModel`, at most one
:class:`~spherevm.plugins.updaters.T1` without flip-back counting, every operation firing each
step, and every tissue small enough for shared memory (about 1,400 cells on one block, 1,800 on a
cluster of blocks, on an H200).
``run(fused=False)`` keeps the general kernels.
"""
from __future__ import annotations

import functools
from pathlib import Path

import numpy as np

from .plugins.base import SURFACE_DEFINES, surface_kernels
from .plugins.forces import VertexModel
from .plugins.integrators import Brownian
from .plugins.updaters import T1

_KERNELS = Path(__file__).with_suffix(".cu")
#: threads per tissue's block (at most this many; fewer for a tissue with fewer vertices)
THREADS = 1024
#: tissues of up to this many vertices run on one block; larger ones on a cluster of blocks, one
#: block per about this many vertices. One H200, Brownian + T1 (2026-11-24), ms a step by blocks a
#: tissue 1 / 2 / 4 / 8: 8 x 1,024 cells 0.033 / 0.024 / 0.024 / 0.029; 1 x 1,000 0.031 / 0.024 /
#: 0.025 / 0.027; 8 x 256 0.013 / 0.019: the chains of dependent double-precision operations of one
#: cell and one vertex set a floor that more blocks do not lower.
VERTICES_PER_BLOCK = 1024
#: largest cluster (the portable size on Hopper)
MAX_CLUSTER = 8


def cluster_size(state, n_sm: int | None = None) -> int:
    """Thread blocks per tissue (a power of two, at most MAX_CLUSTER): a tissue of more than
    VERTICES_PER_BLOCK vertices spreads over more SMs, as long as every tissue's cluster still finds
    SMs of its own (``n_sm``, the device's; a second wave of blocks would cost more: 40 x 1,024 cells
    took 0.024 ms a step on 2 blocks a tissue and 0.044 on 4)."""
    need = -(-int(state.vertices_per_replica.max()) // VERTICES_PER_BLOCK)
    size = 1
    while size < need and size < MAX_CLUSTER and (n_sm is None or 2 * size * state.n_replicas <= n_sm):
        size *= 2
    return size


def shared_bytes(state, cluster: int) -> int:
    """Shared memory of a block of the largest tissue (tissue_steps.cu): two copies of the positions
    (3 doubles a vertex each), the cell coefficients (2 doubles a cell), the forces of the block's
    vertices and the claims (an int a cell)."""
    nv, nc = state.vertices_per_replica, state.cells_per_replica
    return int(np.max(8 * (6 * nv + 2 * nc + 3 * (-(-nv // cluster))) + 4 * nc))


@functools.lru_cache(maxsize=None)
def device_limits(device_id: int):
    """``(compute capability, shared memory a block may opt in to, SM count)`` of a GPU, asked once
    (CuPy's ``Device.attributes`` queries every attribute, a cost each stretch need not pay)."""
    import cupy as cp
    device = cp.cuda.Device(device_id)
    attributes = device.attributes
    return (int(device.compute_capability), attributes["MaxSharedMemoryPerBlockOptin"],
            attributes["MultiProcessorCount"])


def why_not(simulation) -> str | None:
    """Why the fused steps cannot run ``simulation``'s next steps (None if they can)."""
    state, ops = simulation.state, simulation.operations
    if not simulation.device.is_gpu:
        return "the fused small-tissue steps need the GPU"
    if not isinstance(state.constraint, tuple(SURFACE_DEFINES)):
        return f"no kernels for {type(state.constraint).__name__}"
    if type(ops.integrator) is not Brownian:
        return f"the integrator is {type(ops.integrator).__name__}, not Brownian"
    if len(ops.forces) != 1 or type(ops.forces[0]) is not VertexModel:
        return "the forces are not one VertexModel"
    updaters = list(ops.updaters)
    if len(updaters) > 1 or (updaters and type(updaters[0]) is not T1):
        return "the updaters are not at most one T1"
    if updaters and updaters[0].counting(simulation):
        return "T1 counts flip-backs (count_flip_backs=True)"
    import cupy as cp
    capability, room, n_sm = device_limits(cp.cuda.Device().id)
    if capability < 90:
        return "the fused small-tissue steps need thread block clusters (compute capability 9.0, Hopper)"
    need = shared_bytes(state, cluster_size(state, n_sm))
    if need > room:
        return f"a tissue needs {need} bytes of shared memory a block, a block has {room}"
    return None


class TissueSteps:
    """The fused steps of one Simulation: :meth:`run` advances the State ``steps`` steps (the
    caller, :class:`spherevm.graphs.StepGraphs`, has made T1's room and padded the cell table for
    them, and does the Simulation's bookkeeping)."""

    def __init__(self, simulation, max_steps: int):
        import cupy as cp
        self.sim = simulation
        self.n_sm = device_limits(cp.cuda.Device().id)[2]
        self.step_need = cp.full(max_steps, -1, dtype=cp.int32)   # per step of a launch (tissue_steps_finish)
        zero, none = cp.zeros(1, dtype=cp.int32), cp.zeros(1)
        self.no_t1 = (zero.view(bool), none, none, np.float64(0.0), zero, none, zero, zero, zero, zero)

    def run(self, steps: int):
        import cupy as cp
        sim = self.sim
        state = sim.state
        if steps > len(self.step_need):
            raise ValueError(f"at most {len(self.step_need)} fused steps a launch, got {steps}")
        cluster = cluster_size(state, self.n_sm)
        module, size = surface_kernels(_KERNELS, state, (f"TISSUE_CLUSTER={cluster}",))
        kernel = module.get_function("tissue_steps")
        shared = shared_bytes(state, cluster)
        if kernel.max_dynamic_shared_size_bytes < shared:
            kernel.max_dynamic_shared_size_bytes = shared
        model = sim.operations.forces[0]
        kA, kP, A0, P0 = model.device_parameters(state)
        t1 = sim.operations.updaters[0] if sim.operations.updaters else None
        if t1 is not None:
            t1_args, (width, log_pass) = t1.tissue_step_arguments(sim)
        else:                        # t1 = 0: the kernel reads none of T1's arguments
            t1_args = self.no_t1
        vertex_start, cell_start = state.cached((TissueSteps, "starts"), lambda: (
            cp.asarray(state.vertex_start.astype(np.int32)), cp.asarray(state.cell_start.astype(np.int32))))
        block_vertices = -(-int(state.vertices_per_replica.max()) // cluster)
        threads = int(min(THREADS, -(-block_vertices // 32) * 32))
        kernel((cluster * state.n_replicas,), (threads,),
               (state.positions, state.vertex_neighbors, state.vertex_cells, state.cell_vertices, state.cell_sides,
                vertex_start, cell_start, size, np.int32(state.max_sides), kA, kP, A0, P0,
                np.int32(t1 is not None), *t1_args, self.step_need,
                *sim.operations.integrator.tissue_step_arguments(sim), np.uint64(sim.timestep), np.int32(steps)),
               shared_mem=shared)
        if t1 is not None:
            module.get_function("tissue_steps_finish")((1,), (1,), (width, self.step_need, np.int32(steps), log_pass))
