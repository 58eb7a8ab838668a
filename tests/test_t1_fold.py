"""T1 flips never fold the network (issue 13, item 7): a flip must leave its four cells with positive
signed area (as the forces will measure it) adding up to what they did, and must not invert a
corner (turn the three edges at one of its six vertices clockwise) that was not inverted; where the
usual placement would, the edge is rotated the other way round if that is clean (or, where the
usual one folds, if it only keeps corners inverted already), else refused.

Checked here: the rule (spherevm.folding.t1_fold_level) against flipping a copy and measuring it
with code written here; constructed flips that fold, on the sphere and the plane, and an edge
turned past its cells; the CUDA header t1_fold.cuh compiled on the CPU for both surfaces against
the NumPy rule (positions, levels, placements), and t1.cu compiled with nvcc where there is one.
tests/test_fuzz.py counts folds under fuzzing."""
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
def level_when_flipped(state, u, slot, new_length, turn=None):
    """Flip each candidate alone on a copy and look: 2 for a cell of area <= 0, a replica whose
    cells no longer add up to its sphere (mod nothing), or a new inverted corner; 1 for an inverted
    corner among the six that was inverted before; 0 otherwise."""
    out = []
    before = inverted_corners(state)
    total = np.bincount(state.cell_replica_np(), weights=cell_fan_areas(state))
    turn = np.zeros(len(u), dtype=bool) if turn is None else np.asarray(turn, dtype=bool)
    for i in range(len(u)):
        st = state.copy()
        v, a, b, c, d, *cells = topology.t1_cells(st.vertex_neighbors, st.vertex_cells, u[i:i + 1], slot[i:i + 1])
        topology.t1_flip(st, u[i:i + 1], slot[i:i + 1], new_length[i:i + 1], turn=turn[i:i + 1])
        areas = cell_fan_areas(st)
        moved = np.abs(np.bincount(st.cell_replica_np(), weights=areas) - total).max() > 1.0
        six = np.concatenate([u[i:i + 1], v, a, b, c, d])
        inverted = inverted_corners(st)[six]
        if (areas[np.concatenate(cells)] <= 0).any() or moved or (inverted & ~before[six]).any():
            out.append(2)
        else:
            out.append(int(inverted.any()))
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
    for turn in (False, True):
        rule = folding.t1_fold_level(state, u, slot, new, turn=np.full(len(u), turn))
        seen = level_when_flipped(state, u, slot, new, turn=np.full(len(u), turn))
        assert len(u) > 20 and (rule == 2).any() and (turn or (rule == 0).any()), (len(u), np.bincount(rule))
        assert np.array_equal(rule, seen), np.flatnonzero(rule != seen)


def _dodecahedron_pass(new_length):
    """One T1 pass on a dodecahedron whose every edge is short, flips new_length sqrt(<A>) long."""
    sim = svm.Simulation(device="cpu")
    sim.state = svm.init.regular_tiling("dodecahedron")
    t1 = T1(threshold=0.75, new_length=new_length)
    sim.operations.updaters.append(t1)
    before = sim.state.positions.copy()
    sim.run_updaters()
    return sim, t1, before


def test_a_flip_that_would_fold_is_refused_and_counted():
    """Pentagons of area 1 and edges of 0.70: a new edge of 0.8 folds nothing; one of 4.0 puts the
    flipped vertices beyond the cells across it, which would fold them, whichever way it turns."""
    sim, t1, _ = _dodecahedron_pass(0.8)
    assert t1.last_flips.sum() >= 1 and t1.last_refused.sum() == 0
    sim.state.validate()
    st = svm.init.regular_tiling("dodecahedron")
    new = np.array([4.0 * np.sqrt(st.mean_cell_area[0])])
    for turn in (False, True):
        assert level_when_flipped(st, np.array([0]), np.array([0]), new, turn=[turn])[0] == 2   # it really folds
    assert folding.t1_placement(st, np.array([0]), np.array([0]), new)[0].all()
    sim, t1, before = _dodecahedron_pass(4.0)
    refused = t1.last_refused.sum()
    assert refused >= 1 and refused + t1.last_flips.sum() <= 30
    sim.state.validate()                                        # what flipped (turned) folded nothing
    assert not inverted_corners(sim.state).any()


def backwards_edge():
    """A dodecahedron whose edge (u, v) the 'dynamics' turned past its cells: shortened to 0.02 and
    its ends swapped across the midpoint, so that u -> v points the wrong way."""
    st = svm.init.regular_tiling("dodecahedron")
    u, slot = 0, 0
    v = int(st.vertex_neighbors[u, slot])
    pos = st.positions.copy()
    R = np.linalg.norm(pos[u])
    m = (pos[u] + pos[v]) / np.linalg.norm(pos[u] + pos[v])
    t = pos[v] - pos[u]
    t -= (t @ m) * m
    t /= np.linalg.norm(t)
    h = 0.01 * np.sqrt(st.mean_cell_area[0]) / R
    pos[u], pos[v] = R * (np.cos(h) * m + np.sin(h) * t), R * (np.cos(h) * m - np.sin(h) * t)
    st.positions = pos
    return st, np.array([u]), np.array([slot])


