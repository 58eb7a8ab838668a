import os

import numpy as np
import pytest
from hypothesis import settings

import spherevm as svm

# Property tests: the same examples on every run by default, so CI is repeatable (a new failing
# example found by chance would block a landing that changed nothing); HYPOTHESIS_PROFILE=explore
# draws fresh random examples, many more of them, to hunt for new ones.
settings.register_profile("repeatable", max_examples=60, deadline=None, derandomize=True)
settings.register_profile("explore", max_examples=1000, deadline=None)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "repeatable"))


# GPU tests: one mechanism. A test that needs the GPU carries the ``gpu`` marker (directly, or
# through the ``device`` fixture's "gpu" parameter); without CuPy and a working NVIDIA GPU every
# such test is skipped here, with the reason, and nowhere else.
HAS_GPU = svm.device.gpu_available()
GPU_REASON = "needs CuPy and a working NVIDIA GPU"


def pytest_collection_modifyitems(config, items):
    if HAS_GPU:
        return
    skip = pytest.mark.skip(reason=GPU_REASON)
    for item in items:
        if "gpu" in item.keywords:
            item.add_marker(skip)


@pytest.fixture(params=["cpu", pytest.param("gpu", marks=pytest.mark.gpu)])
def device(request):
    """The device name a behavioural test runs on: "cpu" always, "gpu" where CuPy sees one."""
    return request.param


def to_numpy(a):
    """A NumPy copy of a NumPy or CuPy array."""
    return a.get() if hasattr(a, "get") else np.asarray(a)


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
