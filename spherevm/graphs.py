"""Many steps per launch on the GPU: stretches of ``Simulation.run`` captured into CUDA graphs.

A small tissue's step is a handful of short kernels. Launched one at a time from Python, with T1's
read-back of its candidate count each pass, the GPU waits on the host: about 0.13 ms per step below
~1e5 cells whatever the size. Captured once into a CUDA graph and replayed, the same kernels run
back to back with no host work between them.

The trajectory is the step-by-step path's, bit for bit: the kernels and their arguments are the
same, and what changes from step to step lives on the device: the timestep
(:meth:`Simulation.kernel_timestep`: a device counter the graph advances once per replay, plus
each step's place in the graph), T1's candidate count and the width of
its cell table (:meth:`T1.capture_ready`). Every operation says whether it can run inside a graph
(:meth:`~spherevm.plugins.base.Operation.capture_ready`); one that cannot keeps the run step by step.

``Simulation.minimize`` runs its iterations between two convergence checks the same way; there a
step is the minimiser's move followed by the updaters of the next timestep (its order step by step).

Where :func:`spherevm.tissue_steps.why_not` finds nothing against it (Brownian dynamics or FIRE
minimisation of small tissues with the vertex model and T1), a stretch is one launch of the fused
small-tissue steps instead of graph replays: the same trajectory, bit for bit, in a third of the
time.
"""
from __future__ import annotations

from . import tissue_steps
from .plugins.base import Minimizer
from .trigger import Always, Periodic

#: steps per captured graph; the rest of a stretch replays a one-step graph
GRAPH_STEPS = 8
#: auto mode: graphs for runs of at least this many steps (a capture costs about ten steps)...
MIN_STEPS = 64
#: ... and for States of at most this many vertices (graphs hold about 400 more bytes per cell:
#: T1's room for a candidate per edge and spare cell-table columns)
MAX_VERTICES = 1 << 22
#: most steps between two looks of the host (T1 pads its cell table by this many columns)...
MAX_STRETCH = 64
#: ... and for the fused small-tissue steps, whose tables are small: a run's default check interval
#: (100 steps on the GPU) in one launch, so the host looks only at the checks
FUSED_STRETCH = 128


def _every_step(trigger, timestep):
    return isinstance(trigger, Always) or (isinstance(trigger, Periodic) and trigger.period == 1
                                           and trigger.phase <= timestep)


def _end_quietly(stream):
    """End a capture that failed (its own error is the one to report)."""
    try:
        stream.end_capture()
    except Exception:       # noqa: BLE001 - the capture is invalid either way
        pass


def why_not(simulation) -> str | None:
    """Why ``simulation.run`` cannot use CUDA graphs now (None if it can, as far as triggers tell:
    each operation is asked when the first stretch starts)."""
    if not simulation.device.is_gpu:
        return "CUDA graphs need the GPU; this Simulation runs on the CPU"
    ops = list(simulation.operations.updaters) + [simulation.operations.integrator]
    for op in ops:
        if not _every_step(op.trigger, simulation.timestep):
            return (f"{type(op).__name__} runs on a trigger ({op.trigger!r}) that does not fire every step; a graph "
                    "replays the same steps")
    return None


