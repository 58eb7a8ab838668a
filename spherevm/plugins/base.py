"""The four kinds of operation. Built-in plugins derive from these exactly as a user's would."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..trigger import Always, as_trigger
from ..validation import integer, non_negative
from .rows import _host, _index_like, _restored, follow_rows, saved_convergence


class Operation:
    """Something the Simulation runs: it has a trigger and may publish loggable quantities.

    ``loggables`` maps a quantity name to a callable ``f(simulation)`` returning a scalar or a
    per-replica array; writers and ``Simulation.log`` find them by name.

    Device and surface (HOOMD picks its C++ class at attach; so do we): an operation with a NumPy
    and a CUDA implementation names them ``_<name>_cpu`` and ``_<name>_gpu`` and binds one with
    :meth:`implementation` when it attaches, never branching on the device per call. The NumPy
    path measures everything through the constraint, so it serves every surface whose constraint
    implements what it calls; a CUDA path compiled for some surfaces lists their constraint
    classes in ``gpu_surfaces``, and attaching it to a State on another surface raises.
    """

    #: Constraint classes the GPU implementation supports (None: every surface).
    gpu_surfaces = None
    #: Constraint methods this operation calls; a surface lacking one is refused at attach.
    surface_needs = ()

    def __init__(self, trigger=None):
        self.trigger = Always() if trigger is None else as_trigger(trigger)
        self._simulation = None

    def attach(self, simulation):
        """Called when the operation joins a Simulation whose State is set."""
        simulation.state.constraint.require(self.surface_needs, type(self).__name__)
        self._simulation = simulation

    def detach(self):
        self._simulation = None

    def implementation(self, name, state):
        """The bound method ``_<name>_cpu`` or ``_<name>_gpu`` serving ``state``'s device, looked
        up once per device and surface. Raises ValueError if the GPU path does not support
        ``state.constraint`` (naming both)."""
        key = (name, state.device.name, type(state.constraint))
        bound = self.__dict__.setdefault("_bound", {})
        if key not in bound:
            supported = self.gpu_surfaces
            if state.device.is_gpu and supported is not None and not isinstance(state.constraint, supported):
                names = ", ".join(c.__name__ for c in supported)
                raise ValueError(f"{type(self).__name__} on the GPU supports {names} surfaces only, but the "
                                 f"state is on {state.constraint!r}; use device='cpu' for this surface")
            bound[key] = getattr(self, f"_{name}_{state.device.name}")
        return bound[key]

    @property
    def loggables(self) -> dict:
        return {}

    # Checkpoints (exact restart): an operation whose future depends on data it keeps (velocities,
    # directors, counters) lists the attributes holding it in ``checkpoint_fields``, or overrides
    # :meth:`state_to_save` and :meth:`restore_state`. The GSD writer stores what state_to_save
    # returns in every frame (``spherevm/op/<key>/<field>``, ``key`` from :meth:`checkpoint_key`);
    # ``Simulation.create_state_from_gsd`` keeps it pending and hands each operation its entry
    # right after it attaches, so the run goes on bitwise as if never interrupted.
    checkpoint_fields = ()
    #: explicit checkpoint key (None: ``<list>.<position>.<ClassName>``, "integrator.<ClassName>")
    name = None

    def checkpoint_key(self, where: str) -> str:
        """The stable key of this operation's saved state; ``where`` is "integrator" or
        "<forces|updaters|writers>.<position>"."""
        return self.name if self.name is not None else f"{where}.{type(self).__name__}"

    def state_to_save(self) -> dict:
        """``{field: NumPy array}``: everything that affects this operation's future (host copies;
        per-vertex and per-cell rows in the State's order). Default: the ``checkpoint_fields``."""
        return {name: _host(getattr(self, name)) for name in self.checkpoint_fields}

    def restore_state(self, data: dict):
        """Take back what :meth:`state_to_save` returned (called right after :meth:`attach`, so the
        attributes exist with the right shapes, on the State's device). Default: each of the
        ``checkpoint_fields``, checked against the shape of the attribute it replaces."""
        for name in self.checkpoint_fields:
            setattr(self, name, _restored(self, name, data))

    halt_reason = "halted"

    def halted(self):
        """Per-replica bool mask of replicas this operation wants stopped (``minimize`` honours it), or None."""
        return None

    def reset_halted(self):
        """Forget what made replicas halt (called when a minimisation starts)."""

    # Narrowing: Simulation.minimize steps only the replicas still running once at most half are
    # (finished ones cost nothing more). It may do so only if every operation says it can: an
    # operation that keeps per-replica, per-vertex or per-cell data sets ``narrowable = True`` and
    # lists the attributes holding one row per replica, vertex or cell (NumPy or device arrays) in
    # ``per_replica``, ``per_vertex`` and ``per_cell``: the default narrow() and widen() follow
    # them. One with other data overrides both; one that keeps none just sets ``narrowable = True``.
    narrowable = False
    per_replica = ()
    per_vertex = ()
    per_cell = ()

    def _rows(self):
        return [(name, "replicas") for name in self.per_replica] + \
            [(name, "vertices") for name in self.per_vertex] + [(name, "cells") for name in self.per_cell]

    def narrow(self, selection):
        """The Simulation now steps only ``selection`` (a :class:`spherevm.state.ReplicaSelection`
        of the State it stepped so far): keep the rows of those replicas, and return what
        :meth:`widen` needs to restore the others."""
        saved = {}
        for name, axis in self._rows():
            full = getattr(self, name)
            saved[name] = full
            setattr(self, name, full[_index_like(full, getattr(selection, axis))])
        return saved

    def widen(self, selection, saved):
        """Undo :meth:`narrow`: merge the current rows of the selected replicas into ``saved`` and
        go back to it (the Simulation steps the wider State again)."""
        for name, axis in self._rows():
            full = saved[name]
            full[_index_like(full, getattr(selection, axis))] = getattr(self, name)
            setattr(self, name, full)

    # CUDA graphs (spherevm.graphs): on the GPU, Simulation.run captures a stretch of steps once and
    # replays it, when every operation that runs in those steps is ready for it.
    def capture_ready(self, simulation, steps):
        """Prepare to run the next ``steps`` steps inside a CUDA graph, and return a key (hashable:
        what the captured launches depend on beyond the State's arrays; a new key means a new
        capture), or None where this operation cannot: it reads something back each step, or
        passes its kernels host values that change from step to step (a timestep goes through
        ``Simulation.kernel_timestep``). Default: None."""
        return None

    def capture_done(self, simulation):
        """Steps in graphs pause here (a writer, a callback or the end of the run follows): leave
        what the host sees as the step-by-step path would."""

    def resized(self, change):
        """The State gained or lost cells and vertices (:mod:`spherevm.growth`; ``change`` is a
        :class:`spherevm.growth.Change`). The default makes the ``per_cell`` and ``per_vertex``
        arrays follow their rows (see :func:`follow_rows`); one with other per-cell or per-vertex
        data overrides it."""
        follow_rows(self, change)


