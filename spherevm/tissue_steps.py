"""Many steps of small tissues in one launch, assembled from the operations' fused stages: a thread
block (or a cluster of them) per tissue (tissue_steps.cu).

Inside CUDA graphs (:mod:`spherevm.graphs`) a small tissue's Brownian step with T1 is still seven
kernels of a few microseconds each (T1's memset and three kernels, the vertex model's two, the
move), and the GPU idles between them: about 0.03 ms a step for 8 tissues of 1,024 cells on an
H200, whatever the size below ~1e4 cells. Here one launch runs a whole stretch of the plan's cycles
(up to the next check or write): each tissue's block (or cluster of blocks, for tissues of more
than VERTICES_PER_BLOCK vertices) keeps its positions, forces, cell coefficients and the pass's
claims in shared memory and runs the phases of every step one after another, with a barrier
between them.

The kernel is assembled from the stages of the operations present
(:meth:`spherevm.plugins.base.Operation.fused_stage`, :mod:`spherevm.plugins.fusion`): the forces'
stages (a pair that ``Force.combined`` computes together as one, through ``Force.fused_combined``:
:func:`force_stages`), the integrator's (a run's move, or a minimiser's sums, control and move) and
at most one updater's pass. A force's stage has a cell part (from each cell's area, perimeter and
vertices), optionally a second per-cell part that reads its neighbours' coefficients (after every
cell's first part and T1's flips, a barrier between: the bending force's), and a vertex part. The
kernel is compiled once per combination of stages, surface and cluster size. Nothing here names an
operation: an operation without a stage (None) keeps the steps on CUDA graphs of the general
kernels, and :func:`why_not` says which. Each stage calls the same device functions as
its operation's general kernels with the same global indices, so the trajectory is the general
kernels' bit for bit: the same Philox draws, the same flips (lowest edge index wins), the same
arithmetic, the forces summed in the operations' order (``tests/test_tissue_steps.py``).

Kernel arguments are structs declared from one Python definition each
(:class:`~spherevm.kernel_struct.KernelStruct`: :data:`TISSUE_STATE` and each stage's), and each
shared-memory layout is written once (:data:`STEP_LAYOUT`, :data:`MINIMIZE_LAYOUT`): the kernel's
offsets and the bytes asked for at launch come from it.

Sizes (on an H200): spherical tissues of about 1,150 cells on one block and 1,500 on a cluster of
blocks, planar ones of 1,400 and 1,900, for the vertex model, T1 and Brownian dynamics; a
minimisation uses one block a tissue (about 1,250 cells on the sphere, 1,400 on the plane): its
sums would cross the cluster at every iteration. With the bending force (7 doubles a cell more):
about 900 cells on one block, 1,100 on a cluster, 950 minimising.
"""
from __future__ import annotations

import functools
from pathlib import Path

import numpy as np

from .constraints.kernels import compiles, keeps_directions
from .device import BLOCK, load_source
from .kernel_struct import KernelStruct
from .plan import Plan

_KERNELS = Path(__file__).with_suffix(".cu")
#: threads per tissue's block (at most this many; fewer for a tissue with fewer vertices)
THREADS = 1024
#: tissues of up to this many vertices run on one block; larger ones on a cluster of blocks, one
#: block per about this many vertices. One H200, Brownian + T1, ms a step by blocks a tissue
#: 1 / 2 / 4 / 8 before the kept norms: 8 x 1,024 cells 0.033 / 0.024 / 0.024 / 0.029; 1 x 1,000
#: 0.031 / 0.024 / 0.025 / 0.027; 8 x 256 0.013 / 0.019: the chains of dependent double-precision
#: operations of one cell and one vertex set a floor that more blocks do not lower. With the kept
#: norms and two lanes a cell: 8 x 1,024 cells on 4 blocks 0.0214 against 0.0250 on 2; with two or
#: three barriers a step, 16.0 us of GPU time a step on 4 blocks against 19.4 on 8.
VERTICES_PER_BLOCK = 512
#: largest cluster (the portable size on Hopper)
MAX_CLUSTER = 8

#: The State's part of the kernels' arguments, and the engine's per-step room (step_need).
TISSUE_STATE = KernelStruct("TissueState", [
    ("pos", "double*"), ("vn", "int*"), ("vc", "int*"), ("cell_vertices", "int*"), ("sides", "int*"),
    ("vertex_start", "const int*"), ("cell_start", "const int*"), ("size", "const double*"), ("max_sides", "int"),
    ("active", "const bool*"), ("step_need", "int*")])