def test_an_edge_turned_past_its_cells_flips_the_other_way():
    """The usual rotation would put X among the cells across the edge (an inverted corner); turned
    the other way the flip folds nothing, so it flips that way (folding.t1_placement)."""
    st, u, slot = backwards_edge()
    assert inverted_corners(st)[[0, int(st.vertex_neighbors[0, 0])]].all()  # the swap inverted both ends
    new = np.array([0.12 * np.sqrt(st.mean_cell_area[0])])
    refused, turn = folding.t1_placement(st, u, slot, new)
    assert not refused[0] and turn[0]
    assert level_when_flipped(st, u, slot, new, turn=[True])[0] == 0
    sim = svm.Simulation(device="cpu")
    sim.state = st
    t1 = T1()
    sim.operations.updaters.append(t1)
    sim.run_updaters()
    assert t1.last_flips.tolist() == [1] and t1.last_refused.tolist() == [0]
    sim.state.validate()
    assert not inverted_corners(sim.state).any()                # the flip cured the swapped edge


def test_a_folding_flip_on_the_plane_is_refused():
    state = svm.init_plane.hexagonal_tiling(4, 4)
    sim = svm.Simulation(device="cpu")
    sim.state = state
    t1 = T1(threshold=2.0, new_length=5.0)
    sim.operations.updaters.append(t1)
    sim.run_updaters()
    assert t1.last_flips.sum() == 0 and t1.last_refused.sum() > 0
    t1b = T1(threshold=2.0, new_length=2.05)
    sim.operations.updaters[:] = [t1b]
    sim.run_updaters()
    assert t1b.last_flips.sum() >= 1
    sim.state.validate()


def test_ordinary_minimisations_refuse_nothing_that_does_not_fold():
    """A FIRE + T1 minimisation: the rule's verdict on every candidate (either way round) is what
    flipping a copy shows."""
    sim = svm.Simulation(device="cpu")
    sim.state = svm.init.random_tiling(200, replicas=3, seed=5)
    sim.operations.forces.append(svm.plugins.forces.VertexModel.dimensionless(kr=1.0, p0=3.8))
    sim.operations.updaters.append(T1())
    sim.operations.integrator = svm.plugins.integrators.FIRE(dt=0.02)
    checked = []
    rule = folding.t1_fold_level

    def spy(state, u, slot, new_length, turn=None):
        out = rule(state, u, slot, new_length, turn)
        checked.append(np.array_equal(out, level_when_flipped(state, u, slot, np.asarray(new_length), turn)))
        return out

    folding.t1_fold_level = spy
    try:
        res = sim.minimize(force_tol=1e-9, max_steps=3000)
    finally:
        folding.t1_fold_level = rule
    assert res.all_converged and len(checked) > 10 and all(checked)


