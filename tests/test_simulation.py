"""Simulation, operations, triggers and loggable quantities."""
import numpy as np
import pytest

import spherevm as svm
from spherevm import trigger
from spherevm.plugins.base import Updater, Writer
from spherevm.plugins.forces import VertexModel
from spherevm.plugins.integrators import FIRE


def test_triggers():
    p = trigger.Periodic(3, phase=1)
    assert [t for t in range(10) if p(t)] == [1, 4, 7]
    assert [t for t in range(5) if trigger.On(2)(t)] == [2]
    assert [t for t in range(5) if trigger.After(2)(t)] == [3, 4]
    both = trigger.And(trigger.Periodic(2), trigger.After(3))
    assert [t for t in range(10) if both(t)] == [4, 6, 8]
    either = trigger.Or(trigger.On(1), trigger.On(5))
    assert [t for t in range(10) if either(t)] == [1, 5]
    assert [t for t in range(6) if (~trigger.Periodic(2))(t)] == [1, 3, 5]
    assert [t for t in range(6) if (trigger.Periodic(2) & trigger.Before(3))(t)] == [0, 2]
    with pytest.raises(ValueError, match="period must be >= 1"):
        trigger.Periodic(0)
    with pytest.raises(ValueError, match="timestep must be a non-negative integer"):
        trigger.On(-1)


class Recorder(Writer):
    def __init__(self, trigger=1):
        super().__init__(trigger)
        self.seen = []

    def write(self, simulation, timestep):
        self.seen.append((timestep, float(simulation.log("energy").sum())))


class Counter(Updater):
    def __init__(self, trigger):
        super().__init__(trigger)
        self.calls = []

    def update(self, simulation, timestep):
        self.calls.append(timestep)


def test_run_order_triggers_and_logging(device):
    sim = svm.Simulation(device=device)
    sim.state = svm.init.random_tiling(40, seed=1)
    sim.operations.forces.append(VertexModel.dimensionless(kr=1.0, p0=3.9))
    sim.operations.integrator = FIRE(dt=0.01)
    rec, cnt = Recorder(trigger.Periodic(5)), Counter(trigger.Periodic(4))
    sim.operations.writers.append(rec)
    sim.operations.updaters.append(cnt)
    sim.run(20)
    assert sim.timestep == 20
    assert [t for t, _ in rec.seen] == [0, 5, 10, 15, 20]
    assert cnt.calls == [0, 4, 8, 12, 16]
    energies = [e for _, e in rec.seen]
    assert energies[-1] < energies[0]
    names = set(sim.loggables)
    assert {"timestep", "energy", "energy_per_cell", "mean_shape_index", "max_force", "fire_dt"} <= names
    assert sim.log("max_force").shape == (1,)
    with pytest.raises(ValueError, match="unknown loggable"):
        sim.log("temperature_of_the_moon")


def test_operation_type_checks():
    sim = svm.Simulation(device="cpu")
    with pytest.raises(TypeError, match="Force"):
        sim.operations.forces.append(FIRE())
    with pytest.raises(TypeError, match="Integrator"):
        sim.operations.integrator = VertexModel()
    with pytest.raises(TypeError, match="spherevm.State"):
        sim.state = np.zeros((3, 3))


def test_mean_shape_index_of_regular_tiling(device):
    s = svm.init.regular_tiling("dodecahedron", device=device)
    expected = svm.analysis.pentagon_perimeter(12)  # unit-area pentagons at the default radius
    assert np.isclose(svm.analysis.mean_shape_index(s)[0], expected, rtol=1e-13)
