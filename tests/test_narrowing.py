"""minimize() steps only the replicas still running: the same numbers as stepping all of them."""
import numpy as np
import pytest
from conftest import to_numpy

import spherevm as svm
from spherevm.plugins.base import Force
from spherevm.plugins.forces import VertexModel
from spherevm.plugins.integrators import FIRE
from spherevm.plugins.updaters import T1
from spherevm.simulation import Simulation


def mixed_ensemble(device="cpu", replicas=8, n_cells=32):
    """Replicas from floppy (p0 = 3.95, fast to zero energy) to rigid (p0 = 3.6, slow), per-cell P0."""
    state = svm.init.random_tiling(n_cells, replicas=replicas, seed=5)
    p0 = np.linspace(3.6, 3.95, replicas)[state.cell_replica_np()]
    sim = Simulation(device=device, seed=5)
    sim.state = state
    sim.operations.forces.append(VertexModel(kA=0.0, kP=1.0, A0=1.0, P0=p0))
    sim.operations.updaters.append(T1())
    sim.operations.integrator = FIRE(dt=0.02)
    return sim


def counting_narrowings(monkeypatch):
    calls = []
    original = Simulation.narrow

    def spy(self, keep):
        calls.append(len(keep))
        return original(self, keep)

    monkeypatch.setattr(Simulation, "narrow", spy)
    return calls


def test_narrowed_minimisation_is_bitwise_the_full_one(monkeypatch, device):
    """On the CPU, narrowing must not change a single bit. On the GPU a per-replica sum (FIRE's
    power and norms, the energies) adds a replica's items in an order set by where they fall on
    the thread blocks (device_common.cuh), and narrowing moves them: the same bits on every run,
    but not the full run's. There the narrowed run must agree with the full one to rounding:
    same outcome per replica, the stopping check at most one interval apart, energies to 1e-9."""
    full = mixed_ensemble(device)
    ref = full.minimize(force_tol=1e-12, max_steps=3000, narrow=False)
    calls = counting_narrowings(monkeypatch)
    sim = mixed_ensemble(device)
    res = sim.minimize(force_tol=1e-12, max_steps=3000)
    assert len(calls) >= 2 and calls[-1] < 8          # it did narrow, more than once
    assert len(set(ref.steps)) > 2                      # replicas finished at different steps
    fire, fire_ref = sim.operations.integrator, full.operations.integrator
    assert np.array_equal(res.converged, ref.converged) and np.array_equal(res.reason, ref.reason)
    assert sim.log("t1_total_flips").sum() > 0
    for name in ("t1_total_flips", "t1_total_refused", "t1_flip_backs"):
        assert np.array_equal(sim.log(name), full.log(name)), name
    a, b = sim.state, full.state
    for name in ("cell_vertices", "cell_sides", "vertex_neighbors", "vertex_cells"):
        assert np.array_equal(to_numpy(getattr(a, name)), to_numpy(getattr(b, name))), name
    if device == "cpu":
        for name in ("steps", "energy", "max_force", "mean_shape_index"):
            assert np.array_equal(getattr(res, name), getattr(ref, name)), name
        assert np.array_equal(a.positions, b.positions)
        assert np.array_equal(fire.velocities, fire_ref.velocities)
        assert np.array_equal(fire.replica_dt, fire_ref.replica_dt)
    else:
        assert np.all(np.abs(res.steps - ref.steps) <= fire.check_every)
        assert np.allclose(res.energy_per_cell, ref.energy_per_cell, rtol=1e-9, atol=1e-12)
        assert np.abs(to_numpy(a.positions) - to_numpy(b.positions)).max() < 1e-9
    sim.state.validate(orientation=False)
    assert sim.state.n_replicas == 8
    assert np.array_equal(fire.active, ~fire.stopped)     # replicas at max_steps still active


class Stateless(Force):
    """A user force that does not declare narrowable: minimize must not narrow."""

    def compute(self, state):
        xp = state.device.xp
        return svm.plugins.base.ForceResult(forces=xp.zeros_like(state.positions),
                                            energy=xp.zeros(state.n_replicas))


def test_no_narrowing_with_an_operation_that_cannot(monkeypatch, device):
    calls = counting_narrowings(monkeypatch)
    sim = mixed_ensemble(device)
    sim.operations.forces.append(Stateless())
    sim.minimize(force_tol=1e-12, max_steps=1000)
    assert calls == []


def test_no_narrowing_with_a_writer(tmp_path, monkeypatch, device):
    calls = counting_narrowings(monkeypatch)
    sim = mixed_ensemble(device, replicas=4)
    sim.operations.writers.append(svm.plugins.writers.GSD(100, str(tmp_path / "run.gsd")))
    sim.minimize(force_tol=1e-12, max_steps=1000)
    assert calls == []


def test_state_select_and_write_back(device):
    s = svm.init.random_tiling(40, replicas=5, seed=3, device=device)
    sel = s.selection([4, 1, 2])
    part = s.select(sel)
    part.validate()
    for new, old in enumerate([4, 1, 2]):
        a, b = s.replica(old), part.replica(new)
        for name in ("positions", "cell_vertices", "cell_sides", "vertex_neighbors", "vertex_cells", "radius"):
            assert np.array_equal(to_numpy(getattr(a, name)), to_numpy(getattr(b, name))), name
    # flip edges in the part (a cell may grow beyond the table's width), then write it back
    sim = Simulation(device=device, seed=1)
    sim.state = part
    t1 = T1(threshold=1.5, new_length=1.6)            # every edge is "short": many flips at once
    sim.operations.updaters.append(t1)
    sim.operations.integrator = FIRE()
    t1.update(sim, 0)
    assert sim.log("t1_flips").sum() > 0
    whole = s.copy()
    whole.write_back(sel, sim.state)
    whole.validate(orientation=False)
    for new, old in enumerate([4, 1, 2]):
        a, b = whole.replica(old), sim.state.replica(new)
        assert np.array_equal(to_numpy(a.positions), to_numpy(b.positions))
        assert np.array_equal(to_numpy(a.vertex_neighbors), to_numpy(b.vertex_neighbors))
        assert np.array_equal(to_numpy(a.cell_sides), to_numpy(b.cell_sides))
    for r in (0, 3):                                   # untouched replicas
        assert np.array_equal(to_numpy(whole.replica(r).positions), to_numpy(s.replica(r).positions))
    with pytest.raises(IndexError):
        s.selection([5])


def test_t1_flip_back_memory_survives_narrow_and_widen(device):
    sim = mixed_ensemble(device, replicas=4)
    t1 = sim.operations.updaters[0]
    sim.minimize(force_tol=1e-12, max_steps=400, narrow=False)
    sim.log("t1_flip_backs")                           # the GPU's flip log reaches the host memory
    assert len(t1._separated) > 0
    before = (t1._separated.copy(), t1._rejoins.copy(), t1.total_flips.copy())
    sel = sim.state.selection([2, 0])
    saved = t1.narrow(sel)
    assert len(t1.total_flips) == 2
    narrow_state = sim.state.select(sel)
    keys = t1._separated
    assert np.all((keys // narrow_state.n_cells) < narrow_state.n_cells)
    t1.widen(sel, saved)
    assert np.array_equal(t1._separated, before[0])
    assert np.array_equal(t1._rejoins, before[1])
    assert np.array_equal(t1.total_flips, before[2])
