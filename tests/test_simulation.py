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


def test_replica_summary_reads_the_largest_force_energy_and_first_bad_vertex(device):
    """One read-back at a convergence check: per replica max |F_v| and the energy, exactly what the
    forces give, and the first vertex with a non-finite position, which check_finite names."""
    sim = svm.Simulation(device=device)
    sim.state = svm.init.random_tiling(40, replicas=3, seed=4)
    sim.operations.forces.append(VertexModel.dimensionless(kr=1.0, p0=3.7))
    forces, energy = (sim.device.to_numpy(a) for a in sim.compute_forces())
    norm = np.sqrt((forces * forces).sum(axis=1))
    rep = sim.state.vertex_replica_np()
    fmax, e, bad, opened = sim.replica_summary()
    assert fmax.tolist() == [norm[rep == r].max() for r in range(3)]      # the same bits on both devices
    assert e.tobytes() == energy.tobytes() and bad == -1 and opened == 0
    assert sim.device.to_numpy(sim.max_force()).tobytes() == fmax.tobytes()
    pos = sim.device.to_numpy(sim.state.positions)
    pos[[130, 77], [2, 0]] = np.inf, np.nan                  # two bad vertices: the first is named
    sim.state.positions = sim.device.asarray(pos)
    sim.state_changed()
    with np.errstate(invalid="ignore"):                        # the forces of such a state are NaN
        assert sim.replica_summary()[2] == 77
    for fresh in (False, True):             # read with the forces, or from the positions alone
        if fresh:
            sim.state_changed()
        with pytest.raises(FloatingPointError, match=f"replica {int(rep[77])}, vertex 77"):
            sim.check_finite()


def test_replica_summary_of_nan_forces_and_empty_replicas(device):
    """A NaN force norm wins the maximum (as a NaN-propagating max), a replica without vertices gets
    0, and without forces only the positions are looked at."""
    xp = svm.device.resolve(device).xp
    forces = np.array([[3.0, 4.0, 0.0], [0.0, 0.0, 1.0], [np.nan, 0.0, 0.0], [1.0, 2.0, 2.0]])
    positions = np.ones((4, 3))
    rep = np.array([0, 0, 2, 3], dtype=np.int32)
    summary = svm.device.replica_summary(xp.asarray(positions), xp.asarray(rep), 4, xp.asarray(forces),
                                         xp.asarray(np.arange(4.0)))
    fmax, energy, bad, flag = svm.device.read_replica_summary(summary, 4, 4)
    assert fmax[[0, 1, 3]].tolist() == [5.0, 0.0, 3.0] and np.isnan(fmax[2])
    assert energy.tolist() == [0.0, 1.0, 2.0, 3.0] and bad == -1 and flag == 0
    positions[3, 1] = -np.inf
    only = svm.device.read_replica_summary(svm.device.replica_summary(xp.asarray(positions), xp.asarray(rep), 4), 4, 4)
    assert only[0].tolist() == [0.0] * 4 and only[2] == 3