#: The arguments of NoPass (no updater in the steps).
NO_PASS = KernelStruct("NoPassArgs", [("unused", "int")])


class Layout:
    """A shared-memory layout, written once: regions of doubles, then regions of ints, each sized
    by an expression in the layout's variables (``//`` is integer division). :attr:`cuda` declares
    a struct of the regions' offsets and a device function computing it; :meth:`bytes` evaluates the
    same expressions in Python (NumPy arrays of tissues allowed).

    Parameters
    ----------
    name : str
        The struct's C name; the function is ``tissue_<...>_layout`` (:attr:`function`).
    function : str
        The C function's name.
    variables : sequence of str
        The function's arguments, in order.
    doubles, ints : sequence of (str, str)
        ``(region, size expression)``.
    """

    def __init__(self, name, function, variables, doubles, ints):
        self.name, self.function, self.variables = name, function, tuple(variables)
        self.doubles, self.ints = tuple(doubles), tuple(ints)

    @property
    def cuda(self) -> str:
        fields = [r for r, _ in self.doubles] + ["ints"] + [r for r, _ in self.ints]
        lines = [f"struct {self.name} {{ long {', '.join(fields)}; }};",
                 f"__device__ __forceinline__ {self.name} {self.function}("
                 + ", ".join(f"long {v}" for v in self.variables) + ") {",
                 f"    {self.name} at;", "    long d = 0, i = 0;"]
        lines += [f"    at.{r} = d; d += {size.replace('//', '/')};" for r, size in self.doubles]
        lines += ["    at.ints = d;"]
        lines += [f"    at.{r} = i; i += {size.replace('//', '/')};" for r, size in self.ints]
        lines += ["    return at;", "}"]
        return "\n".join(lines) + "\n"

    def bytes(self, **values):
        """Bytes of shared memory for the variables' ``values``."""
        env = {"__builtins__": {}}
        doubles = sum(eval(size, env, values) for _, size in self.doubles)   # noqa: S307 - fixed expressions
        ints = sum(eval(size, env, values) for _, size in self.ints)         # noqa: S307
        return 8 * doubles + 4 * ints


#: A run's steps: two copies of the positions, the forces' cell coefficients (cd a cell) and their
#: neighbour parts' (md a cell), on the sphere two copies of the kept inverse norms (kept: nv, else
#: 0), the forces of the block's vertices (vchunk of them); the pass's claims (an int a cell), a
#: pass's flips (an int per four cells) and, where a force has a neighbour part, the step at which
#: each cell was last needed and the cells a step needs (an int a cell each).
STEP_LAYOUT = Layout("TissueStepLayout", "tissue_step_layout", ("nv", "nc", "kept", "vchunk", "cd", "md"),
                     [("pos", "6 * nv"), ("coef", "cd * nc"), ("more", "md * nc"), ("inv", "2 * kept"),
                      ("force", "3 * vchunk")],
                     [("claim", "nc"), ("flipped", "(nc + 3) // 4"), ("mark", "nc * (md > 0)"),
                      ("needed", "nc * (md > 0)")])
#: A minimisation (one block a tissue): the positions, forces and the minimiser's vertex state (vd
#: doubles a vertex), the forces' cell coefficients and neighbour parts, the kept inverse norms, the
#: sums' warp parts (n_sums (n_warps + 1), n_warps the warps from v0 rounded down to a warp's start
#: to v1); the claims.
MINIMIZE_LAYOUT = Layout("TissueMinimizeLayout", "tissue_minimize_layout",
                         ("nv", "nc", "kept", "n_warps", "cd", "md", "n_sums", "vd"),
                         [("pos", "3 * nv"), ("force", "3 * nv"), ("velocity", "vd * nv"), ("coef", "cd * nc"),
                          ("more", "md * nc"), ("inv", "kept"), ("part", "n_sums * (n_warps + 1)")],
                         [("claim", "nc")])


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


