"""The four kinds of operation. Built-in plugins derive from these exactly as a user's would."""
from __future__ import annotations

from dataclasses import dataclass

from ..trigger import Always, as_trigger


class Operation:
    """Something the Simulation runs: it has a trigger and may publish loggable quantities.

    ``loggables`` maps a quantity name to a callable ``f(simulation)`` returning a scalar or a
    per-replica array; writers and ``Simulation.log`` find them by name.
    """

    def __init__(self, trigger=None):
        self.trigger = Always() if trigger is None else as_trigger(trigger)
        self._simulation = None

    def attach(self, simulation):
        """Called when the operation joins a Simulation whose State is set."""
        self._simulation = simulation

    def detach(self):
        self._simulation = None

    @property
    def loggables(self) -> dict:
        return {}

    halt_reason = "halted"

    def halted(self):
        """Per-replica bool mask of replicas this operation wants stopped (``minimize`` honours it), or None."""
        return None

    def reset_halted(self):
        """Forget what made replicas halt (called when a minimisation starts)."""

    # Narrowing: Simulation.minimize steps only the replicas still running once at most half are
    # (finished ones cost nothing more). It may do so only if every operation says it can: an
    # operation that keeps per-replica, per-vertex or per-cell data sets ``narrowable = True`` and
    # implements narrow() and widen(); one that keeps none just sets ``narrowable = True``.
    narrowable = False

    def narrow(self, selection):
        """The Simulation now steps only ``selection`` (a :class:`spherevm.state.ReplicaSelection`
        of the State it stepped so far): keep the data of those replicas, and return what
        :meth:`widen` needs to restore the others."""
        return None

    def widen(self, selection, saved):
        """Undo :meth:`narrow`: merge the current data of the selected replicas into ``saved`` and
        go back to it (the Simulation steps the wider State again)."""


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

    def energy(self, state):
        """Energy per replica, as a NumPy array."""
        return state.device.to_numpy(self.compute(state).energy)

    def forces(self, state):
        """Forces ``(n_vertices, 3)``, as a NumPy array."""
        return state.device.to_numpy(self.compute(state).forces)


class Integrator(Operation):
    """Moves the vertices one step: ``step(simulation, forces)`` with the summed forces.

    ``check(simulation)`` is called every few steps (where the GPU path reads back error flags)
    and raises if the integration went wrong.
    """

    def step(self, simulation, forces):
        raise NotImplementedError

    def check(self, simulation):
        pass


class Updater(Operation):
    """Changes the state between steps (for example the topology): ``update(simulation, timestep)``."""

    def update(self, simulation, timestep):
        raise NotImplementedError


class Writer(Operation):
    """Records the simulation: ``write(simulation, timestep)``; ``close()`` at the end."""

    def write(self, simulation, timestep):
        raise NotImplementedError

    def close(self):
        pass
