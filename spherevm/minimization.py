"""A minimisation's iterations on the host, in the plan's order, and its outcome.

:class:`Minimization` carries out a minimisation's :class:`~spherevm.plan.Plan` (update, check,
integrate, write): the convergence check (every ``check_every`` iterations and at the limit), the
narrowing to the replicas still running, and, between two checks, the stretch of iterations that
an executor on the device (:class:`spherevm.graphs.StepGraphs`) runs where it can.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass
class MinimizeResult:
    """Outcome of :meth:`Simulation.minimize`, one entry per replica (NumPy arrays).

    Parameters
    ----------
    converged, reason, energy, energy_per_cell, max_force, steps, mean_shape_index : numpy.ndarray"""
    converged: np.ndarray
    reason: np.ndarray          # "force", "energy", "max_steps" or an operation's halt reason
    energy: np.ndarray          # total energy per replica
    energy_per_cell: np.ndarray
    max_force: np.ndarray
    steps: np.ndarray
    mean_shape_index: np.ndarray = field(default=None)

    @property
    def all_converged(self) -> bool:
        return bool(np.all(self.converged))

    def table(self) -> str:
        """A plain-text table, one row per replica.

        Returns
        -------
        str"""
        rows = ["replica   energy/cell  <P/sqrt(A)>     max|F|  converged  reason          steps"]
        for r in range(len(self.converged)):
            rows.append(f"{r:7d}  {self.energy_per_cell[r]:12.6e}  {self.mean_shape_index[r]:11.6f}  "
                        f"{self.max_force[r]:9.3e}  {'yes' if self.converged[r] else 'no':9s}  "
                        f"{self.reason[r]:14s}  {int(self.steps[r]):5d}")
        return "\n".join(rows)


class Minimization:
    """The iterations of one ``Simulation.minimize``, phase by phase as the plan orders them.

    Parameters
    ----------
    plan : spherevm.plan.Plan
        The minimisation's plan (``minimizing=True``).
    runner : spherevm.graphs.StepGraphs or None
        Runs the iterations between two checks on the device, where it can (None: the host does).
    limit : int
        The minimiser's iteration count at which to stop.
    narrow : bool
        Step only the running replicas once at most half still run.
    progress : callable or None
        ``progress(iteration, n_done, n_replicas)`` at every check.
    """

    def __init__(self, plan, runner, limit: int, narrow: bool, progress=None):
        self.plan, self.runner, self.limit, self.narrow, self.progress = plan, runner, limit, narrow, progress
        self.sim = plan.simulation
        self.n_replicas = self.sim.state.n_replicas   # progress counts over all, narrowed or not
        self.narrowed = []

    def run(self):
        """Iterate until every replica stopped or the limit; the Simulation's State and operations
        are whole again at the end (also after an error)."""
        sim = self.sim
        try:
            while self._iterate():
                pass
        finally:
            if self.runner is not None:
                self.runner.pause()
            while self.narrowed:
                sim.widen(*self.narrowed.pop())
            for u in sim.operations.updaters:
                if not u.in_minimize:
                    u.after_minimize(sim)

    def _iterate(self) -> bool:
        """One pass over the plan's phases (or a stretch on the device after a check); False once
        the minimisation is over."""
        sim = self.sim
        for phase in self.plan.phases:
            if phase == "update":
                sim.update(minimizing=True)
            elif phase == "check":
                if not self._check():
                    return False
                if self.runner is not None:   # the iterations up to the next check (or the limit) on the device
                    fire = sim.operations.integrator
                    if self.runner.advance(min(fire.steps_to_check(), self.limit - fire.iteration,
                                               self.runner.max_stretch())):
                        return True
                    self.runner = None        # an operation cannot: step by step from here
            elif phase == "integrate":
                sim.integrate()
            else:
                sim.write()
        return True

    def _check(self) -> bool:
        """The convergence check when due (and at the limit), the finite check, progress and
        narrowing after it; False once every replica stopped or the limit is reached."""
        sim = self.sim
        fire = sim.operations.integrator
        if fire.check_due() or (fire.iteration >= self.limit and fire.checked_at != fire.iteration):
            fire.check_convergence(sim)
        if fire.checked_at != fire.iteration:
            return True
        sim.check_finite()   # NaN, or an exploding step the GPU kernel flagged
        running = int((~fire.stopped).sum())
        if self.progress is not None:
            if self.runner is not None:
                self.runner.pause()
            self.progress(fire.iteration, self.n_replicas - running, self.n_replicas)
        if running == 0 or fire.iteration >= self.limit:
            return False
        if self.narrow and 2 * running <= len(fire.stopped):
            if self.runner is not None:
                self.runner.pause()
            self.narrowed.append(sim.narrow(np.flatnonzero(~fire.stopped)))
        return True
