"""T1 flips that would fold the network are refused (issue 13, item 7): a flip must leave its four
cells with positive signed area (as the forces will measure it) and must not invert a corner
(turn the three edges at one of its six vertices clockwise) that was not inverted.

Checked here: the rule (spherevm.folding.t1_folds) against flipping a copy and measuring it with
code written here; constructed flips that fold, on the sphere and the plane; the CUDA header
t1_fold.cuh compiled on the CPU against the NumPy rule (positions and decisions), and t1.cu
compiled with nvcc where there is one. tests/test_fuzz.py counts folds under fuzzing."""
import ctypes
import pathlib
import shutil
import subprocess

import numpy as np
import pytest

import spherevm as svm
from spherevm import folding, topology
from spherevm.plugins.updaters import T1

from test_cuda_headers import HERE, PACKAGE, build_harness, find_compiler
from test_fuzz import fan_areas as cell_fan_areas, inverted_corners


# ------------------------------------------------------------------ measured independently
def folds_when_flipped(state, u, slot, new_length):
    """Flip each candidate alone on a copy and look: a cell of area <= 0, or a new inverted corner."""
    out = []
    before = inverted_corners(state)
    for i in range(len(u)):
        st = state.copy()
        v, a, b, c, d, *cells = topology.t1_cells(st.vertex_neighbors, st.vertex_cells, u[i:i + 1], slot[i:i + 1])
        topology.t1_flip(st, u[i:i + 1], slot[i:i + 1], new_length[i:i + 1])
        area = cell_fan_areas(st)[np.concatenate(cells)]
        six = np.concatenate([u[i:i + 1], v, a, b, c, d])
        out.append(bool((area <= 0).any() or (inverted_corners(st)[six] & ~before[six]).any()))
    return np.array(out)


def kicked(n_cells, seed, kick, replicas=2):
    state = svm.init.random_tiling(n_cells, replicas=replicas, seed=seed)
    rng = np.random.default_rng(seed)
    con, pos = state.constraint, state.positions
    state.positions = con.project_normal(pos + con.project_tangent(pos, rng.normal(scale=kick, size=pos.shape)),
                                         state.radius[state.vertex_replica])
    return state


def candidates(state, threshold):
    t1 = T1(threshold=threshold, new_length=1.5 * threshold)
    u, slot, lengths = t1.short_edges(state)
    cells = np.stack(topology.t1_cells(state.vertex_neighbors, state.vertex_cells, u, slot)[5:], axis=1)
    ok = (np.sort(cells, axis=1)[:, 1:] != np.sort(cells, axis=1)[:, :-1]).all(axis=1)
    ok &= (state.cell_sides[cells[:, 0]] > 3) & (state.cell_sides[cells[:, 1]] > 3)
    return u[ok], slot[ok], t1.new_lengths(state, u[ok], lengths[ok])


@pytest.mark.parametrize("n_cells, seed, kick, threshold", [(40, 1, 0.05, 0.4), (24, 2, 0.12, 0.5), (12, 3, 0.1, 0.9)])
def test_rule_is_what_flipping_a_copy_shows(n_cells, seed, kick, threshold):
    state = kicked(n_cells, seed, kick)
    u, slot, new = candidates(state, threshold)
    rule = folding.t1_folds(state, u, slot, new)
    seen = folds_when_flipped(state, u, slot, new)
    assert len(u) > 20 and rule.any() and (~rule).any(), (len(u), rule.sum())
    assert np.array_equal(rule, seen), np.flatnonzero(rule != seen)


def _dodecahedron_pass(new_length):
    """One T1 pass on a dodecahedron whose every edge is short, flips new_length sqrt(<A>) long."""
    sim = svm.Simulation(device="cpu")
    sim.state = svm.init.regular_tiling("dodecahedron")
    t1 = T1(threshold=0.75, new_length=new_length)
    sim.operations.updaters.append(t1)
    before = sim.state.positions.copy()
    sim._update()
    return sim, t1, before


def test_a_flip_that_would_fold_is_refused_and_counted():
    """Pentagons of area 1 and edges of 0.70: a new edge of 0.8 folds nothing; one of 4.0 puts the
    flipped vertices beyond the cells across it, which would fold them."""
    sim, t1, _ = _dodecahedron_pass(0.8)
    assert t1.last_flips.sum() >= 1 and t1.last_refused.sum() == 0
    sim.state.validate()
    sim, t1, before = _dodecahedron_pass(4.0)
    assert t1.last_flips.sum() == 0 and t1.last_refused.sum() == 30       # every edge, refused and counted
    assert np.array_equal(sim.state.positions, before)                    # nothing moved
    st = svm.init.regular_tiling("dodecahedron")
    u = np.array([0])
    slot = np.array([0])
    flipped = st.copy()
    topology.t1_flip(flipped, u, slot, np.array([4.0 * np.sqrt(st.mean_cell_area[0])]))
    assert (cell_fan_areas(flipped) <= 0).any() or inverted_corners(flipped).any()   # it really folds


def test_a_folding_flip_on_the_plane_is_refused():
    state = svm.init_plane.hexagonal_tiling(4, 4)
    sim = svm.Simulation(device="cpu")
    sim.state = state
    t1 = T1(threshold=2.0, new_length=5.0)
    sim.operations.updaters.append(t1)
    sim._update()
    assert t1.last_flips.sum() == 0 and t1.last_refused.sum() > 0
    t1b = T1(threshold=2.0, new_length=2.05)
    sim.operations.updaters[:] = [t1b]
    sim._update()
    assert t1b.last_flips.sum() >= 1
    sim.state.validate()