def test_a_flip_that_folds_turns_where_turned_it_only_keeps_inverted_corners():
    """Untangling (``T1(untangle=True)``): where the usual placement folds and the turned one only
    keeps corners inverted already, the flip turns rather than being refused (t1_pass.cuh's
    t1_placement_refused decides the same): a crossed edge beside a fold is flipped, which untangling
    needs (else the edges next to it flip back and forth, docs/validation.md). Without untangling the
    flip is refused, as the rule always was."""
    state = kicked(40, 6, 0.15, replicas=3)
    u, slot, new = candidates(state, 0.6)
    usual = folding.t1_fold_level(state, u, slot, new)
    turned = folding.t1_fold_level(state, u, slot, new, turn=np.ones(len(u), dtype=bool))
    pick = np.flatnonzero((usual == 2) & (turned == 1))
    assert len(pick) > 0
    refused, turn = folding.t1_placement(state, u[pick], slot[pick], new[pick], untangle=True)
    assert turn.all() and not refused.any()
    assert folding.t1_placement(state, u[pick], slot[pick], new[pick])[0].all()
    assert (level_when_flipped(state, u[pick], slot[pick], new[pick], turn=turn) == 1).all()


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
    """Surface::t1_positions and t1_fold_level, built for the host, against topology.t1_new_positions
    and folding.t1_fold_level on every candidate of kicked tilings (a few hundred, folding or not)."""
    state = kicked(n_cells, seed, kick, replicas=3) if surface == "sphere" else kicked_plane(n_cells, seed, kick)
    lib = fold_header[surface]
    u, slot, new = candidates(state, threshold)
    vn, vc, pos = state.vertex_neighbors, state.vertex_cells, state.positions
    v, a, b, c, d, C1, C2, C3, C4 = topology.t1_cells(vn, vc, u, slot)
    n = len(u)
    cand = np.ascontiguousarray(np.stack([u, v, a, b, c, d, C1, C2, C3, C4], axis=1), dtype=np.int32)
    size = np.ascontiguousarray(state.constraint.size_np(state)[state.vertex_replica_np()[u]], dtype=np.float64)
    table = np.ascontiguousarray(state.cell_vertices, dtype=np.int32)
    scale = state.constraint.length_scale(size)[:, None]
    levels = {}
    for turn in (False, True):      # t1_detect: the usual placement, then the other way round
        px, py = topology.t1_new_positions(state, pos, u, v, a, b, c, d, new, np.full(n, turn))
        hx, hy = np.empty((n, 3)), np.empty((n, 3))
        lib.h_t1_positions(ctypes.c_long(n), _p(np.ascontiguousarray(pos)), _p(cand), _p(size),
                           _p(np.ascontiguousarray(new, dtype=np.float64)), ctypes.c_int(turn), _p(hx), _p(hy))
        assert np.max(np.abs(hx - px) / scale) < 1e-14 and np.max(np.abs(hy - py) / scale) < 1e-14
        host = np.empty(n, dtype=np.int32)
        lib.h_t1_fold_level(ctypes.c_long(n), _p(np.ascontiguousarray(pos)), _p(np.ascontiguousarray(vn, np.int32)),
                            _p(table), _p(np.ascontiguousarray(state.cell_sides, np.int32)), ctypes.c_int(table.shape[1]),
                            _p(cand), _p(size), _p(np.ascontiguousarray(px)), _p(np.ascontiguousarray(py)), _p(host))
        rule = folding.t1_fold_level(state, u, slot, new, turn=np.full(n, turn))
        assert np.array_equal(host, rule), np.flatnonzero(host != rule)
        levels[turn] = rule
    keeps = (levels[False] == 2) & (levels[True] == 1)          # usual folds, turned only keeps inverted corners
    for untangle in (False, True):       # what t1_detect decides from the two levels
        refused, turned = folding.t1_placement(state, u, slot, new, untangle)
        assert np.array_equal(turned, (levels[False] != 0) & ((levels[True] == 0) | (untangle & keeps)))
        assert np.array_equal(refused, (levels[False] == 2) & ~turned)
    assert n > 20 and (levels[False] == 2).any() and (levels[False] == 0).any(), (n, np.bincount(levels[False]))


@pytest.mark.skipif(shutil.which("nvcc") is None, reason="no nvcc: the T1 kernels are compiled at run time by CuPy")
@pytest.mark.parametrize("surface", [svm.constraints.Sphere(), svm.constraints.PeriodicPlane()],
                         ids=["sphere", "plane"])
def test_t1_kernels_compile(tmp_path, surface):
    """t1.cu after the surface's device code, as surface_kernels compiles it."""
    source = tmp_path / "t1.cu"
    source.write_text(surface.device_surface().prelude + (PACKAGE / "plugins" / "updaters" / "t1.cu").read_text())
    done = subprocess.run(["nvcc", "-ptx", "-std=c++17", f"-I{PACKAGE}", str(source), "-o",
                           str(tmp_path / "t1.ptx")], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    assert pathlib.Path(tmp_path / "t1.ptx").stat().st_size > 0


@pytest.mark.parametrize("surface, n_cells, seed, kick", [("sphere", 60, 5, 0.3), ("sphere", 200, 6, 0.2),
                                                          ("plane", 60, 5, 0.3), ("plane", 200, 6, 0.2)])
def test_cuda_bow_tie_test_agrees_with_numpy(fold_header, surface, n_cells, seed, kick):
    """t1_bow_tie (t1_detect's untangling candidates), built for the host, against
    folding.inverted_edges on every edge of tilings kicked hard enough to cross many."""
    state = kicked(n_cells, seed, kick, replicas=3) if surface == "sphere" else kicked_plane(n_cells, seed, kick)
    vn, vc = state.vertex_neighbors, state.vertex_cells
    corner = np.flatnonzero((np.arange(state.n_vertices)[:, None] < vn).reshape(-1))
    u, slot = corner // 3, corner % 3
    cand = np.ascontiguousarray(np.stack([u, *topology.t1_cells(vn, vc, u, slot)], axis=1)[:, :10], dtype=np.int32)
    size = np.ascontiguousarray(state.constraint.size_np(state)[state.vertex_replica_np()[u]], dtype=np.float64)
    host = np.empty(len(u), dtype=np.int32)
    fold_header[surface].h_t1_bow_tie(ctypes.c_long(len(u)), _p(np.ascontiguousarray(state.positions)), _p(cand),
                                      _p(size), _p(host))
    iu, islot = folding.inverted_edges(state)
    assert len(iu) > 10
    assert np.array_equal(corner[host == 1], np.sort(3 * iu + islot))
