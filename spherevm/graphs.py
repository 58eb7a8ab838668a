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

import logging

from . import tissue_steps
from .plan import DeviceClock, Plan
from .plugins.base import Operation
from .plugins.minimizer import Minimizer
from .trigger import Always, Periodic

log = logging.getLogger("spherevm")

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


def why_not(simulation, minimizing: bool = False, steps=None) -> str | None:
    """Why CUDA graphs cannot run ``simulation``'s next steps of ``run`` (or of ``minimize``:
    ``minimizing``) now: None if they can, as far as triggers and the operations' kinds tell (each
    operation's :meth:`~spherevm.plugins.base.Operation.capture_ready` is asked when the first
    stretch starts). ``steps``: the length of the run, for the auto mode's rules."""
    plan = Plan(simulation, minimizing)
    if not simulation.device.is_gpu:
        return "CUDA graphs need the GPU; this Simulation runs on the CPU"
    for op in [*plan.updaters, plan.integrator]:
        if not _every_step(op.trigger, simulation.timestep):
            return (f"{type(op).__name__} runs on a trigger ({op.trigger!r}) that does not fire every step; a graph "
                    "replays the same steps")
    for op in plan.device_operations():
        if type(op).capture_ready is Operation.capture_ready:
            return f"{type(op).__name__} has no capture_ready (it cannot run inside a CUDA graph)"
    if plan.minimizing and plan.writers:
        return "a writer is attached (minimize writes between a move and the next updaters)"
    if steps is not None and steps < MIN_STEPS:   # auto mode's rules
        return f"the run has {steps} steps, fewer than graphs.MIN_STEPS = {MIN_STEPS} (a capture costs about ten)"
    if steps is not None and simulation.state.n_vertices > MAX_VERTICES:
        return f"the State has more than graphs.MAX_VERTICES = {MAX_VERTICES} vertices"
    return None