def shared_bytes(state, cluster: int, minimizing: bool, stages) -> int:
    """Shared memory of a block of the largest tissue (:data:`STEP_LAYOUT` or :data:`MINIMIZE_LAYOUT`)."""
    forces, move, _ = stages
    nv, nc = state.vertices_per_replica, state.cells_per_replica
    kept = nv if keeps_directions(state.constraint) else 0   # Surface::directions
    cd, md = sum(s.cell_doubles for s in forces), sum(s.neighbour_doubles for s in forces)
    if minimizing:
        return int(np.max(MINIMIZE_LAYOUT.bytes(nv=nv, nc=nc, kept=kept, n_warps=(nv + 62) // 32, cd=cd, md=md,
                                                n_sums=move.sums, vd=move.vertex_doubles)))
    return int(np.max(STEP_LAYOUT.bytes(nv=nv, nc=nc, kept=kept, vchunk=-(-nv // cluster), cd=cd, md=md)))


def layout(state, minimizing: bool, n_sm: int, stages):
    """``(blocks a tissue, shared memory a block, threads a block, register bound)`` of the fused
    kernels for ``state`` (worked out once per State and stages' shape). Threads: a tissue's vertices
    over its blocks, from a warp's start when minimising. The kernel is compiled for blocks of at
    most ``bound`` threads (``__launch_bounds__``): 512 where the launch's blocks take at most 512
    threads of each SM, which lets a thread hold 128 registers (a few dozen bytes spilled, against
    170-320 on 64), else 1,024, whose 64 registers a thread keep more blocks on an SM at once (one
    H200: 8 x 1,024 cells, Brownian + T1, 16.3 us a step against 17.1; 1,024 x 32 cells, FIRE + T1,
    0.025 ms an iteration on a bound of 512 against 0.019)."""
    forces, move, _ = stages
    shape = (sum(s.cell_doubles for s in forces), sum(s.neighbour_doubles for s in forces), move.sums,
             move.vertex_doubles)

    def build():
        cluster = 1 if minimizing else cluster_size(state, n_sm)
        block_vertices = -(-(int(state.vertices_per_replica.max()) + 31 * minimizing) // cluster)
        threads = int(min(THREADS, -(-block_vertices // 32) * 32))
        per_sm = -(-cluster * state.n_replicas // n_sm) * threads
        bound = THREADS // 2 if per_sm <= THREADS // 2 else THREADS
        return cluster, shared_bytes(state, cluster, minimizing, stages), threads, bound
    return state.cached((layout, minimizing, n_sm, shape), build)


@functools.lru_cache(maxsize=None)
def device_limits(device_id: int):
    """``(compute capability, shared memory a block may opt in to, SM count)`` of a GPU, asked once
    (CuPy's ``Device.attributes`` queries every attribute, a cost each stretch need not pay)."""
    import cupy as cp
    device = cp.cuda.Device(device_id)
    attributes = device.attributes
    return (int(device.compute_capability), attributes["MaxSharedMemoryPerBlockOptin"],
            attributes["MultiProcessorCount"])


def stages(plan):
    """``((force stages...), move stage, pass stage or None)`` of ``plan``'s operations, or a string
    saying which operation has no stage (or what else stands in the way). The force stages are in
    :func:`~spherevm.plugins.base.compute_all`'s order, a pair that ``Force.fused_combined`` joins
    as its host's stage followed by the joined (``extra``) one."""
    sim = plan.simulation
    passes = []
    for op in plan.updaters:
        stage = op.fused_stage(sim, plan.minimizing)
        if stage is None or stage.role != "pass":
            return _refused(op, stage, plan.minimizing)
        passes.append(stage)
    forces = force_stages(plan)
    if isinstance(forces, str):
        return forces
    move = plan.integrator.fused_stage(sim, plan.minimizing)
    if move is None:
        return _refused(plan.integrator, move, plan.minimizing)
    if move.role != "move":
        return f"the integrator {type(plan.integrator).__name__}'s fused stage has role {move.role!r}, not 'move'"
    if len(passes) > 1:
        return "more than one updater's pass (the fused steps take at most one)"
    if not any(s.measures for s in forces):
        return "no force stage computes the cells (the fused steps need one, such as the vertex model's)"
    return tuple(forces), move, (passes[0] if passes else None)


def _refused(op, stage, minimizing):
    """Why ``op``'s ``stage`` (None, or of a role its kind cannot take) keeps the steps unfused."""
    if stage is None:
        return (f"{type(op).__name__} has no fused stage for {'minimize' if minimizing else 'run'} "
                "(Operation.fused_stage; docs/plugins.md, making your plugin fusable)")
    return f"{type(op).__name__}'s fused stage has role {stage.role!r}, which its kind cannot take"


def force_stages(plan):
    """The forces' stages, paired as :func:`~spherevm.plugins.base.compute_all` pairs the forces
    (``Force.fused_combined`` asked both ways round, in order), or why they cannot be fused."""
    sim, minimizing = plan.simulation, plan.minimizing
    left, out = list(plan.forces), []
    while left:
        force = left.pop(0)
        host, joined = force, None
        for i, other in enumerate(left):
            host, joined = other, force.fused_combined(other, sim, minimizing)
            if joined is None:
                host, joined = force, other.fused_combined(force, sim, minimizing)
            if joined is not None:
                del left[i]
                break
        stage = host.fused_stage(sim, minimizing)   # (host is force where nothing joined it)
        if stage is None or stage.role != "force":
            return _refused(host, stage, minimizing)
        if stage.extra:
            return f"{type(host).__name__}'s fused stage is an extra, which only Force.fused_combined gives"
        out.append(stage)
        if joined is not None:
            partner = other if host is force else force
            if not joined.extra or joined.role != "force":
                return f"{type(partner).__name__}.fused_combined gave a stage that is no force's extra"
            if not stage.takes_extra:
                return (f"{type(host).__name__}'s fused stage takes no extra, which {type(partner).__name__}'s "
                        "combined stage needs")
            out.append(joined)
    return out


def why_not(simulation, minimizing: bool = False) -> str | None:
    """Why the fused steps cannot run ``simulation``'s next steps of ``run`` (or of ``minimize``:
    ``minimizing``); None if they can. Asked before every stretch: the answer is kept with the State
    for the operations and their parameters' versions."""
    if not simulation.device.is_gpu:
        return "the fused small-tissue steps need the GPU"
    return reason(Plan(simulation, minimizing))


def reason(plan) -> str | None:
    """:func:`why_not` for ``plan`` (its executor's), kept with the State for the operations and
    their parameters' versions."""
    key = tuple((id(op), type(op), op.parameter_version) for op in plan.device_operations())
    return plan.simulation.state.cached((why_not, plan.minimizing, key), lambda: _why_not(plan))


def _why_not(plan):
    simulation, minimizing = plan.simulation, plan.minimizing
    state = simulation.state
    if not compiles(state.constraint):
        return f"no kernels for {type(state.constraint).__name__}"
    found = stages(plan)
    if isinstance(found, str):
        return found
    if minimizing and -(-int(state.vertices_per_replica.max()) // BLOCK) >= 32:
        return "a tissue spans more than 31 tiles of the general kernels' sums"
    import cupy as cp
    capability, room, n_sm = device_limits(cp.cuda.Device().id)
    if capability < 90:
        return "the fused small-tissue steps need thread block clusters (compute capability 9.0, Hopper)"
    need = layout(state, minimizing, n_sm, found)[1]
    if need > room:
        return f"a tissue needs {need} bytes of shared memory a block, a block has {room}"
    return None


def _unique(items):
    return list(dict.fromkeys(items))


def _signature(found, minimizing):
    forces, move, pas = found
    return (minimizing,) + tuple((s.role, s.struct, s.source, id(s.arguments), s.cell_doubles, s.measures,
                                  s.neighbour_doubles, s.takes_extra, s.extra, s.sums, s.vertex_doubles)
                                 for s in (*forces, move, *([pas] if pas is not None else [])))


def kernel_source(found, minimizing: bool) -> str:
    """The CUDA source of the fused kernel for the stages ``found`` (see :func:`stages`): the
    argument structs, the layouts, tissue_steps.cu, the stages' sources, the forces' aggregate
    (:func:`_forces_aggregate`) and the extern "C" kernel."""
    forces, move, pas = found
    structs = _unique([TISSUE_STATE.cuda, NO_PASS.cuda] + [s.arguments.cuda for s in (*forces, move)]
                      + ([pas.arguments.cuda] if pas is not None else []))
    sources = _unique([s.source for s in (*forces, move)] + ([pas.source] if pas is not None else []))
    out = structs + [STEP_LAYOUT.cuda, MINIMIZE_LAYOUT.cuda, '#include "tissue_steps.cu"'] + sources
    out += _forces_aggregate(forces)
    pass_type, pass_args = (pas.struct, pas.arguments.name) if pas is not None else ("NoPass", NO_PASS.name)
    out.append(f"using TissueMove = {move.struct};\nusing TissuePass = {pass_type};")
    head = "extern \"C\" __global__ void __launch_bounds__(TISSUE_THREADS)"
    common = f"TissueState st, TissueForcesArgs fa, {move.arguments.name} ma, {pass_args} pa"
    build = ("    const TissueForces forces(fa);\n    const TissueMove move{ma};\n"
             "    const TissuePass pass(pa, st.step_need);\n")
    if minimizing:
        out.append(f"static_assert(TissueMove::n_sums == {move.sums} && TissueMove::vertex_doubles == "
                   f"{move.vertex_doubles}, \"the minimiser's stage and its FusedStage disagree\");")
        out.append(f"{head} tissue_minimize({common}, int tile, unsigned long long step0, int steps)\n{{\n"
                   f"{build}    tissue_minimize_body(st, forces, move, pass, tile, step0, steps);\n}}")
    else:
        out.append(f"{head} TISSUE_CLUSTER_DIMS tissue_steps({common}, unsigned long long step0, int steps)\n{{\n"
                   f"{build}    tissue_steps_body(st, forces, move, pass, step0, steps);\n}}")
    return "\n".join(out) + "\n"


def _copy(width, region, paired):
    """The line of the forces' aggregate that copies a stage's ``width`` doubles of cell ``c``:
    ``paired`` (an even width at an even offset, so 16-byte aligned), two at a time (half the
    stores, which cost most where they go to another block of the cluster)."""
    if paired:
        return (f"        for (int j = 0; j < {width}; j += 2) {{ long i = {region} + {width}L * c + j; "
                "*(double2*)(to + i) = *(const double2*)(from + i); }")
    return f"        for (int j = 0; j < {width}; ++j) {{ long i = {region} + {width}L * c + j; to[i] = from[i]; }}"


def _forces_aggregate(forces):
    """The CUDA of the forces' arguments (``TissueForcesArgs``) and aggregate (``TissueForces``):
    each stage's regions of the coefficient areas in turn (``data``: ``cell_doubles`` a cell,
    ``more``: ``neighbour_doubles``), its cell part, its neighbour part, and the vertex forces summed
    in order, an ``extra`` stage's gradient added inside the vertex force of the stage before it
    (``StageExtra``, tissue_steps.cu)."""
    members, cells, neighbours, vertex, copies = [], [], [], [], []
    offset = more = 0
    regions = []
    for s in forces:
        regions.append((f"{offset}L * nc - {s.cell_doubles}L * c0", f"{more}L * nc - {s.neighbour_doubles}L * c0",
                        offset % 2 == 0 and s.cell_doubles % 2 == 0))
        offset, more = offset + s.cell_doubles, more + s.neighbour_doubles
    for k, s in enumerate(forces):
        (at, more_at, paired), rest = regions[k], forces[k + 1:]
        coef, extra = f"data + {at}", f"more + {more_at}"
        members.append(f"    {s.struct} s{k};")
        if s.measures:
            cells.append(f"        s{k}.cell(A, P, c, s, {coef}, pos, row, n);")
        if s.neighbour_doubles:
            neighbours.append(f"        s{k}.neighbours(pos, vc, cell_vertices, sides, max_sides, c, s, {coef}, "
                              f"{extra});")
        if s.cell_doubles:
            copies.append(_copy(s.cell_doubles, at, paired))
        if s.extra:
            continue
        args = coef + (f", {extra}" if s.neighbour_doubles else "") + ", norm"
        if rest and rest[0].extra:
            joined_at, joined_more_at, _ = regions[k + 1]
            args += f", StageExtra<{rest[0].struct}>{{s{k + 1}, data + {joined_at}, more + {joined_more_at}}}"
        term = f"s{k}.vertex(pos, vn, vc, v, s, {args})"
        vertex.append(f"        f = add3_rn(f, {term});" if vertex else f"        vec3 f = {term};")
    measures = "true" if any(s.measures for s in forces) else "false"
    return ["struct TissueForcesArgs {\n" + "".join(f"    {s.arguments.name} s{k};\n" for k, s in enumerate(forces))
            + "};", "\n".join([
                "struct TissueForces {",
                f"    static constexpr int cell_doubles = {offset}, neighbour_doubles = {more};",
                f"    static constexpr bool measures = {measures};",
                *members,
                "    __device__ explicit TissueForces(const TissueForcesArgs& a) : "
                + ", ".join(f"s{k}{{a.s{k}}}" for k in range(len(forces))) + " {}",
                "    __device__ __forceinline__ void cell(double A, double P, long c, Surface::Size s, double* data,",
                "        long nc, long c0, const double* pos, const int* row, int n) const {", *cells, "    }",
                "    __device__ __forceinline__ void neighbours(const double* pos, const int* vc,",
                "        const int* cell_vertices, const int* sides, int max_sides, long c, Surface::Size s,",
                "        const double* data, double* more,"
                "        long nc, long c0) const {", *neighbours, "    }",
                "    __device__ __forceinline__ vec3 vertex(const double* pos, const int* vn, const int* vc, long v,",
                "        Surface::Size s, const double* data, const double* more, long nc, long c0,",
                "        KeptNorm norm) const {",
                *vertex, "        return f;", "    }",
                "    __device__ static __forceinline__ void copy_cell(long c, const double* from, double* to, long nc,",
                "        long c0) {", *copies, "    }",
                "};"])]

class TissueSteps:
    """The fused steps of a plan: :meth:`run` advances the State ``steps`` cycles of the plan of
    ``run`` (or iterations of ``minimize``; the caller,
    :class:`spherevm.graphs.StepGraphs`, has made T1's room and padded the cell table for them, and
    does the Simulation's bookkeeping)."""

    def __init__(self, plan, max_steps: int):
        import cupy as cp
        self.plan, self.sim, self.minimizing = plan, plan.simulation, plan.minimizing
        self.n_sm = device_limits(cp.cuda.Device().id)[2]
        self.step_need = cp.full(max_steps, -1, dtype=cp.int32)   # per step of a launch (the pass's finish)
        self.no_pass = NO_PASS.pack(unused=0)

    def run(self, steps: int):
        import cupy as cp
        sim = self.sim
        state = sim.state
        if steps > len(self.step_need):
            raise ValueError(f"at most {len(self.step_need)} fused steps a launch, got {steps}")
        found = stages(self.plan)
        if isinstance(found, str):
            raise ValueError(f"the fused steps cannot run: {found}")
        forces, move, pas = found
        cluster, shared, threads, bound = layout(state, self.minimizing, self.n_sm, found)
        kernel, forces_dtype = self._kernel(found, state, cluster, bound, shared)
        vertex_start, cell_start = state.cached((TissueSteps, "starts"), lambda: (
            cp.asarray(state.vertex_start.astype(np.int32)), cp.asarray(state.cell_start.astype(np.int32))))
        st = TISSUE_STATE.pack(
            pos=state.positions, vn=state.vertex_neighbors, vc=state.vertex_cells, cell_vertices=state.cell_vertices,
            sides=state.cell_sides, vertex_start=vertex_start, cell_start=cell_start,
            size=state.constraint.kernel_size(state), max_sides=state.max_sides,
            active=sim.operations.integrator.active_on_device(), step_need=self.step_need)
        fa = np.array(tuple(s.packed() for s in forces), dtype=forces_dtype)[()]
        args = (st, fa, move.packed(), pas.packed() if pas is not None else self.no_pass)
        tail = (np.int32(BLOCK),) if self.minimizing else ()
        kernel((cluster * state.n_replicas,), (threads,), (*args, *tail, np.uint64(sim.timestep), np.int32(steps)),
               shared_mem=shared)
        if pas is not None and pas.finish is not None:
            pas.finish(kernel.module, self.step_need, steps)

    def _kernel(self, found, state, cluster, bound, shared):
        """The compiled kernel for the stages ``found`` on ``state``'s surface (kept per combination),
        with room for ``shared`` bytes, and the dtype of its forces' arguments."""
        surface = state.constraint.device_surface()
        key = (_signature(found, self.minimizing), surface.prelude, cluster, bound)
        entry = _KERNELS_BUILT.get(key)
        if entry is None:
            module = load_source(surface.prelude + kernel_source(found, self.minimizing),
                                 (f"TISSUE_CLUSTER={cluster}", f"TISSUE_THREADS={bound}"), surface.options)
            kernel = _Kernel(module, "tissue_minimize" if self.minimizing else "tissue_steps")
            dtype = np.dtype([(f"s{k}", s.arguments.dtype) for k, s in enumerate(found[0])], align=True)
            entry = _KERNELS_BUILT[key] = (kernel, dtype)
        kernel = entry[0]
        if kernel.function.max_dynamic_shared_size_bytes < shared:
            kernel.function.max_dynamic_shared_size_bytes = shared
        return entry


class _Kernel:
    """A fused kernel and the module it came from (whose other kernels, such as a pass's finishing
    kernel, its stage launches)."""

    def __init__(self, module, name):
        self.module, self.function = module, module.get_function(name)

    def __call__(self, grid, block, args, shared_mem):
        self.function(grid, block, args, shared_mem=shared_mem)


#: compiled fused kernels, by their stages' signature, surface, cluster size and register bound
_KERNELS_BUILT = {}
