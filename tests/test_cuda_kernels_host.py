"""The force kernels (vertex_model.cu, bending.cu), compiled with the host C++ compiler and run on the CPU.

``tests/cuda_host/kernels.cpp`` includes the two ``.cu`` files unmodified (and through them
``vertex_model.cuh``, where the fused kernels' bodies live, and ``geometry/sphere.cuh``), after the
stand-ins of ``tests/cuda_host`` (``cuda_host.h``; ``kernels/device_common.cuh``: a thread index
set per call and a plain per-replica sum). The GPU paths' own Python code (``_compute_gpu``,
``Bending._combined_gpu``: allocations, argument lists, launch sequences) then runs on a NumPy
State with ``cupy``'s allocations served by NumPy and every launch calling the host kernel once per
thread, and its results are compared with the NumPy path. So the kernels' formulas, the fused ones
included, and the code that launches them are checked on every machine; the GPU tests
(test_bending.py, test_forces.py) check the same on a GPU. Built without fused multiply-adds
(``-ffp-contract=off``).
"""
import ctypes
import subprocess
import sys
import types

import numpy as np
import pytest

from test_cuda_headers import CXXFLAGS, HERE, PACKAGE, find_compiler

import spherevm as svm
from spherevm.plugins.base import ForceResult
from spherevm.plugins.forces import Bending, VertexModel, bending, vertex_model

# The NumPy path against the same formulas in another order (rsqrt as 1/sqrt, a fan of cross
# products about the first vertex rather than per corner): rounding, ~1e-15 to 1e-14 here;
# a wrong term or sign is off by O(1).
RTOL = 1e-12


@pytest.fixture(scope="module")
def kernels(tmp_path_factory):
    if find_compiler() is None:
        pytest.skip("no C++ compiler (g++ or c++) on the PATH")
    lib = tmp_path_factory.mktemp("kernels") / "libsvm_kernels_host.so"
    cmd = [find_compiler(), *CXXFLAGS, "-Wno-unknown-pragmas", f"-I{HERE / 'kernels'}", f"-I{PACKAGE}", f"-I{HERE}",
           str(HERE / "kernels.cpp"), "-o", str(lib)]
    done = subprocess.run(cmd, capture_output=True, text=True)
    if done.returncode != 0:
        raise RuntimeError(f"building the kernels on the host failed:\n{' '.join(cmd)}\n{done.stderr}")
    return Kernels(lib)


class Kernels:
    """Runs a kernel of the host build once per thread: ``launch(name, n, *args)`` with NumPy
    arrays (passed as pointers) and integers (passed as C ints), as ``spherevm.device.launch``."""

    def __init__(self, path):
        self.lib = ctypes.CDLL(str(path))

    def launch(self, name, n, *args):
        assert all(a.flags.c_contiguous for a in args if isinstance(a, np.ndarray))
        c_args = [a.ctypes.data_as(ctypes.c_void_p) if isinstance(a, np.ndarray) else ctypes.c_int(int(a)) for a in args]
        kernel = getattr(self.lib, name)
        for i in range(n):
            self.lib.h_set_thread(ctypes.c_long(i))
            kernel(*c_args)


@pytest.fixture
def host_gpu(kernels, monkeypatch):
    """The forces' GPU paths with cupy's allocations from NumPy and the kernels from the host build."""
    monkeypatch.setitem(sys.modules, "cupy", types.SimpleNamespace(empty=np.empty, zeros=np.zeros, empty_like=np.empty_like))
    functions = types.SimpleNamespace(get_function=lambda name: name)
    for module in (bending, vertex_model):
        monkeypatch.setattr(module, "surface_kernels", lambda path, state: (functions, state.size))
    for module in (bending, vertex_model):
        monkeypatch.setattr(module, "launch", lambda kernel, n, args: kernels.launch(kernel, n, *args))


def _state(n, replicas, seed):
    """Replicas of different radii (the kernels take R per replica)."""
    return svm.State.concatenate([svm.init.random_tiling(n, seed=seed + r, radius=1.0 + r) for r in range(replicas)])


def _assert_close(got, result):
    for a, b in ((got.forces, result.forces), (got.energy, result.energy), (got.cell_energy, result.cell_energy)):
        assert np.abs(a - b).max() <= RTOL * np.abs(b).max()


@pytest.mark.parametrize("n, replicas", [(200, 1), (150, 3)])
def test_vertex_model_kernels_match_numpy(host_gpu, n, replicas):
    s = _state(n, replicas, seed=n)
    model = VertexModel.dimensionless(kr=0.8, p0=3.7)
    _assert_close(model._compute_gpu(s), model._compute_cpu(s))


@pytest.mark.parametrize("n, replicas", [(200, 1), (150, 3)])
def test_bending_kernels_match_numpy(host_gpu, n, replicas):
    s = _state(n, replicas, seed=n + 1)
    force = Bending(np.linspace(0.05, 2.0, replicas))
    got = force._compute_gpu(s)
    _assert_close(got, force._compute_cpu(s))
    assert np.abs(got.forces).max() > 1e-3                # not trivially zero


@pytest.mark.parametrize("n, replicas", [(200, 1), (150, 3)])
def test_fused_kernels_match_numpy_and_the_two_forces_apart(host_gpu, n, replicas):
    s = _state(n, replicas, seed=n + 2)
    model, force = VertexModel.dimensionless(kr=0.8, p0=3.7), Bending(np.linspace(1.0, 3.0, replicas))
    got = force._combined_gpu(model, s)
    _assert_close(got, force._combined_cpu(model, s))
    a, b = model._compute_cpu(s), force._compute_cpu(s)
    _assert_close(got, ForceResult(forces=a.forces + b.forces, energy=a.energy + b.energy,
                                   cell_energy=a.cell_energy + b.cell_energy))
    # the bending part is far above the tolerance: fused kernels that dropped it would fail
    assert np.abs(b.forces).max() > 1e-3 * np.abs(a.forces).max()
