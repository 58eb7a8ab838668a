"""The four kinds of operation. Built-in plugins derive from these exactly as a user's would."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..trigger import Always, as_trigger
from ..validation import KeywordHints
from .parameters import Parameter, parameter_names
from .rows import _host, _index_like, _restored, follow_rows


class Operation(KeywordHints):
    """Something the Simulation runs: it has a trigger and may publish loggable quantities.

    ``loggables`` maps a name to a callable ``f(simulation)`` returning a scalar or a per-replica
    array. An operation with a NumPy and a CUDA implementation names them ``_<name>_cpu`` and
    ``_<name>_gpu`` and binds one with :meth:`implementation` at attach (as HOOMD picks its C++
    class), never branching per call; a CUDA path lists the constraint classes it was compiled for
    in ``gpu_surfaces``, and attaching it to a State on another surface raises.

    Parameters
    ----------
    trigger : Trigger or int, optional
        The timesteps it runs on (an int: ``Periodic(int)``; default every step)."""

    #: Constraint classes the GPU implementation supports (None: every surface).
    gpu_surfaces = None
    #: Constraint methods this operation calls; a surface lacking one is refused at attach.
    surface_needs = ()

    # Parameters (spherevm.plugins.parameters): each public parameter is a class attribute
    # ``name = Parameter(check)``; an assignment is checked, and a change after attach takes effect at
    # the next step (``parameter_version`` advances: the State's cache entries keyed by this operation
    # and the CUDA graphs holding its kernels are renewed; ``parameters_changed`` runs).
    trigger = Parameter(lambda name, value: Always() if value is None else as_trigger(value))
    #: advances at every parameter change (see spherevm.plugins.parameters)
    parameter_version = 0

    def __init__(self, trigger=None):
        self.trigger = trigger
        self._simulation = None

    @classmethod
    def parameter_names(cls) -> tuple:
        """The names of this operation's public parameters (its :class:`Parameter` attributes)."""
        return parameter_names(cls)

    def check_parameters(self):
        """Raise ValueError if the parameters together are inconsistent (each was checked alone
        already); called after every assignment, once all are set. Default: nothing to check."""

    def parameters_changed(self, name):
        """Parameter ``name`` has a new value (called after every accepted assignment once all
        parameters are set, attached or not): bring derived data in line. Caches kept with
        ``State.cached`` under a key starting with this operation renew by themselves."""

    def attach(self, simulation):
        """Called when the operation joins a Simulation whose State is set."""
        simulation.state.constraint.require(self.surface_needs, type(self).__name__)
        self._simulation = simulation

    def detach(self):
        self._simulation = None

    def implementation(self, name, state):
        """``_<name>_cpu`` or ``_<name>_gpu``, bound, for ``state``'s device, looked up once (ValueError,
        naming both, if the GPU path does not support ``state.constraint``).

        Parameters
        ----------
        name : str
        state : State

        Returns
        -------
        bound method"""
        key = (name, state.device.name, type(state.constraint))
        bound = self.__dict__.setdefault("_bound", {})
        if key not in bound:
            supported = self.gpu_surfaces
            if state.device.is_gpu and supported is not None and not isinstance(state.constraint, supported):
                names = ", ".join(c.__name__ for c in supported)
                raise ValueError(f"{type(self).__name__} on the GPU supports {names} surfaces only, but the "
                                 f"state is on {state.constraint!r}; use device='cpu' for this surface")
            if state.device.is_gpu and supported is not None:
                state.constraint.device_surface()   # a surface without device code says what to add
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

    def row_attributes(self):
        """``[(attribute, "replicas" | "vertices" | "cells")]``: the attributes holding one row per
        replica, vertex or cell (``per_replica``, ``per_vertex``, ``per_cell``)."""
        return [(name, "replicas") for name in self.per_replica] + \
            [(name, "vertices") for name in self.per_vertex] + [(name, "cells") for name in self.per_cell]

    def narrow(self, selection):
        """The Simulation now steps only ``selection`` (a :class:`spherevm.state.ReplicaSelection`
        of the State it stepped so far): keep the rows of those replicas, and return what
        :meth:`widen` needs to restore the others."""
        saved = {}
        for name, axis in self.row_attributes():
            full = getattr(self, name)
            saved[name] = full
            setattr(self, name, full[_index_like(full, getattr(selection, axis))])
        return saved

    def widen(self, selection, saved):
        """Undo :meth:`narrow`: merge the current rows of the selected replicas into ``saved`` and
        go back to it (the Simulation steps the wider State again)."""
        for name, axis in self.row_attributes():
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

    def fused_stage(self, simulation, minimizing: bool):
        """This operation's part of the fused small-tissue steps of ``run`` (or of ``minimize``:
        ``minimizing``), a :class:`spherevm.plugins.fusion.FusedStage`, or None (the default): the
        steps then run as CUDA graphs of the general kernels. Asked before every stretch."""
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
    """What a Force computes, on the State's device.

    Parameters
    ----------
    forces : array
        ``(V, 3)``, minus the surface gradient of the energy.
    energy, cell_energy : array
        Per replica, and per cell (optional: None if the force does not split its energy by cell)."""
    forces: object
    energy: object
    cell_energy: object = None