class StepGraphs:
    """The CUDA graphs of one ``Simulation.run`` or ``minimize``: ``advance(n)`` runs n cycles of the
    plan (a stretch between checks and writes) as replays, or as one launch of the fused steps;
    ``pause()`` before anything on the host looks at the State."""

    def __init__(self, plan, required: bool, fused=None):
        import cupy as cp
        self.plan, self.sim, self.required = plan, plan.simulation, required
        self.minimizing = plan.minimizing
        self.fused = fused          # None: the fused small-tissue steps where they can run; True: must; False: never
        self.tissue = None
        self.stream = cp.cuda.Stream()          # blocking: ordered with the default stream both ways
        self.pool = cp.cuda.MemoryPool()        # the graphs' temporaries, never lent to anything else
        self.counter = cp.zeros(1, dtype=cp.uint64)
        self.graphs = {}
        self._fell_back = False

    @classmethod
    def reasons(cls, plan, steps):
        """``(why not CUDA graphs, why not fused)`` for ``plan`` and a run of ``steps`` (None: they
        can); :meth:`spherevm.plan.Plan.explain` words them."""
        graphs = why_not(plan.simulation, plan.minimizing, steps)
        fused = graphs if graphs is not None else tissue_steps.why_not(plan.simulation, plan.minimizing)
        return graphs, fused

    @classmethod
    def for_run(cls, plan, steps, graphs, fused=None):
        """The runner for ``run(steps, graphs=..., fused=...)``: None where graphs are off (``graphs=None``:
        on the GPU for runs of at least MIN_STEPS steps on at most MAX_VERTICES vertices)."""
        return cls._for(plan, steps, graphs, fused, "run")

    @classmethod
    def for_minimize(cls, plan, max_steps, graphs, fused=None):
        """The runner for ``minimize(max_steps, graphs=..., fused=...)``: as :meth:`for_run`, and never
        with a writer attached (a writer sees the State between the move and the updaters)."""
        return cls._for(plan, max_steps, graphs, fused, "minimize")

    @classmethod
    def _for(cls, plan, steps, graphs, fused, what):
        if fused not in (None, True, False):
            raise ValueError(f"fused must be None (auto), True or False, got {fused!r}")
        if graphs not in (None, True, False):
            raise ValueError(f"graphs must be None (auto), True or False, got {graphs!r}")
        if fused is True:
            if graphs is False:
                raise ValueError(f"{what}(fused=True, graphs=False): the fused steps run in the graphs' stretches")
            reason = why_not(plan.simulation, plan.minimizing) or tissue_steps.why_not(plan.simulation, plan.minimizing)
            if reason is not None:
                raise ValueError(f"{what}(fused=True): {reason}")
            return cls(plan, True, fused)
        if graphs is False:
            return None
        reason = why_not(plan.simulation, plan.minimizing, steps if graphs is None else None)
        if graphs is True and reason is not None:
            raise ValueError(f"{what}(graphs=True): {reason}")
        if reason is not None:
            if plan.simulation.device.is_gpu:
                log.debug("%s runs step by step: %s", what, reason)
            return None
        return cls(plan, graphs is True, fused)

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

    def _ready(self, steps):
        """Every operation's key for the next ``steps`` steps, or None (naming the one that refused)."""
        keys = []
        for op in self.plan.device_operations():
            key = op.capture_ready(self.sim, steps)
            if key is None:
                return None, type(op).__name__
            keys.append((id(op), op.parameter_version, key))   # a parameter change: a new capture
        state = self.sim.state
        arrays = (state.positions, state.cell_vertices, state.cell_sides, state.vertex_neighbors,
                  state.vertex_cells, state.size)
        return (id(state), tuple(a.data.ptr for a in arrays), tuple(keys)), None

    def advance(self, steps) -> bool:
        """Run ``steps`` cycles of the plan (at most :meth:`max_stretch`) through graphs or the fused
        steps; False (nothing run) where an operation cannot."""
        sim = self.sim
        if not self.minimizing and sim.updated_now():   # the updaters ran at this timestep already
            self.pause()
            self.plan.cycle()
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
        sim.advanced(steps, self.minimizing)
        return True

    def _fused_ready(self) -> bool:
        """Whether this stretch goes to the fused small-tissue steps (:mod:`spherevm.tissue_steps`);
        a fall-back from them is logged once."""
        if self.fused is False:
            return False
        reason = tissue_steps.reason(self.plan)
        if reason is not None:
            if self.fused is True:
                raise ValueError(f"{'minimize' if self.minimizing else 'run'}(fused=True): {reason}")
            if not self._fell_back:
                log.info("not fused (CUDA graphs of the general kernels instead): %s", reason)
                self._fell_back = True
            return False
        if self.tissue is None:
            self.tissue = tissue_steps.TissueSteps(self.plan, FUSED_STRETCH)
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
        """``k`` cycles of the plan in graph mode: run at once, or captured into a graph (returned;
        the host's timestep is then put back, the graph has not run yet)."""
        import cupy as cp
        sim = self.sim
        integrator = sim.operations.integrator
        t0, i0 = sim.timestep, integrator.iteration if isinstance(integrator, Minimizer) else None
        sim.device_clock = DeviceClock(self.counter, t0)
        sim.state_changed()                  # the first step computes its forces inside the graph
        try:
            with cp.cuda.using_allocator(self.pool.malloc), self.stream:
                if capture:
                    self.stream.begin_capture()
                try:
                    for _ in range(k):
                        self.plan.cycle()
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
            sim.device_clock = None
            sim.state_changed()
        if capture:
            sim.timestep = t0
            if i0 is not None:
                integrator.iteration = i0
        return graph

    def pause(self):
        """Before the host looks at the State: each operation leaves it as the step-by-step path would."""
        for op in self.plan.device_operations():
            op.capture_done(self.sim)

    def forget(self):
        """Drop the graphs (after user code ran: it may have changed what they hold)."""
        self.graphs = {}