@dataclass
class ForceResult:
    """What a Force computes: ``forces (V, 3)`` on the device and ``energy`` per replica."""
    forces: object
    energy: object
    cell_energy: object = None


class Force(Operation):
    """A contribution to the potential energy; subclasses implement :meth:`compute`.

    ``compute(state)`` returns a :class:`ForceResult` whose forces are minus the surface
    (tangent-plane) gradient of the energy, on the state's device. Forces are evaluated whenever
    the integrator needs them; their trigger is not used.
    """

    def compute(self, state) -> ForceResult:
        raise NotImplementedError

    def energy_scale(self, state):
        """This force's natural energy per cell per replica (NumPy), or None (the default): a
        :class:`Minimizer` measures its tolerances in the largest scale its forces declare."""
        return None

    def combined(self, other, state):
        """A :class:`ForceResult` of this force and ``other`` together (forces, energies and cell
        energies summed), where this force computes the pair in fewer passes than the two apart;
        None (the default) otherwise. :func:`compute_all` asks each pair of attached forces, both
        ways round."""
        return None

    def energy(self, state):
        """Energy per replica, as a NumPy array."""
        return state.device.to_numpy(self.compute(state).energy)

    def forces(self, state):
        """Forces ``(n_vertices, 3)``, as a NumPy array."""
        return state.device.to_numpy(self.compute(state).forces)


