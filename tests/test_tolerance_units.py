"""Minimisation tolerances in the replica's natural units (issue 13, item 6): force in
e / sqrt(<A>) and energy per cell in e = kP <A> (VertexModel.energy_scale; kA <A>^2 without perimeter
stiffness), so the same tiling at any size stops in the same shape after the same number of steps."""
import numpy as np
import pytest

import spherevm as svm
from spherevm.plugins.minimizer import Minimizer
from spherevm.plugins.forces import Bending, VertexModel
from spherevm.plugins.integrators import FIRE
from spherevm.plugins.updaters import T1


def _minimised(radius, device, seed=0, tol=1e-9):
    sim = svm.Simulation(device=device)
    sim.state = svm.init.random_tiling(64, replicas=2, seed=seed, radius=radius)
    sim.operations.forces.append(VertexModel.dimensionless(kr=1.0, p0=3.7))
    sim.operations.updaters.append(T1())
    sim.operations.integrator = FIRE(dt=0.02)
    return sim, sim.minimize(force_tol=tol, max_steps=20_000)


@pytest.mark.parametrize("seed", [0, 1])
def test_the_same_tiling_at_any_size_reaches_the_same_shape(device, seed):
    """Radius 1e-9, 1 and 1e6 (<A> from 2e-20 to 2e10): before, 1e-9 stopped at once with the wrong
    shape index (3.88 against 3.76 here) and 1e6 needed ten times the steps."""
    results = [_minimised(r, device, seed)[1] for r in (1e-9, 1.0, 1e6)]
    ref = results[1]
    assert list(ref.reason) == ["force", "force"]
    for res in results:
        assert list(res.reason) == ["force", "force"]
        np.testing.assert_allclose(res.mean_shape_index, ref.mean_shape_index, rtol=0, atol=1e-6)
        assert np.all(np.abs(res.steps - ref.steps) <= 0.1 * ref.steps + 20), (res.steps, ref.steps)


def test_units_of_the_vertex_model():
    """kP <A> per cell (kA <A>^2 where kP = 0), averaged per replica; the force unit divides by sqrt(<A>)."""
    state = svm.init.random_tiling(20, replicas=2, seed=1, radius=np.sqrt(20 / (4 * np.pi)) * 3.0)   # <A> = 9
    area = state.mean_cell_area
    np.testing.assert_allclose(area, 9.0, rtol=1e-14)
    sim = svm.Simulation(device="cpu")
    sim.state = state
    for model, e in ((VertexModel(kA=2.0, kP=1.0), 9.0), (VertexModel(kA=0.01, kP=3.0), 27.0),
                     (VertexModel(kA=2.0, kP=0.0), 2 * 81.0), (VertexModel.dimensionless(kr=0.0, p0=3.8), 9.0),
                     (VertexModel.dimensionless(kr=4.0), 9.0)):
        sim.operations.forces[:] = [model]
        energy, force = Minimizer.tolerance_units(sim)
        np.testing.assert_allclose(energy, e, rtol=1e-14)
        np.testing.assert_allclose(force, e / 3.0, rtol=1e-14)
    kP = np.where(np.arange(40) < 30, 2.0, 0.0)        # per cell: replica 1 has ten cells of kA alone
    sim.operations.forces[:] = [VertexModel(kA=1.0, kP=kP)]
    np.testing.assert_allclose(Minimizer.tolerance_units(sim)[0], [18.0, (10 * 18.0 + 10 * 81.0) / 20], rtol=1e-14)


def test_forces_without_a_scale_leave_absolute_tolerances():
    sim = svm.Simulation(device="cpu")
    sim.state = svm.init.random_tiling(20, replicas=2, seed=1, radius=7.0)
    sim.operations.forces.append(Bending(B=0.5))
    energy, force = Minimizer.tolerance_units(sim)
    assert energy.tolist() == [1.0, 1.0]
    np.testing.assert_allclose(force, 1 / np.sqrt(sim.state.mean_cell_area), rtol=1e-15)
    sim.operations.forces.append(VertexModel(kA=0.0, kP=0.0))     # a zero scale: absolute, not 0
    assert Minimizer.tolerance_units(sim)[0].tolist() == [1.0, 1.0]


def test_unit_cells_keep_absolute_numbers():
    """At <A> = 1 with kP = 1 the units are 1 to the last bit: the tolerances mean what they meant."""
    sim = svm.Simulation(device="cpu")
    sim.state = svm.init.random_tiling(200, replicas=2, seed=5)
    assert np.all(sim.state.mean_cell_area == 1.0)
    sim.operations.forces.append(VertexModel.dimensionless(kr=1.0, p0=3.8))
    energy, force = Minimizer.tolerance_units(sim)
    assert energy.tolist() == [1.0, 1.0] and force.tolist() == [1.0, 1.0]


def test_stopping_is_decided_in_natural_units():
    """A replica stops by force exactly when max|F| / (e / sqrt(<A>)) < force_tol."""
    sim, res = _minimised(1e3, "cpu", tol=1e-7)
    _, force = Minimizer.tolerance_units(sim)
    np.testing.assert_allclose(force, np.sqrt(sim.state.mean_cell_area), rtol=1e-14)   # kP sqrt(<A>), ~443
    assert list(res.reason) == ["force", "force"] and np.all(res.max_force < 1e-7 * force)
