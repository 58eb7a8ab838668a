"""Implicit surfaces' device code (constraints/implicit.cuh, implicit_device.py) built for the CPU
and compared with the NumPy path: ``Implicit<Shape>`` of the torus, the ellipsoid, the Gaussian bump
and the user's sinusoid, through the harness templates of tests/cuda_host/harness.cpp (each
Surface function as the kernels call it). The flat-facet measures and forces agree to rounding
(1e-12 relative); projections, normals and T1's positions to 1e-12 of the length scale (the
Newton iterations stop within 1e-14 of it and take the Hessian by differences)."""
import ctypes
import importlib.util
import pathlib
import shutil
import subprocess
import sys

import numpy as np
import pytest

import spherevm as svm
from spherevm import folding, topology
from spherevm.constraints import Ellipsoid, GaussianBump, Torus
from spherevm.plugins.forces import VertexModel

from test_cuda_headers import HERE, PACKAGE, Harness, build_harness, find_compiler

EXAMPLE = pathlib.Path(__file__).parent / "plugin_example"
RTOL = 1e-12


def sinusoid():
    """The user's surface of tests/plugin_example, loaded from its file (not put on the path: other
    tests look for its distribution there)."""
    spec = importlib.util.spec_from_file_location("sinusoid_plugin", EXAMPLE / "spherevm_sinusoid.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module.Sinusoid(1.5, 10.0)


SURFACES = {"torus": lambda: Torus(3.0, 1.0), "ellipsoid": lambda: Ellipsoid(1.0, 1.5, 2.0),
            "bump": lambda: GaussianBump(1.5, 1.0, 10.0), "sinusoid": sinusoid}


@pytest.fixture(scope="module")
def harness(tmp_path_factory):
    """harness.cpp with every implicit surface's device code exported as h_<name>_*."""
    if find_compiler() is None:
        pytest.skip("no C++ compiler (g++ or c++) on PATH: the CUDA headers cannot be built for the CPU")
    directory = tmp_path_factory.mktemp("implicit_harness")
    parts = [f'#include "{HERE / "harness.cpp"}"']
    for name, make in SURFACES.items():
        code = make().device_surface()
        parts += [code.source, f"EXPORT_SURFACE({name}, {code.struct})"]
    source = directory / "implicit_harness.cpp"
    source.write_text("\n".join(parts) + "\n")
    return Harness(build_harness(directory, source=source))


@pytest.fixture(scope="module", params=list(SURFACES))
def tissue(request):
    """Two replicas of different sizes, kicked off their relaxed places (some cells straddle the box)."""
    con = SURFACES[request.param]()
    s = svm.State.concatenate([svm.init.random_tiling(60, seed=3 + r, surface=con) for r in range(2)])
    rng = np.random.default_rng(1)
    size = con.size(s, s.vertex_replica)
    step = con.project_tangent(s.positions, rng.normal(scale=0.05, size=s.positions.shape), size)
    s.positions = con.project_normal(s.positions + step, size)
    return request.param, s


def test_cell_measures_and_forces(harness, tissue):
    """Surface::cell_measures and vertex_force (coefficients (dE/dA a / A, dE/dP) per cell) against
    FlatFacets.cell_geometry and shape_gradient, for random per-cell coefficients and for the
    vertex model with per-cell parameters."""
    name, s = tissue
    con = s.constraint
    geom = con.cell_geometry(s)
    area, perimeter, units = harness.cells(name, s)
    np.testing.assert_allclose(area, geom.area, rtol=RTOL)
    np.testing.assert_allclose(perimeter, geom.perimeter, rtol=RTOL)
    assert np.all(units == 1.0)
    rng = np.random.default_rng(7)
    for d_area, d_perimeter in ((rng.normal(size=s.n_cells), rng.normal(size=s.n_cells)),
                                (np.eye(s.n_cells)[5], np.zeros(s.n_cells))):
        coef = np.concatenate([(d_area / geom.area)[:, None] * geom.area_vector, d_perimeter[:, None]], axis=1)
        host, ref = harness.forces(name, s, coef), -con.shape_gradient(s, geom, d_area, d_perimeter)
        assert np.abs(host - ref).max() <= RTOL * np.abs(ref).max()
    vm = VertexModel(kA=rng.uniform(0.5, 2, s.n_cells), kP=rng.uniform(0.5, 2, s.n_cells), A0=1.0,
                     P0=rng.uniform(3.4, 4.0, s.n_cells))
    kA, kP, A0, P0 = vm.parameters(s)
    coef = np.concatenate([(2 * kA * (area - A0) / area)[:, None] * geom.area_vector,
                           (2 * kP * (perimeter - P0))[:, None]], axis=1)
    ref = vm.compute(s).forces
    assert np.abs(harness.forces(name, s, coef) - ref).max() <= RTOL * np.abs(ref).max()


def test_projection_normals_edges_and_t1_positions(harness, tissue):
    """normal and place (P_N from points off the surface), chord2 and edge_length, cell_normal and
    t1_positions against the constraint and topology.t1_new_positions."""
    name, s = tissue
    con = s.constraint
    rng = np.random.default_rng(2)
    rep = s.vertex_replica
    size = con.size(s, rep)
    scale = con.length_scale(size)[:, None]
    y = s.positions + rng.normal(scale=0.1, size=s.positions.shape) * scale
    normal, placed = harness.project(name, y, rep, con.kernel_size(s))
    np.testing.assert_allclose(normal, con.normal(y, size), atol=1e-13)
    assert np.abs(placed - con.project_normal(y, size)).max() <= 1e-12 * scale.max()
    u = np.arange(s.n_vertices)
    v = s.vertex_neighbors[:, 0]
    chord2, length = harness.edges(name, s, u, v)
    np.testing.assert_allclose(length, con.edge_lengths(s, u, v), rtol=RTOL)
    np.testing.assert_allclose(chord2, length ** 2, rtol=RTOL)
    np.testing.assert_allclose(harness.cell_normals(name, s), con.cell_normals(s), atol=1e-12)
    slot = np.zeros(s.n_vertices, dtype=np.int64)
    vv, a, b, c, d = topology.t1_cells(s.vertex_neighbors, s.vertex_cells, u, slot)[:5]
    full = np.full(len(u), 0.3)
    x_pos, y_pos = harness.t1(name, s, np.stack([u, vv, a, b, c, d], axis=1), full)
    px, py = topology.t1_new_positions(s, s.positions, u, vv, a, b, c, d, full)
    assert np.abs(x_pos - px).max() <= 1e-12 * scale.max()
    assert np.abs(y_pos - py).max() <= 1e-12 * scale.max()


def test_kernel_size_table():
    """Per replica the parameters, the length scale and half the area (Surface::size's k + 2 columns)."""
    s = svm.State.concatenate([svm.init.random_tiling(40, seed=1, surface=Torus(3.0, 1.0)),
                               svm.init.random_tiling(60, seed=2, surface=Torus(3.0, 1.0))])
    con, size = s.constraint, s.size_np()
    table = con.kernel_size(s)
    np.testing.assert_array_equal(table, np.column_stack([size, size[:, 1], 0.5 * con.total_area_np(size)]))
    assert con.kernel_size(s) is table
    s.size = size * 2
    assert con.kernel_size(s)[0, 0] == 2 * size[0, 0]


def test_device_parameters_replace_the_parameters_in_the_table():
    """A class that derives its device parameters (the ellipsoid: 1/a^2, 1/b^2, 1/c^2; the user's
    sinusoid: its box, amplitude and wavenumber) gives them to the kernels in place of the
    parameters, with the length scale and half the area of the parameters after them."""
    for con in (Ellipsoid(1.0, 1.5, 2.0), sinusoid()):
        s = svm.init.random_tiling(60, replicas=2, seed=1, surface=con)
        size = s.size_np()
        expected = np.column_stack([1.0 / size ** 2] if isinstance(con, Ellipsoid) else
                                   [size, 2 * np.pi / size[:, 0]])
        table = con.kernel_size(s)
        assert table.shape == (2, len(type(con).device_parameter_names) + 2)
        np.testing.assert_array_equal(table[:, :-2], expected)
        np.testing.assert_array_equal(table[:, -2:], np.column_stack([con.length_scale(size),
                                                                      0.5 * con.total_area_np(size)]))
        assert f"static constexpr int k = {len(type(con).device_parameter_names)};" in con.device_surface().source


def test_device_parameters_of_another_width_than_their_names_are_refused():
    """A class deriving values without naming them (its CUDA code would read p[] of the wrong width)
    is told so when its size table is built, not left to read the wrong columns."""
    class Unnamed(Ellipsoid):
        def device_parameters(self, size):
            return np.column_stack([size, 1.0 / size ** 2])
    s = svm.init.random_tiling(40, seed=1, surface=Ellipsoid(1.0, 1.5, 2.0))
    state = svm.State(**s.arrays_np(), constraint=Unnamed(1.0, 1.5, 2.0), validate=False)
    with pytest.raises(ValueError, match="gives 6 values a replica, its CUDA code reads 3"):
        state.constraint.kernel_size(state)


def test_a_periodic_surface_keeps_its_box_first_among_its_device_parameters():
    """Implicit<Shape>::period reads the box from p[0], p[1]: a periodic class naming other device
    parameters first is refused when it is defined."""
    from spherevm.constraints import ImplicitSurface
    with pytest.raises(TypeError, match="first two device parameters are its box"):
        type("Wavy", (ImplicitSurface,), {"size_names": ("Lx", "Ly", "amplitude"), "periodic": True,
                                          "device_parameter_names": ("wavenumber", "Lx", "Ly")})


@pytest.mark.skipif(shutil.which("nvcc") is None, reason="no nvcc: the kernels are compiled at run time by CuPy")
@pytest.mark.parametrize("cu", ["plugins/forces/vertex_model.cu", "plugins/integrators/brownian.cu"])
def test_kernels_compile_for_an_implicit_surface(tmp_path, cu):
    """A kernel module after the ellipsoid's device code (the Newton projection), as surface_kernels
    compiles it (t1.cu: tests/test_t1_fold.py)."""
    source = tmp_path / "module.cu"
    surface = Ellipsoid(1.0, 1.5, 2.0).device_surface()
    source.write_text(surface.prelude + (PACKAGE / cu).read_text())
    done = subprocess.run(["nvcc", "-ptx", "-std=c++17", f"-I{PACKAGE}", *surface.options, str(source), "-o",
                           str(tmp_path / "m.ptx")], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr


def _host_gpu(tmp_path, monkeypatch, con, cu, *modules):
    """``cu`` built for the CPU after ``con``'s device code (tests/test_cuda_kernels_host.py's stand-ins),
    and the GPU paths of ``modules`` (plugins) running on it: cupy's allocations from NumPy, each
    launch calling the host kernel once per thread."""
    if find_compiler() is None:
        pytest.skip("no C++ compiler (g++ or c++) on the PATH")
    import types
    from test_cuda_headers import CXXFLAGS
    from test_cuda_kernels_host import Kernels
    source = tmp_path / "kernels.cpp"
    source.write_text('#include "cuda_host.h"\n#include "device_common.cuh"\n' + con.device_surface().prelude +
                      f'#include "{cu}"\nextern "C" void h_set_thread(long i)\n'
                      "{ blockIdx.x = (unsigned int)i; threadIdx.x = 0; blockDim.x = 1; }\n")
    lib = tmp_path / "libkernels.so"
    done = subprocess.run([find_compiler(), *CXXFLAGS, "-Wno-unknown-pragmas", f"-I{HERE / 'kernels'}", f"-I{PACKAGE}",
                           f"-I{HERE}", str(source), "-o", str(lib)], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    kernels = Kernels(lib)
    monkeypatch.setitem(sys.modules, "cupy", types.SimpleNamespace(empty=np.empty, zeros=np.zeros,
                                                                     empty_like=np.empty_like))
    functions = types.SimpleNamespace(get_function=lambda kernel: kernel)
    for module in modules:
        monkeypatch.setattr(module, "surface_kernels", lambda path, state: (functions, con.kernel_size(state)))
        monkeypatch.setattr(module, "launch", lambda kernel, n, args: kernels.launch(kernel, n, *args))


def _assert_same(got, ref):
    for a, b in ((got.forces, ref.forces), (got.energy, ref.energy), (got.cell_energy, ref.cell_energy)):
        assert np.abs(a - b).max() <= RTOL * np.abs(b).max()


def _per_cell_model(s):
    rng = np.random.default_rng(4)
    return VertexModel(kA=rng.uniform(0.5, 2, s.n_cells), kP=rng.uniform(0.5, 2, s.n_cells), A0=1.0,
                       P0=rng.uniform(3.4, 4.0, s.n_cells))


@pytest.mark.parametrize("name", ["torus", "bump"])
def test_vertex_model_gpu_path_on_the_host(tmp_path, monkeypatch, name):
    """VertexModel._compute_gpu (its allocations, the coefficients' width, the launches) with
    vertex_model.cu built for the CPU: vm_facet_terms' coefficients give the NumPy path's forces and
    energies to 1e-12."""
    from spherevm.plugins.forces import vertex_model
    con = SURFACES[name]()
    _host_gpu(tmp_path, monkeypatch, con, "plugins/forces/vertex_model.cu", vertex_model)
    s = svm.State.concatenate([svm.init.random_tiling(60, seed=3 + r, surface=con) for r in range(2)])
    vm = _per_cell_model(s)
    _assert_same(vm._compute_gpu(s), vm._compute_cpu(s))


@pytest.mark.parametrize("name", ["ellipsoid", "bump"])
def test_bending_gpu_paths_on_the_host(tmp_path, monkeypatch, name):
    """Bending._facets_gpu, alone and combined with the vertex model (bending.cu built for the CPU):
    the NumPy path's forces and energies to 1e-12, with per-replica B."""
    from spherevm.plugins.forces import Bending, bending
    con = SURFACES[name]()
    _host_gpu(tmp_path, monkeypatch, con, "plugins/forces/bending.cu", bending)
    s = svm.State.concatenate([svm.init.random_tiling(60, seed=5 + r, surface=con) for r in range(2)])
    force = Bending(np.array([0.5, 2.0]))
    got = force._compute_gpu(s)
    _assert_same(got, force._compute_cpu(s))
    assert np.abs(got.forces).max() > 1e-3
    vm = _per_cell_model(s)
    _assert_same(force._combined_gpu(vm, s), force._combined_cpu(vm, s))


# ------------------------------------------------------------------ T1's fold rule (plugins/updaters/t1_fold.cuh)
@pytest.fixture(scope="module")
def fold_header(tmp_path_factory):
    """tests/cuda_host/t1_fold_harness.cpp after each implicit surface's device code: {name: lib}."""
    if find_compiler() is None:
        pytest.skip("no C++ compiler (g++ or c++) on PATH: the CUDA header cannot be built for the CPU")
    libs = {}
    for name, make in SURFACES.items():
        directory = tmp_path_factory.mktemp(f"t1_fold_{name}")
        source = directory / "t1_fold.cpp"
        source.write_text(f'#include "cuda_host.h"\n{make().device_surface().prelude}'
                          f'#include "{HERE / "t1_fold_harness.cpp"}"\n')
        libs[name] = ctypes.CDLL(str(build_harness(directory, source=source)))
    return libs


def _p(a):
    return np.ascontiguousarray(a).ctypes.data_as(ctypes.c_void_p)


@pytest.mark.parametrize("kick, threshold", [(0.05, 0.4), (0.12, 0.6)])
def test_fold_rule_and_bow_ties_agree_with_numpy(fold_header, tissue, kick, threshold):
    """t1_positions, t1_fold_level (triangle_area, half_area, delta, normal) and t1_bow_tie
    (crossing_point) built for the host against folding.t1_fold_level and folding.inverted_edges on
    every candidate of kicked tissues."""
    from test_t1_fold import candidates
    name, s = tissue
    s = s.copy()
    con, rng = s.constraint, np.random.default_rng(int(100 * kick))
    size = con.size(s, s.vertex_replica)
    step = con.project_tangent(s.positions, rng.normal(scale=kick, size=s.positions.shape), size)
    s.positions = con.project_normal(s.positions + step, size)
    lib = fold_header[name]
    u, slot, new = candidates(s, threshold)
    vn, vc, pos = s.vertex_neighbors, s.vertex_cells, s.positions
    v, a, b, c, d, C1, C2, C3, C4 = topology.t1_cells(vn, vc, u, slot)
    n = len(u)
    cand = np.stack([u, v, a, b, c, d, C1, C2, C3, C4], axis=1).astype(np.int32)
    table = np.ascontiguousarray(con.kernel_size(s)[s.vertex_replica_np()[u]])
    scale = con.length_scale(con.size_np(s)[s.vertex_replica_np()[u]])[:, None]
    found = set()
    for turn in (False, True):
        px, py = topology.t1_new_positions(s, pos, u, v, a, b, c, d, new, np.full(n, turn))
        hx, hy = np.empty((n, 3)), np.empty((n, 3))
        lib.h_t1_positions(ctypes.c_long(n), _p(pos), _p(cand), _p(table), _p(new.astype(np.float64)),
                           ctypes.c_int(turn), _p(hx), _p(hy))
        assert np.max(np.abs(hx - px) / scale) < 1e-12 and np.max(np.abs(hy - py) / scale) < 1e-12
        host = np.empty(n, dtype=np.int32)
        lib.h_t1_fold_level(ctypes.c_long(n), _p(pos), _p(vn.astype(np.int32)), _p(s.cell_vertices.astype(np.int32)),
                            _p(s.cell_sides.astype(np.int32)), ctypes.c_int(s.cell_vertices.shape[1]), _p(cand),
                            _p(table), _p(px), _p(py), host.ctypes.data_as(ctypes.c_void_p))
        rule = folding.t1_fold_level(s, u, slot, new, turn=np.full(n, turn))
        assert np.array_equal(host, rule), np.flatnonzero(host != rule)
        found |= set(rule.tolist())
    assert n > 20 and found >= {0, 2}, (n, found)
    corner = np.flatnonzero((np.arange(s.n_vertices)[:, None] < vn).reshape(-1))
    eu, eslot = corner // 3, corner % 3
    ecand = np.stack([eu, *topology.t1_cells(vn, vc, eu, eslot)], axis=1)[:, :10].astype(np.int32)
    bow = np.empty(len(eu), dtype=np.int32)
    lib.h_t1_bow_tie(ctypes.c_long(len(eu)), _p(pos), _p(ecand), _p(con.kernel_size(s)[s.vertex_replica_np()[eu]]),
                     bow.ctypes.data_as(ctypes.c_void_p))
    iu, islot = folding.inverted_edges(s)
    assert np.array_equal(corner[bow == 1], np.sort(3 * iu + islot))
    assert kick < 0.1 or len(iu) > 0          # the harder kick crosses edges