def compute_all(forces, state):
    """The :class:`ForceResult` of each of ``forces`` on ``state``, in order, except that a pair one
    of which computes both together (:meth:`Force.combined`) gives one result for the two."""
    left, results = list(forces), []
    while left:
        force = left.pop(0)
        for i, other in enumerate(left):
            result = force.combined(other, state)
            result = other.combined(force, state) if result is None else result
            if result is not None:
                del left[i]
                break
        else:
            result = force.compute(state)
        results.append(result)
    return results


class Integrator(Operation):
    """Moves the vertices one step: ``step(simulation, forces)`` with the summed forces.

    ``check(simulation)`` is called every few steps (where the GPU path reads back error flags)
    and raises if the integration went wrong.

    The contract other operations rely on:

    * ``active``: per-replica bool mask (NumPy) of the replicas this integrator still moves; a
      minimiser stops the replicas that have converged. Updaters act on active replicas only.
      ``active_on_device()`` is the same mask on the State's device, uploaded once per change.
    * ``reset_vertices(vertices)``: forget the per-vertex dynamical memory (velocities, say) of the
      given vertices, after an updater changed the topology around them; ``vertices`` is an index
      array on the State's device, negative entries are ignored. The default keeps nothing.
    """

    def attach(self, simulation):
        super().attach(simulation)
        self.set_active(None)

    per_replica = ("active",)

    def narrow(self, selection):
        saved = super().narrow(selection)
        self._active_device = None
        return saved

    def widen(self, selection, saved):
        super().widen(selection, saved)
        self._active_device = None

    def set_active(self, mask):
        """Move only the replicas where ``mask`` is true (None: every replica)."""
        state = self._simulation.state
        n = state.n_replicas
        active = np.ones(n, dtype=bool) if mask is None else np.array(mask, dtype=bool).reshape(-1)
        if len(active) != n:
            raise ValueError(f"active mask has {len(active)} entries, but the state has {n} replicas")
        self.active = active
        self._active_device = None

    def active_on_device(self):
        """``active`` on the State's device (uploaded at most once per change, into the same device
        array while the replica count stays: CUDA graphs hold its address)."""
        if self._active_device is None:
            held = getattr(self, "_active_held", None)
            if self._simulation.state.device.is_gpu and held is not None and held.shape == self.active.shape:
                held.set(self.active)
            else:
                held = self._active_held = self._simulation.state.device.asarray(self.active)
            self._active_device = held
        return self._active_device

    def reset_vertices(self, vertices):
        """Forget per-vertex memory of ``vertices`` (device index array; negative entries ignored)."""

    def step(self, simulation, forces):
        raise NotImplementedError

    def check(self, simulation):
        pass


def raise_flagged_step(error, simulation, message):
    """Read the GPU kernels' error word (``step << 32 | vertex``, all ones when nothing happened;
    one small read-back) and raise FloatingPointError with ``message(step, replica, vertex)``."""
    if error is None:
        return
    code = int(error.get()[0])
    if code != np.iinfo(np.uint64).max:
        step, v = code >> 32, code & 0xFFFFFFFF
        raise FloatingPointError(message(step, int(simulation.state.vertex_replica_np()[v]), v))