def test_ordinary_minimisations_refuse_nothing_that_does_not_fold():
    """A FIRE + T1 minimisation: every refusal by the fold rule is a flip that really folds."""
    sim = svm.Simulation(device="cpu")
    sim.state = svm.init.random_tiling(200, replicas=3, seed=5)
    sim.operations.forces.append(svm.plugins.forces.VertexModel.dimensionless(kr=1.0, p0=3.8))
    sim.operations.updaters.append(T1())
    sim.operations.integrator = svm.plugins.integrators.FIRE(dt=0.02)
    checked = []
    rule = folding.t1_folds

    def spy(state, u, slot, new_length):
        out = rule(state, u, slot, new_length)
        checked.append(np.array_equal(out, folds_when_flipped(state, u, slot, np.asarray(new_length))))
        return out

    folding.t1_folds = spy
    try:
        res = sim.minimize(force_tol=1e-9, max_steps=3000)
    finally:
        folding.t1_folds = rule
    assert res.all_converged and len(checked) > 10 and all(checked)


# ------------------------------------------------------------------ the CUDA header on the CPU
@pytest.fixture(scope="module")
def fold_header(tmp_path_factory):
    """The header built for the sphere and for the plane: {"sphere": lib, "plane": lib}."""
    if find_compiler() is None:
        pytest.skip("no C++ compiler (g++ or c++) on PATH: the CUDA header cannot be built for the CPU")
    return {name: ctypes.CDLL(str(build_harness(tmp_path_factory.mktemp(f"t1_fold_{name}"), source=HERE / source)))
            for name, source in (("sphere", "t1_fold_harness.cpp"), ("plane", "t1_fold_harness_plane.cpp"))}


def _p(a):
    return a.ctypes.data_as(ctypes.c_void_p)


def kicked_plane(n_cells, seed, kick, replicas=3):
    state = svm.init_plane.random_planar_tiling(n_cells, replicas=replicas, seed=seed)
    rng = np.random.default_rng(seed)
    con = state.constraint
    step = con.project_tangent(state.positions, rng.normal(scale=kick, size=state.positions.shape))
    state.positions = con.project_normal(state.positions + step, state.box[state.vertex_replica])
    return state


@pytest.mark.parametrize("surface, n_cells, seed, kick, threshold", [
    ("sphere", 40, 1, 0.05, 0.3), ("sphere", 24, 2, 0.12, 0.5), ("sphere", 12, 3, 0.1, 0.9),
    ("sphere", 200, 4, 0.02, 0.25), ("plane", 40, 1, 0.05, 0.4), ("plane", 60, 2, 0.12, 0.5)])
def test_cuda_header_agrees_with_numpy(fold_header, surface, n_cells, seed, kick, threshold):
    """Surface::t1_positions and t1_would_fold, built for the host, against topology.t1_new_positions
    and folding.t1_folds on every candidate of kicked tilings (a few hundred, folding or not)."""
    state = kicked(n_cells, seed, kick, replicas=3) if surface == "sphere" else kicked_plane(n_cells, seed, kick)
    lib = fold_header[surface]
    u, slot, new = candidates(state, threshold)
    vn, vc, pos = state.vertex_neighbors, state.vertex_cells, state.positions
    v, a, b, c, d, C1, C2, C3, C4 = topology.t1_cells(vn, vc, u, slot)
    px, py = topology.t1_new_positions(state, pos, u, v, a, b, c, d, new)
    n = len(u)
    cand = np.ascontiguousarray(np.stack([u, v, a, b, c, d, C1, C2, C3, C4], axis=1), dtype=np.int32)
    size = np.ascontiguousarray(state.constraint.size_np(state)[state.vertex_replica_np()[u]], dtype=np.float64)
    hx, hy = np.empty((n, 3)), np.empty((n, 3))
    lib.h_t1_positions(ctypes.c_long(n), _p(np.ascontiguousarray(pos)), _p(cand), _p(size),
                       _p(np.ascontiguousarray(new, dtype=np.float64)), _p(hx), _p(hy))
    scale = state.constraint.length_scale(size)[:, None]
    assert np.max(np.abs(hx - px) / scale) < 1e-14 and np.max(np.abs(hy - py) / scale) < 1e-14
    table = np.ascontiguousarray(state.cell_vertices, dtype=np.int32)
    host = np.empty(n, dtype=np.int32)
    lib.h_t1_would_fold(ctypes.c_long(n), _p(np.ascontiguousarray(pos)), _p(np.ascontiguousarray(vn, np.int32)),
                        _p(table), _p(np.ascontiguousarray(state.cell_sides, np.int32)), ctypes.c_int(table.shape[1]),
                        _p(cand), _p(size), _p(np.ascontiguousarray(px)), _p(np.ascontiguousarray(py)), _p(host))
    rule = folding.t1_folds(state, u, slot, new)
    assert n > 20 and rule.any() and (~rule).any(), (n, rule.sum())
    assert np.array_equal(host.astype(bool), rule), np.flatnonzero(host.astype(bool) != rule)


@pytest.mark.skipif(shutil.which("nvcc") is None, reason="no nvcc: the T1 kernels are compiled at run time by CuPy")
@pytest.mark.parametrize("flags", [[], ["-DSVM_SURFACE_PLANE"]], ids=["sphere", "plane"])
def test_t1_kernels_compile(tmp_path, flags):
    kernel = PACKAGE / "plugins" / "updaters" / "t1.cu"
    done = subprocess.run(["nvcc", "-ptx", "-std=c++17", *flags, f"-I{PACKAGE}", str(kernel), "-o",
                           str(tmp_path / "t1.ptx")], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    assert pathlib.Path(tmp_path / "t1.ptx").stat().st_size > 0
