"""Many Brownian steps or FIRE iterations of small tissues in one launch: a thread block (or a
cluster of them) per tissue (tissue_steps.cu).

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

It serves ``Simulation.run`` where :func:`why_not` finds nothing against it: the GPU, a sphere or
periodic plane, a :class:`~spherevm.plugins.integrators.Brownian` integrator (not Active), one
:class:`~spherevm.plugins.forces.VertexModel`, at most one :class:`~spherevm.plugins.updaters.T1`,
every operation firing each step, and every tissue small enough for shared memory (on an H200,
spherical tissues of about 1,150 cells on one block and 1,500 on a cluster of blocks, planar ones of
1,400 and 1,900: the sphere's blocks also keep every vertex's inverse norm). ``run(fused=False)``
keeps the general kernels.

It serves ``Simulation.minimize`` the same way with :class:`~spherevm.plugins.integrators.FIRE`
(``minimize(fused=False)`` keeps the general kernels): the tissue's block also sums FIRE's power and
norms per replica in the order the general reduction adds them (``device_common.cuh``:
``block_segment_total``), so the minimisation is the general one bit for bit too. One block a
tissue (about 1,250 cells on the sphere, 1,400 on the plane, on an H200): a minimisation's sums
would cross the cluster at every iteration.
"""
from __future__ import annotations

import functools
from pathlib import Path

import numpy as np

from .constraints import Sphere
from .device import BLOCK
from .constraints.kernels import SURFACE_DEFINES, surface_kernels
from .plugins.forces import VertexModel
from .plugins.integrators import FIRE, Brownian
from .plugins.updaters import T1

_KERNELS = Path(__file__).with_suffix(".cu")
#: threads per tissue's block (at most this many; fewer for a tissue with fewer vertices)
THREADS = 1024
#: tissues of up to this many vertices run on one block; larger ones on a cluster of blocks, one
#: block per about this many vertices. The chains of dependent double-precision operations of one
#: cell and one vertex set a floor that more blocks do not lower. One H200, Brownian + T1, 8 x 1,024
#: cells: 0.0214 ms a step on 4 blocks against 0.0250 on 2 (kept norms, two lanes a cell in blocks
#: of 512 threads, T1's detection on every block), and 16.0 us of GPU time a step on 4 blocks
#: against 19.4 on 8 (two or three barriers a step). See docs/performance.md.
VERTICES_PER_BLOCK = 512
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


