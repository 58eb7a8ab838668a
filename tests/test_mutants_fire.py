"""Tests that kill mutants of spherevm/plugins/integrators/fire.py that survived the existing tests.

Found with ``python3 benchmarks/mutate.py spherevm/plugins/integrators/fire.py ...`` (docs/testing.md,
"Mutation testing"): the step guard's default and its threshold in units of sqrt(<A>).
"""
import numpy as np
import pytest

import spherevm as svm
from spherevm.plugins.integrators import FIRE

from test_fire_known_answers import UniformField, reference_forces


def test_step_guard_default_is_one_cell_size():
    assert FIRE().max_step == 1.0


@pytest.mark.parametrize("radius", [0.2, 5.0])
def test_step_guard_threshold_is_max_step_times_sqrt_mean_area(radius):
    """From rest (P = 0: dt <- f_dec dt, v <- dt F) the first move is dt^2 F: it passes just
    under max_step sqrt(<A>) and is refused just over it, on spheres whose sqrt(<A>) is far from 1."""
    g = np.array([[0.3, -1.2, 0.7]])
    dt = 0.5 * radius
    state = svm.init.random_tiling(32, seed=4, radius=radius)
    F = reference_forces(state.positions, g[0])
    steps = (0.5 * dt) ** 2 * np.linalg.norm(F, axis=1) / np.sqrt(state.mean_cell_area[0])
    step, worst = steps.max(), int(steps.argmax())
    assert np.sum(steps > step * (1 - 1e-6)) == 1                  # one vertex over: it is the one named
    assert abs(np.log(np.sqrt(state.mean_cell_area[0]))) > 1        # sqrt(<A>) far from 1
    for factor, raises in ((1 + 1e-6, False), (1 - 1e-6, True)):
        sim = svm.Simulation(device="cpu")
        sim.state = state.copy()
        sim.operations.forces.append(UniformField(g))
        sim.operations.integrator = FIRE(dt=dt, max_step=step * factor, force_tol=0.0, energy_tol=0.0)
        if raises:
            with pytest.raises(FloatingPointError, match=f"exploding step at timestep 0: replica 0, vertex {worst} "):
                sim.run(1)
        else:
            sim.run(1)
