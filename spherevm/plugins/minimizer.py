"""Minimisers: integrators that lower the energy and keep per-replica convergence (FIRE is one)."""
from __future__ import annotations

import numpy as np

from ..validation import integer, non_negative
from .base import Integrator
from .parameters import Parameter
from .rows import saved_convergence


class Minimizer(Integrator):
    """An integrator that lowers the energy and keeps per-replica convergence (FIRE is one).

    HOOMD-style use: ``while not fire.done: sim.run(100)``, or ``sim.minimize()``. Per replica
    (NumPy): ``replica_converged``, ``reason`` ("force", "energy", an operation's ``halt_reason``,
    "running"), ``steps`` (-1 while running); ``converged`` and ``done`` for all. Subclasses
    implement :meth:`move` (one iteration) and :meth:`reset_motion`.

    Parameters
    ----------
    force_tol, energy_tol : float
        A replica stops when its largest vertex force, or its energy per cell, is below these, in
        its natural units (:meth:`tolerance_units`), or when an operation halts it.
    check_every : int
        Iterations between checks (:meth:`check_convergence`, one small read-back).
    trigger : Trigger or int, optional"""

    force_tol = Parameter(lambda name, value: float(non_negative(name, value, per_item="a scalar")))
    energy_tol = Parameter(lambda name, value: float(non_negative(name, value, per_item="a scalar")))
    check_every = Parameter(lambda name, value: integer(name, value, minimum=1))

    def __init__(self, force_tol=1e-10, energy_tol=1e-20, check_every=10, trigger=None):
        super().__init__(trigger)
        self.configure(force_tol=force_tol, energy_tol=energy_tol, check_every=check_every)

    _units = None    # (State, forces, energy unit, force unit) of the minimisation under way

    def configure(self, force_tol=None, energy_tol=None, check_every=None):
        """Set the stopping rules (None keeps one as it is); ``Simulation.minimize`` calls it first,
        so each minimisation works out its tolerance units afresh."""
        self._units = None
        for name, value in (("force_tol", force_tol), ("energy_tol", energy_tol), ("check_every", check_every)):
            if value is not None:
                setattr(self, name, value)

    def attach(self, simulation):
        super().attach(simulation)
        self.reset()

    def reset(self):
        """Start afresh: motion (velocities and the like) and convergence of every replica."""
        self.reset_motion()
        self.reset_convergence()

    def reset_motion(self):
        """Forget the dynamical memory of every replica (subclasses)."""

    def reset_convergence(self):
        """Every replica runs again; the iteration count restarts at 0."""
        n = self._simulation.state.n_replicas
        self.iteration = 0
        self.checked_at = None
        self.replica_converged = np.zeros(n, dtype=bool)
        self.stopped = np.zeros(n, dtype=bool)
        self.reason = np.full(n, "running", dtype=object)
        self.steps = np.full(n, -1, dtype=np.int64)
        self.set_active(None)

    per_replica = Integrator.per_replica + ("replica_converged", "stopped", "reason", "steps")

    def state_to_save(self) -> dict:
        """The convergence state (iteration, last check, per-replica flags, reasons, steps) plus the
        subclass's ``checkpoint_fields`` (FIRE: velocities, dt, alpha, counters)."""
        out = super().state_to_save()
        reason = "\n".join(str(r) for r in self.reason)
        out.update(iteration=np.array([self.iteration], dtype=np.int64),
                   checked_at=np.array([-1 if self.checked_at is None else self.checked_at], dtype=np.int64),
                   replica_converged=self.replica_converged.astype(np.uint8), stopped=self.stopped.astype(np.uint8),
                   steps=self.steps.copy(), active=self.active.astype(np.uint8),
                   reason=np.frombuffer(reason.encode("utf-8"), dtype=np.uint8).copy())
        return out

    def restore_state(self, data: dict):
        super().restore_state(data)
        saved = saved_convergence(self, data, self._simulation.state.n_replicas)
        self.iteration = saved["iteration"]
        self.checked_at = None if saved["checked_at"] < 0 else saved["checked_at"]
        self.replica_converged, self.stopped = saved["replica_converged"], saved["stopped"]
        self.steps, self.reason = saved["steps"], saved["reason"]
        self.set_active(saved["active"])

    @property
    def converged(self) -> bool:
        return bool(self.replica_converged.all())

    @property
    def done(self) -> bool:
        return bool(self.stopped.all())

    @staticmethod
    def tolerance_units(simulation):
        """The units of ``energy_tol`` and ``force_tol`` per replica (NumPy): the largest
        :meth:`Force.energy_scale` of the forces (1 if none, or 0) and that over sqrt(<A>)."""
        state = simulation.state
        scales = [s for s in (f.energy_scale(state) for f in simulation.operations.forces) if s is not None]
        energy = np.max(scales, axis=0) if scales else np.ones(state.n_replicas)
        energy = np.where(np.isfinite(energy) & (energy > 0), energy, 1.0)
        return energy, energy / np.sqrt(state.mean_cell_area)

    def check_convergence(self, simulation):
        """Stop the replicas that reached a tolerance now, or that an operation halts."""
        self.checked_at = self.iteration
        state = simulation.state
        fmax, energy = simulation.replica_summary()[:2]     # one read-back
        epc = energy / state.cells_per_replica
        forces = tuple(simulation.operations.forces)
        if self._units is None or self._units[0] is not state or self._units[1] != forces:
            self._units = (state, forces, *self.tolerance_units(simulation))   # once per minimisation, State, forces
        energy_unit, force_unit = self._units[2:]
        running = ~self.stopped
        by_force = running & (fmax < self.force_tol * force_unit)
        by_energy = running & ~by_force & (epc < self.energy_tol * energy_unit)
        self.reason[by_force], self.reason[by_energy] = "force", "energy"
        newly = by_force | by_energy
        for op in simulation.operations:
            halted = op.halted()
            if halted is not None:
                stop = ~self.stopped & ~newly & np.asarray(halted, dtype=bool)
                self.reason[stop] = op.halt_reason
                self.steps[stop] = self.iteration
                self.stopped[stop] = True
        self.steps[newly] = self.iteration
        self.stopped[newly] = True
        self.replica_converged[newly] = True
        self.set_active(~self.stopped)

    def check_due(self) -> bool:
        return self.iteration % self.check_every == 0 and self.checked_at != self.iteration

    def steps_to_check(self) -> int:
        """Iterations that can run before the next convergence check falls due."""
        if self.check_due():
            return 0
        return self.check_every - self.iteration % self.check_every

    def step(self, simulation, forces):
        if not simulation.capturing and self.check_due():   # inside CUDA graphs checks fall between stretches
            self.check_convergence(simulation)
            forces, _ = simulation.compute_forces()
        self.move(simulation, forces)
        self.iteration += 1

    def move(self, simulation, forces):
        raise NotImplementedError