class StepGraphs:
    """The CUDA graphs of one ``Simulation.run`` or ``minimize``: ``advance(n)`` runs n steps (a
    stretch between checks and writes) as replays; ``pause()`` before anything on the host looks at
    the State."""

    def __init__(self, simulation, required: bool, minimizing: bool = False, fused=None):
        import cupy as cp
        self.sim, self.required, self.minimizing = simulation, required, minimizing
        self.fused = fused          # None: the fused small-tissue steps where they can run; False: never
        self.tissue = None
        self.stream = cp.cuda.Stream()          # blocking: ordered with the default stream both ways
        self.pool = cp.cuda.MemoryPool()        # the graphs' temporaries, never lent to anything else
        self.counter = cp.zeros(1, dtype=cp.uint64)
        self.graphs = {}

    @classmethod
    def for_run(cls, simulation, steps, graphs, fused=None):
        """The runner for ``run(steps, graphs=..., fused=...)``: None where graphs are off (``graphs=None``:
        on the GPU for runs of at least MIN_STEPS steps on at most MAX_VERTICES vertices)."""
        return cls._for(simulation, steps, graphs, fused, why_not(simulation), "run")

    @classmethod
    def for_minimize(cls, simulation, max_steps, graphs, fused=None):
        """The runner for ``minimize(max_steps, graphs=..., fused=...)``: as :meth:`for_run`, and never
        with a writer attached (a writer sees the State between the move and the updaters)."""
        reason = why_not(simulation)
        if reason is None and simulation.operations.writers:
            reason = "a writer is attached (minimize writes between a move and the next updaters)"
        return cls._for(simulation, max_steps, graphs, fused, reason, "minimize")

    @classmethod
    def _for(cls, simulation, steps, graphs, fused, reason, what):
        if fused not in (None, False):
            raise ValueError(f"fused must be None (auto) or False, got {fused!r}")
        if graphs is False:
            return None
        minimizing = what == "minimize"
        if graphs is None:
            small = simulation.state.n_vertices <= MAX_VERTICES
            if reason is None and small and steps >= MIN_STEPS:
                return cls(simulation, False, minimizing, fused)
            return None
        if graphs is not True:
            raise ValueError(f"graphs must be None (auto), True or False, got {graphs!r}")
        if reason is not None:
            raise ValueError(f"{what}(graphs=True): {reason}")
        return cls(simulation, True, minimizing, fused)

    def stretch(self, done, steps, check_every):
        """How many steps to run before the host must look: the next check, the end of the run, or
        the next timestep at which a writer is due (evaluated ahead on the host)."""
        n = min(steps - done, check_every - done % check_every, self.max_stretch())
        t = self.sim.timestep
        writers = self.sim.operations.writers
        for i in range(1, n if writers else 1):
            if any(w.trigger(t + i) for w in writers):
                return i
        return n

    def max_stretch(self) -> int:
        """Most steps :meth:`advance` takes at once (the cell table's padding bounds it)."""
        return FUSED_STRETCH if self._fused_ready() else MAX_STRETCH

    def _ops(self):
        """The operations that run inside the steps (writers run between stretches)."""
        ops = self.sim.operations
        return [*ops.updaters, *ops.forces, ops.integrator]

    def _ready(self, steps):
        """Every operation's key for the next ``steps`` steps, or None (naming the one that refused)."""
        keys = []
        for op in self._ops():
            key = op.capture_ready(self.sim, steps)
            if key is None:
                return None, type(op).__name__
            keys.append((id(op), op.parameter_version, key))   # a parameter change: a new capture
        state = self.sim.state
        arrays = (state.positions, state.cell_vertices, state.cell_sides, state.vertex_neighbors,
                  state.vertex_cells, getattr(state, state.constraint.size_name))
        return (id(state), tuple(a.data.ptr for a in arrays), tuple(keys)), None

    def advance(self, steps) -> bool:
        """Run ``steps`` steps (at most :meth:`max_stretch`) through graphs; False (nothing run)
        where an operation cannot."""
        sim = self.sim
        if not self.minimizing and sim._updated_at == sim.timestep:   # the updaters ran at this timestep already
            self.pause()
            sim._update_once()
            sim._integrate()
            steps -= 1
        if steps == 0:
            return True
        key, refused = self._ready(steps)
        if key is None:
            self.pause()
            if self.required:
                what = "minimize" if self.minimizing else "run"
                raise ValueError(f"{what}(graphs=True): {refused} cannot run inside a CUDA graph now")
            return False
        if self._fused_ready():
            self.tissue.run(steps)
        else:
            steps = self._replay(key, steps)
        sim.timestep += steps
        integrator = sim.operations.integrator
        if isinstance(integrator, Minimizer):   # its iteration count, which its steps advance on the host
            integrator.iteration += steps
        if self.minimizing:          # the updaters of the last timestep ran, those not in_minimize held back
            sim._updated_at, sim._held_back = sim.timestep, True
        else:
            sim._updated_at, sim._held_back = sim.timestep - 1, False
        sim.state.topology_changed()
        sim.state_changed()
        return True

    def _fused_ready(self) -> bool:
        """Whether this stretch goes to the fused small-tissue steps (:mod:`spherevm.tissue_steps`)."""
        if self.fused is False or tissue_steps.why_not(self.sim, self.minimizing) is not None:
            return False
        if self.tissue is None:
            self.tissue = tissue_steps.TissueSteps(self.sim, FUSED_STRETCH, self.minimizing)
        return True

    def _replay(self, key, steps) -> int:
        """``steps`` steps as graph replays; a new key's first step runs at once (its timestep counted
        then), the graphs are captured, and the rest replayed: returns how many were replayed."""
        sim = self.sim
        self.counter.fill(sim.timestep)
        if key not in self.graphs:
            self._steps(1, capture=False)          # one step at once: builds caches, fills the pool
            steps -= 1
            self.graphs = {key: {k: self._steps(k, capture=True) for k in (GRAPH_STEPS, 1)}}
        big, rest = divmod(steps, GRAPH_STEPS)
        for k, repeats in ((GRAPH_STEPS, big), (1, rest)):
            for _ in range(repeats):
                self.graphs[key][k].launch(self.stream)
        return steps

    def _steps(self, k, capture):
        """``k`` steps in graph mode: run at once, or captured into a graph (returned; the host's
        timestep is then put back, the graph has not run yet)."""
        import cupy as cp
        sim = self.sim
        integrator = sim.operations.integrator
        t0, i0 = sim.timestep, integrator.iteration if isinstance(integrator, Minimizer) else None
        sim._step_counter = self.counter
        sim.state_changed()                  # the first step computes its forces inside the graph
        try:
            with cp.cuda.using_allocator(self.pool.malloc), self.stream:
                if capture:
                    self.stream.begin_capture()
                try:
                    for i in range(k):
                        sim._step_offset = i
                        if self.minimizing:   # the move, then the updaters of the next timestep
                            sim._integrate()
                            sim._step_offset = i + 1
                            sim._update(minimizing=True)
                        else:
                            sim._update()
                            sim._integrate()
                    self.counter += k
                except Exception as exc:
                    if not capture:
                        raise
                    _end_quietly(self.stream)
                    raise RuntimeError("capturing steps into a CUDA graph failed: an operation whose capture_ready "
                                       "said yes read something back or copied from the host; run(graphs=False) "
                                       "runs step by step") from exc
                graph = self.stream.end_capture() if capture else None
        finally:
            sim._step_counter, sim._step_offset = None, 0
            sim.state_changed()
        if capture:
            sim.timestep = t0
            if i0 is not None:
                integrator.iteration = i0
        return graph

    def pause(self):
        """Before the host looks at the State: each operation leaves it as the step-by-step path would."""
        for op in self._ops():
            op.capture_done(self.sim)

    def forget(self):
        """Drop the graphs (after user code ran: it may have changed what they hold)."""
        self.graphs = {}