class Minimizer(Integrator):
    """An integrator that lowers the energy and keeps per-replica convergence (FIRE is one).

    Every ``check_every`` steps (one small read-back) :meth:`check_convergence` stops, per replica,
    the replicas whose largest vertex force is below ``force_tol`` or whose energy per cell is
    below ``energy_tol`` (in the replica's natural units, :meth:`tolerance_units`: the same shape
    at any size), and those that an operation halts (:meth:`Operation.halted`); the others go on.
    HOOMD-style use: ``while not fire.done: sim.run(100)``, or ``sim.minimize()``.

    Per replica (NumPy): ``replica_converged``, ``reason`` ("force", "energy", an operation's
    ``halt_reason``, or "running"), ``steps`` (the iteration at which it stopped, -1 while running).
    ``converged``: every replica reached a tolerance; ``done``: every replica stopped.
    Subclasses implement :meth:`move` (one iteration) and :meth:`reset_motion`.
    """

    def __init__(self, force_tol=1e-10, energy_tol=1e-20, check_every=10, trigger=None):
        super().__init__(trigger)
        self.configure(force_tol=force_tol, energy_tol=energy_tol, check_every=check_every)

    _units = None    # (State, forces, energy unit, force unit) of the minimisation under way

    def configure(self, force_tol=None, energy_tol=None, check_every=None):
        """Set the stopping rules (None keeps one as it is); ``Simulation.minimize`` calls it first,
        so each minimisation works out its tolerance units afresh."""
        self._units = None
        if force_tol is not None:
            self.force_tol = float(non_negative("force_tol", force_tol, per_item="a scalar"))
        if energy_tol is not None:
            self.energy_tol = float(non_negative("energy_tol", energy_tol, per_item="a scalar"))
        if check_every is not None:
            self.check_every = integer("check_every", check_every, minimum=1)

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
        self._checked_at = None
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
                   checked_at=np.array([-1 if self._checked_at is None else self._checked_at], dtype=np.int64),
                   replica_converged=self.replica_converged.astype(np.uint8), stopped=self.stopped.astype(np.uint8),
                   steps=self.steps.copy(), active=self.active.astype(np.uint8),
                   reason=np.frombuffer(reason.encode("utf-8"), dtype=np.uint8).copy())
        return out

    def restore_state(self, data: dict):
        super().restore_state(data)
        saved = saved_convergence(self, data, self._simulation.state.n_replicas)
        self.iteration = saved["iteration"]
        self._checked_at = None if saved["checked_at"] < 0 else saved["checked_at"]
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
        self._checked_at = self.iteration
        state = simulation.state
        fmax, energy, _ = simulation.replica_summary()     # one read-back
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
        return self.iteration % self.check_every == 0 and self._checked_at != self.iteration

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


class Updater(Operation):
    """Changes the state between steps (for example the topology): ``update(simulation, timestep)``.

    ``in_minimize``: whether ``Simulation.minimize`` runs it (T1: yes). The growth updaters
    (Division, Extrusion, RadiusSchedule) sit minimisations out: a quench finds the inherent state
    of the tissue as it is (its N and R); a later ``run`` goes on with them, and
    :meth:`after_minimize` tells them a minimisation passed.
    """

    in_minimize = True

    def update(self, simulation, timestep):
        raise NotImplementedError

    def after_minimize(self, simulation):
        """A ``Simulation.minimize`` that this updater sat out (``in_minimize`` False) has ended."""


class Writer(Operation):
    """Records the simulation: ``write(simulation, timestep)``; ``close()`` at the end.

    ``final = True`` asks for one more ``write`` at the end of every ``run`` and ``minimize`` (at
    the timestep they end on, unless the trigger already wrote it), so the last record is the
    final state; the GSD writer sets it by default.
    """

    final = False

    def write(self, simulation, timestep):
        raise NotImplementedError

    def close(self):
        pass

