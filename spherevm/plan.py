"""The plan of a step: the order of a run's step and of a minimisation's iteration, written once.

``Simulation.run`` and ``Simulation.minimize`` build a :class:`Plan` from the operations present
and hand it to an executor, which carries it out:

* step by step on the host (:meth:`Plan.cycle`, once per step);
* CUDA graphs (:mod:`spherevm.graphs`): the same :meth:`Plan.cycle` captured once and replayed;
* fused small-tissue steps (:mod:`spherevm.tissue_steps`): one kernel runs many cycles, assembled
  from the operations' fused stages (:meth:`spherevm.plugins.base.Operation.fused_stage`); the
  kernel is chosen by :attr:`Plan.device_cycle`, the order it must keep.

A step is a sequence of phases. The device phases (updaters; forces, integrator and the timestep's
advance) run wherever the executor runs them; the host phases (checks, writers) run on the host
between two stretches of device phases. :meth:`Plan.explain` says which executor runs each
operation, and why.
"""
from __future__ import annotations

#: A run's step: the updaters due, the forces and the integrator, then (on the host) the checks
#: every ``check_every`` steps and the writers due.
RUN = ("update", "integrate", "check", "write")
#: A minimisation's iteration: the updaters that take part, the convergence check when due, the
#: move, the writers.
MINIMIZE = ("update", "check", "integrate", "write")
#: Phases that run on the host between stretches of steps.
HOST_PHASES = ("check", "write")


class DeviceClock:
    """The timestep as kernels take it while steps are captured into CUDA graphs: a device
    ``counter`` that each replay advances by the graph's length, plus each step's place in the graph
    (``Simulation.timestep - start``)."""

    def __init__(self, counter, start: int):
        self.counter = counter
        self.start = int(start)


class Plan:
    """The order of one ``run`` step or ``minimize`` iteration, built from the operations present.

    Parameters
    ----------
    simulation : spherevm.Simulation
        Whose operations the plan orders.
    minimizing : bool
        A minimisation's iteration (updaters with ``in_minimize`` False held back) instead of a
        run's step.
    """

    def __init__(self, simulation, minimizing: bool = False):
        self.simulation = simulation
        self.minimizing = bool(minimizing)
        self.phases = MINIMIZE if minimizing else RUN
        ops = simulation.operations
        self.updaters = tuple(u for u in ops.updaters if u.in_minimize or not minimizing)
        self.forces = tuple(ops.forces)
        self.integrator = ops.integrator
        self.writers = tuple(ops.writers)

    @property
    def device_cycle(self) -> tuple:
        """The device phases between two looks of the host, in order: a stretch starts right after a
        check (run: ``("update", "integrate")``; minimize: ``("integrate", "update")``)."""
        at = self.phases.index("check") + 1
        rotated = self.phases[at:] + self.phases[:at]
        return tuple(p for p in rotated if p not in HOST_PHASES)

    def device_operations(self) -> list:
        """The operations that run inside a stretch of device phases (writers run between them)."""
        return [*self.updaters, *self.forces, self.integrator]

    def cycle(self):
        """One pass of :attr:`device_cycle` on the host (step by step, or captured into a graph)."""
        sim = self.simulation
        for phase in self.device_cycle:
            if phase == "update":
                sim.update(minimizing=self.minimizing)
            else:
                sim.integrate()

    def explain(self, graphs_reason=None, fused_reason=None) -> str:
        """Which executor runs each operation, and why, as lines of text.

        Parameters
        ----------
        graphs_reason : str or None
            Why CUDA graphs cannot run the steps (None: they can).
        fused_reason : str or None
            Why the fused small-tissue steps cannot (None: they can).

        Returns
        -------
        str
            The step's order, then one line per operation.
        """
        what = "minimize iteration" if self.minimizing else "run step"
        lines = [f"{what}: " + " -> ".join(self.phases)]
        if fused_reason is None:
            executor, why = "fused", "every operation has a fused stage"
        elif graphs_reason is None:
            executor, why = "CUDA graphs", f"not fused: {fused_reason}"
        else:
            executor, why = "step by step", f"no CUDA graphs: {graphs_reason}"
        for op in self.device_operations():
            lines.append(f"  {type(op).__name__:<16} {executor:<13} ({why})")
        for op in self.writers:
            lines.append(f"  {type(op).__name__:<16} {'host':<13} (writers run between stretches)")
        return "\n".join(lines)
