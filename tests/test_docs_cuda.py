"""The CUDA in the docs compiles, and the documented line-tension kernel computes what the NumPy
plugin computes.

Every ```cuda block of README.md and docs/*.md is compiled as the kernels of ``spherevm/`` are in
``tests/test_cuda_kernels_host.py``: with the host C++ compiler, after ``tests/cuda_host/cuda_host.h``
(empty CUDA qualifiers) and with ``tests/cuda_host/kernels`` first on the include path (its
``device_common.cuh`` stands in for the per-replica sums: a thread index set per call, a plain
running sum of the same signature). Where nvcc is on the PATH the block is also compiled for the
device against the package's real headers. The kernel of docs/plugins.md then runs on the CPU, one
call per thread, against ``examples/line_tension_plugin.LineTension`` on NumPy.

A block is a whole ``.cu`` file (its own ``#include`` lines). The comments of spherevm's own ``.cu``
and ``.cuh`` files name Python functions (``spherevm.device.segment_sums``): each must exist.
"""
import ctypes
import importlib
import pathlib
import re
import shutil
import subprocess
import sys

import numpy as np
import pytest

from test_cuda_headers import CXXFLAGS, HERE, PACKAGE, find_compiler

import spherevm as svm

ROOT = pathlib.Path(__file__).resolve().parent.parent
FILES = [ROOT / "README.md"] + sorted((ROOT / "docs").glob("*.md"))
BLOCK = re.compile(r"```cuda\n(.*?)```", re.S)


def cuda_blocks():
    out = []
    for path in FILES:
        text = path.read_text()
        for m in BLOCK.finditer(text):
            line = text[:m.start(1)].count("\n") + 1
            out.append(pytest.param(m.group(1), id=f"{path.name}:{line}"))
    return out


BLOCKS = cuda_blocks()


def build_host(source, directory):
    """The block as a shared library of the host build; returns its path."""
    if find_compiler() is None:
        pytest.skip("no C++ compiler (g++ or c++) on the PATH")
    directory = pathlib.Path(directory)
    (directory / "block.cu").write_text(source)
    (directory / "block.cpp").write_text('#include "cuda_host.h"\n#include "device_common.cuh"\n#include "block.cu"\n'
                                         'extern "C" void h_set_thread(long i) { blockIdx.x = (unsigned int)i; }\n')
    lib = directory / "libblock.so"
    cmd = [find_compiler(), *CXXFLAGS, "-Wno-unknown-pragmas", "-Wno-unused-parameter", f"-I{HERE / 'kernels'}",
           f"-I{PACKAGE}", f"-I{HERE}", f"-I{directory}", str(directory / "block.cpp"), "-o", str(lib)]
    done = subprocess.run(cmd, capture_output=True, text=True)
    assert done.returncode == 0, f"the documented kernel does not compile:\n{' '.join(cmd)}\n{done.stderr}"
    return lib


def test_the_docs_have_cuda_blocks():
    assert any("line_tension" in p.values[0] for p in BLOCKS), "docs/plugins.md's kernel block is gone"


@pytest.mark.parametrize("source", BLOCKS)
def test_cuda_block_compiles_on_the_host(source, tmp_path):
    build_host(source, tmp_path)


@pytest.mark.parametrize("source", BLOCKS)
def test_cuda_block_compiles_with_nvcc(source, tmp_path):
    nvcc = shutil.which("nvcc")
    if nvcc is None:
        pytest.skip("no nvcc on the PATH (the host build above still checks the block)")
    (tmp_path / "block.cu").write_text(source)
    cmd = [nvcc, "-std=c++17", "-arch=sm_90", f"-I{PACKAGE}", "-c", str(tmp_path / "block.cu"),
           "-o", str(tmp_path / "block.o")]
    done = subprocess.run(cmd, capture_output=True, text=True)
    assert done.returncode == 0, f"nvcc rejects the documented kernel:\n{' '.join(cmd)}\n{done.stderr}"


def test_documented_line_tension_kernel_matches_the_numpy_plugin(tmp_path):
    source = next(p.values[0] for p in BLOCKS if "line_tension(" in p.values[0])
    lib = ctypes.CDLL(str(build_host(source, tmp_path)))
    sys.path.insert(0, str(ROOT / "examples"))
    try:
        from line_tension_plugin import LineTension
    finally:
        sys.path.remove(str(ROOT / "examples"))
    state = svm.State.concatenate([svm.init.random_tiling(40, seed=3), svm.init.random_tiling(60, seed=4, radius=2.5)])
    nv, tension = state.n_vertices, 0.7
    forces, corner = np.empty((nv, 3)), np.empty((nv, 3))
    energy = np.full(state.n_replicas, np.nan)
    start = np.ascontiguousarray(state.vertex_start, dtype=np.int32)
    arrays = [np.ascontiguousarray(a) for a in (state.positions, state.vertex_neighbors.astype(np.int32),
                                                state.vertex_replica.astype(np.int32), state.radius)]
    ptr = lambda a: a.ctypes.data_as(ctypes.c_void_p)   # noqa: E731
    args = [*map(ptr, arrays), ctypes.c_int(nv), ctypes.c_double(tension), ptr(forces), ptr(corner), ptr(energy),
            ptr(start), ctypes.c_int(state.n_replicas), None, None]
    for i in range(nv):                                  # one call per thread, in item order
        lib.h_set_thread(ctypes.c_long(i))
        lib.line_tension(*args)
    want = LineTension(tension).compute(state)
    assert np.abs(forces - want.forces).max() <= 1e-12 * np.abs(want.forces).max()
    np.testing.assert_allclose(energy, want.energy, rtol=1e-12)
    cell_energy = np.bincount(state.vertex_cells.reshape(-1), weights=corner.reshape(-1), minlength=state.n_cells)
    np.testing.assert_allclose(cell_energy, want.cell_energy, rtol=1e-12)


def test_the_example_plugin_ships_the_documented_kernel():
    """tests/plugin_example's FastLineTension compiles the kernel of docs/plugins.md, character for
    character (its fused stage calls the same line_tension_force)."""
    sys.path.insert(0, str(ROOT / "tests" / "plugin_example"))
    try:
        import spherevm_line_tension
    finally:
        sys.path.remove(str(ROOT / "tests" / "plugin_example"))
    documented = next(p.values[0] for p in BLOCKS if "line_tension(" in p.values[0])
    assert spherevm_line_tension.KERNEL == documented
    assert spherevm_line_tension.STAGE.startswith(documented)


def _named_in_kernel_comments():
    names = set()
    for path in sorted(PACKAGE.rglob("*.cu*")):
        names.update(re.findall(r"\bspherevm(?:\.[A-Za-z_]\w*)+", path.read_text()))
    return sorted(names)


@pytest.mark.parametrize("dotted", _named_in_kernel_comments())
def test_python_names_in_kernel_comments_exist(dotted):
    parts = dotted.split(".")
    for k in range(len(parts), 0, -1):                   # the longest importable prefix, then attributes
        try:
            obj = importlib.import_module(".".join(parts[:k]))
        except ImportError:
            continue
        for attr in parts[k:]:
            assert hasattr(obj, attr), f"{dotted}, named in a kernel's comment, does not exist"
            obj = getattr(obj, attr)
        return
    pytest.fail(f"{dotted}: no such module")