class Force(Operation):
    """A contribution to the potential energy; subclasses implement :meth:`compute`. Forces are
    evaluated whenever the integrator needs them; their trigger is not used."""

    def compute(self, state) -> ForceResult:
        """The force of ``state``: a :class:`ForceResult` on the State's device."""
        raise NotImplementedError

    def energy_scale(self, state):
        """This force's natural energy per cell per replica (NumPy), or None (the default): a
        :class:`~spherevm.plugins.minimizer.Minimizer` measures its tolerances in the largest scale its forces declare."""
        return None

    def combined(self, other, state):
        """A :class:`ForceResult` of this force and ``other`` together (forces, energies and cell
        energies summed), where this force computes the pair in fewer passes than the two apart;
        None (the default) otherwise. :func:`compute_all` asks each pair of attached forces, both
        ways round. A force that pairs here and has a fused stage gives :meth:`fused_combined` for
        the same pairs (else the fused steps would sum the two forces apart, in other roundings)."""
        return None

    def fused_combined(self, other, simulation, minimizing: bool):
        """This force's fused stage where :meth:`combined` computes it together with ``other``: a
        :class:`~spherevm.plugins.fusion.FusedStage` with ``extra=True``, whose gradient ``other``'s
        stage (one that ``takes_extra``) adds inside its vertex force, as the pair's general kernels
        do; None (the default) where ``combined`` does not pair them. The fused steps ask each pair
        of forces both ways round, in :func:`compute_all`'s order."""
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
    """Moves the vertices one step: :meth:`step` with the summed forces. ``check(simulation)``,
    called every few steps (where the GPU path reads back error flags), raises if it went wrong.

    What other operations rely on: ``active``, the per-replica bool mask (NumPy) of the replicas it
    still moves (a minimiser stops converged ones; updaters act on active replicas only;
    ``active_on_device()`` is the same mask on the State's device); ``reset_vertices(vertices)``:
    forget the per-vertex memory (velocities, say) of vertices whose topology an updater changed
    (an index array on the State's device, negative entries ignored; the default keeps nothing)."""

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
        """Move the ``active`` replicas one step under the summed ``forces`` ``(V, 3)``."""
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


class Updater(Operation):
    """Changes the State between steps (for example its topology): :meth:`update`. ``in_minimize``:
    whether ``Simulation.minimize`` runs it (T1: yes; the growth updaters sit minimisations out,
    a quench finds the inherent state at the tissue's N and R, and :meth:`after_minimize` tells them)."""

    in_minimize = True

    def update(self, simulation, timestep):
        """Change the State (at ``timestep``) before the step's forces."""
        raise NotImplementedError

    def after_minimize(self, simulation):
        """A ``Simulation.minimize`` that this updater sat out (``in_minimize`` False) has ended."""


class Writer(Operation):
    """Records the simulation: :meth:`write`; ``close()`` at the end. ``final = True`` asks for one
    more write at the end of every ``run`` and ``minimize`` (the GSD writer sets it)."""

    final = False
    #: the timestep this writer last wrote (the Simulation sets it; at most one write a timestep)
    last_written = None

    def write(self, simulation, timestep):
        """Record the simulation's current state (at ``timestep``)."""
        raise NotImplementedError

    def close(self):
        pass

