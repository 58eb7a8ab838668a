import numpy as np
import pytest

import spherevm as svm


@pytest.fixture
def tiling200():
    return svm.init.random_tiling(200, seed=11)


def finite_difference_forces(force, state, vertices, h=1e-6):
    """Minus the central finite-difference gradient of the total energy at the given vertices."""
    pos0 = state.positions.copy()
    out = np.zeros((len(vertices), 3))
    for i, v in enumerate(vertices):
        for d in range(3):
            state.positions = pos0.copy()
            state.positions[v, d] += h
            ep = force.energy(state).sum()
            state.positions = pos0.copy()
            state.positions[v, d] -= h
            em = force.energy(state).sum()
            out[i, d] = -(ep - em) / (2 * h)
    state.positions = pos0
    return out