def shared_bytes(state, cluster: int, minimizing: bool = False) -> int:
    """Shared memory of a block of the largest tissue (tissue_steps.cu). Steps: two copies of the
    positions (3 doubles a vertex each), the cell coefficients (2 doubles a cell), on the sphere two
    copies of the kept inverse norms (a double a vertex each), the forces of the block's vertices,
    the claims (an int a cell) and a pass's flips (an int per four cells). Minimisation (one block):
    the positions, forces and velocities, the cell coefficients, on the sphere the kept inverse
    norms, the sums' warp parts (3 doubles a warp, one more) and the claims."""
    nv, nc = state.vertices_per_replica, state.cells_per_replica
    kept = nv if isinstance(state.constraint, Sphere) else 0   # Surface::directions
    if minimizing:
        warps = (nv + 62) // 32          # from v0 rounded down to a warp's start, to v1
        return int(np.max(8 * (9 * nv + 2 * nc + kept + 3 * (warps + 1)) + 4 * nc))
    return int(np.max(8 * (6 * nv + 2 * nc + 2 * kept + 3 * (-(-nv // cluster))) + 4 * (nc + -(-nc // 4))))


def layout(state, minimizing: bool, n_sm: int):
    """``(blocks a tissue, shared memory a block, threads a block, register bound)`` of the fused
    kernels for ``state`` (worked out once per State: they are asked before every stretch). Threads:
    a tissue's vertices over its blocks, from a warp's start when minimising. The kernel is compiled
    for blocks of at most ``bound`` threads (``__launch_bounds__``): 512 where the launch's blocks
    take at most 512 threads of each SM, which lets a thread hold 128 registers (a few dozen bytes
    spilled, against 170-320 on 64), else 1,024, whose 64 registers a thread keep more blocks on an
    SM at once (one H200: 8 x 1,024 cells, Brownian + T1, 16.3 us a step against 17.1; 1,024 x 32
    cells, FIRE + T1, 0.025 ms an iteration on a bound of 512 against 0.019)."""
    def build():
        cluster = 1 if minimizing else cluster_size(state, n_sm)
        block_vertices = -(-(int(state.vertices_per_replica.max()) + 31 * minimizing) // cluster)
        threads = int(min(THREADS, -(-block_vertices // 32) * 32))
        per_sm = -(-cluster * state.n_replicas // n_sm) * threads
        bound = THREADS // 2 if per_sm <= THREADS // 2 else THREADS
        return cluster, shared_bytes(state, cluster, minimizing), threads, bound
    return state.cached((layout, minimizing, n_sm), build)


@functools.lru_cache(maxsize=None)
def device_limits(device_id: int):
    """``(compute capability, shared memory a block may opt in to, SM count)`` of a GPU, asked once
    (CuPy's ``Device.attributes`` queries every attribute, a cost each stretch need not pay)."""
    import cupy as cp
    device = cp.cuda.Device(device_id)
    attributes = device.attributes
    return (int(device.compute_capability), attributes["MaxSharedMemoryPerBlockOptin"],
            attributes["MultiProcessorCount"])


def why_not(simulation, minimizing: bool = False) -> str | None:
    """Why the fused steps cannot run ``simulation``'s next steps of ``run`` (or of ``minimize``:
    ``minimizing``); None if they can. Asked before every stretch: the answer depends only on the
    State and the operations' types, so it is kept with the State for those types."""
    ops = simulation.operations
    kinds = (type(ops.integrator), tuple(map(type, ops.forces)), tuple((type(u), u.in_minimize) for u in ops.updaters))
    return simulation.state.cached((why_not, minimizing, kinds), lambda: _why_not(simulation, minimizing))


def _why_not(simulation, minimizing):
    state, ops = simulation.state, simulation.operations
    if not simulation.device.is_gpu:
        return "the fused small-tissue steps need the GPU"
    if not isinstance(state.constraint, tuple(SURFACE_DEFINES)):
        return f"no kernels for {type(state.constraint).__name__}"
    wanted = FIRE if minimizing else Brownian
    if type(ops.integrator) is not wanted:
        return f"the integrator is {type(ops.integrator).__name__}, not {wanted.__name__}"
    if len(ops.forces) != 1 or type(ops.forces[0]) is not VertexModel:
        return "the forces are not one VertexModel"
    updaters = [u for u in ops.updaters if u.in_minimize or not minimizing]
    if len(updaters) > 1 or (updaters and type(updaters[0]) is not T1):
        return "the updaters are not at most one T1"
    if minimizing and -(-int(state.vertices_per_replica.max()) // BLOCK) >= 32:
        return "a tissue spans more than 31 tiles of the general kernels' sums"
    import cupy as cp
    capability, room, n_sm = device_limits(cp.cuda.Device().id)
    if capability < 90:
        return "the fused small-tissue steps need thread block clusters (compute capability 9.0, Hopper)"
    need = layout(state, minimizing, n_sm)[1]
    if need > room:
        return f"a tissue needs {need} bytes of shared memory a block, a block has {room}"
    return None


class TissueSteps:
    """The fused steps of one Simulation: :meth:`run` advances the State ``steps`` steps of ``run``
    (or iterations of ``minimize``: ``minimizing``; the caller, :class:`spherevm.graphs.StepGraphs`,
    has made T1's room and padded the cell table for them, and does the Simulation's bookkeeping)."""

    def __init__(self, simulation, max_steps: int, minimizing: bool = False):
        import cupy as cp
        self.sim, self.minimizing = simulation, minimizing
        self.n_sm = device_limits(cp.cuda.Device().id)[2]
        self.step_need = cp.full(max_steps, -1, dtype=cp.int32)   # per step of a launch (tissue_steps_finish)
        zero, none = cp.zeros(1, dtype=cp.int32), cp.zeros(1)
        self.no_t1 = (zero.view(bool), none, none, np.float64(0.0), zero, none, zero, zero, zero, zero, zero, zero,
                      np.int32(0), zero)

    def run(self, steps: int):
        import cupy as cp
        sim = self.sim
        state = sim.state
        if steps > len(self.step_need):
            raise ValueError(f"at most {len(self.step_need)} fused steps a launch, got {steps}")
        cluster, shared, threads, bound = layout(state, self.minimizing, self.n_sm)
        module, size = surface_kernels(_KERNELS, state, (f"TISSUE_CLUSTER={cluster}", f"TISSUE_THREADS={bound}"))
        kernel = module.get_function("tissue_minimize" if self.minimizing else "tissue_steps")
        if kernel.max_dynamic_shared_size_bytes < shared:
            kernel.max_dynamic_shared_size_bytes = shared
        model = sim.operations.forces[0]
        kA, kP, A0, P0 = model.device_parameters(state)
        t1 = next((u for u in sim.operations.updaters if u.in_minimize or not self.minimizing), None)
        if t1 is not None:
            t1_args, (width, log_pass) = t1.tissue_step_arguments(sim)
        else:                        # t1 = 0: the kernel reads none of T1's arguments
            t1_args = self.no_t1
        integrator = sim.operations.integrator.tissue_step_arguments(sim)
        if self.minimizing:          # the tile of the general sums, whose order the kernel keeps
            integrator = (np.int32(t1 is not None and t1.reset_velocities), *integrator, np.int32(BLOCK))
        vertex_start, cell_start = state.cached((TissueSteps, "starts"), lambda: (
            cp.asarray(state.vertex_start.astype(np.int32)), cp.asarray(state.cell_start.astype(np.int32))))
        kernel((cluster * state.n_replicas,), (threads,),
               (state.positions, state.vertex_neighbors, state.vertex_cells, state.cell_vertices, state.cell_sides,
                vertex_start, cell_start, size, np.int32(state.max_sides), kA, kP, A0, P0,
                np.int32(t1 is not None), *t1_args, self.step_need, *integrator, np.uint64(sim.timestep),
                np.int32(steps)),
               shared_mem=shared)
        if t1 is not None:
            module.get_function("tissue_steps_finish")((1,), (1,), (width, self.step_need, np.int32(steps), log_pass))
