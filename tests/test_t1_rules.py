"""T1 rules reached one by one: each refusal branch, the conflict rule, the reference preset's and the
default rule's new edge length, with the ``t1_flips`` / ``t1_refused`` counts and a valid network after.

Edges are made short on purpose (their ends placed symmetrically about the midpoint, at a chosen
geodesic separation), so every branch runs; lengths are measured here, not with spherevm's geometry.
"""
import numpy as np
import pytest

import spherevm as svm
from spherevm import folding, topology
from spherevm.plugins.base import Integrator
from spherevm.plugins.integrators import FIRE
from spherevm.plugins.updaters import T1

from conftest import to_numpy


# ---------------------------------------------------------------------- helpers (plain NumPy)
def geodesic(p, q):
    """Geodesic distance on the sphere through p and q (same radius)."""
    R = np.linalg.norm(p)
    return R * np.arctan2(np.linalg.norm(np.cross(p, q)), np.dot(p, q))


def with_edge_length(pos, u, v, length):
    """Positions with u and v symmetric about their midpoint, ``length`` apart along the old edge."""
    pos = pos.copy()
    R = np.linalg.norm(pos[u])
    m = pos[u] + pos[v]
    m /= np.linalg.norm(m)
    t = pos[v] - pos[u]
    t -= np.dot(t, m) * m
    t /= np.linalg.norm(t)
    h = 0.5 * length / R
    pos[u] = R * (np.cos(h) * m - np.sin(h) * t)
    pos[v] = R * (np.cos(h) * m + np.sin(h) * t)
    return pos


def edge_index(vn, u, v):
    a, b = min(u, v), max(u, v)
    return 3 * a + int(np.flatnonzero(vn[a] == b)[0])


def edge_cells(state, u, v):
    """(C1, C2, C3, C4) of the edge u - v, with u < v (the updater's orientation)."""
    vn, vc = to_numpy(state.vertex_neighbors), to_numpy(state.vertex_cells)
    a, b = min(u, v), max(u, v)
    slot = int(np.flatnonzero(vn[a] == b)[0])
    *_, C1, C2, C3, C4 = topology.t1_cells(vn, vc, np.array([a]), np.array([slot]))
    return int(C1[0]), int(C2[0]), int(C3[0]), int(C4[0])


def short_edges(state, threshold):
    """Edges (u, v), u < v, geodesically shorter than threshold * sqrt(<A>) of their replica."""
    pos, vn = to_numpy(state.positions), to_numpy(state.vertex_neighbors)
    unit = np.sqrt(4 * np.pi * state.radius_np() ** 2 / np.diff(state.cell_start))
    rep = state.vertex_replica_np()
    return sorted((u, int(v)) for u in range(len(vn)) for v in vn[u]
                  if u < v and geodesic(pos[u], pos[v]) < threshold * unit[rep[u]])


def t1_sim(state, t1, device):
    """T1 then FIRE without forces: FIRE stops every replica at its first check, so the positions a
    pass leaves are not moved afterwards; one ``run(1)`` is exactly one T1 pass."""
    sim = svm.Simulation(device=device)
    sim.state = state
    sim.operations.updaters.append(t1)
    sim.operations.integrator = FIRE(dt=0.01)
    return sim


def topology_arrays(state):
    return [to_numpy(a).copy() for a in (state.cell_vertices, state.cell_sides, state.vertex_neighbors,
                                          state.vertex_cells)]


# ---------------------------------------------------------------------- refusals
# A network reached by a T1 random walk on an 8-cell tiling (seed 5, threshold 0.5, kicks 0.15,
# 8 kicks and 7 passes), stored so that it does not depend on the walk. Three edges are shorter than
# 0.5: (2, 4) between two triangles, (8, 10) whose C2 is a triangle, and (5, 9) whose C1 and C2
# have 6 and 5 sides but whose end cells coincide (C3 == C4): flipping it would give that cell an
# edge with itself on both sides. Cell 3 is folded and cell 5 covers more than a hemisphere (the
# walk is not a physical run): the checks here are of the network (``validate(cover=False)``).
WALK_R = 0.7978845608028654
WALK_POS = [
    [0.054714158365134574, -0.712486093705776, 0.3549502775289246],
    [-0.00042517808314499486, -0.20871909532744867, -0.7701012471336937],
    [-0.2950360323787866, -0.6517054634742266, -0.3533461487601196],
    [-0.6672848446883402, -0.027944173801951962, 0.43654304663728805],
    [-0.42017871336160484, -0.6340484855435428, -0.2409401153509055],
    [-0.17203744732978168, -0.6160921208875558, -0.4769207352004182],
    [-0.323317881445589, 0.4269154120273836, -0.5914630596060981],
    [0.5526893913750507, 0.2239487780463463, -0.5300954195619936],
    [0.11662923490853513, 0.7893046297907629, -0.0039490914268796905],
    [-0.5600590391379322, -0.5330457851686513, -0.1970173493919087],
    [-0.27760779908689504, 0.7241902083993393, 0.18735587610809817],
    [0.6658759420006379, 0.43952315744176235, 0.006956745271193195],
]
WALK_CELLS = [[2, 0, 4], [9, 3, 10, 6, 7, 5], [1, 2, 4], [5, 0, 2, 1, 9], [11, 7, 6, 8], [11, 3, 9, 1, 4, 0, 5, 7],
              [6, 10, 8], [11, 8, 10, 3]]


def walk_state():
    return svm.init.from_polygons(WALK_POS, WALK_CELLS, WALK_R, validate=False)


def test_the_stored_network_reaches_every_refusal_branch():
    s = walk_state()
    s.validate(cover=False)
    sides = s.cell_sides
    assert short_edges(s, 0.5) == [(2, 4), (5, 9), (8, 10)]
    C1, C2, C3, C4 = edge_cells(s, 2, 4)
    assert sides[C1] == 3 and sides[C2] == 3 and len({C1, C2, C3, C4}) == 4
    C1, C2, C3, C4 = edge_cells(s, 8, 10)
    assert sides[C1] > 3 and sides[C2] == 3 and len({C1, C2, C3, C4}) == 4
    C1, C2, C3, C4 = edge_cells(s, 5, 9)
    assert sides[C1] > 3 and sides[C2] > 3 and C3 == C4 and len({C1, C2, C3}) == 3


def test_every_refusal_is_counted_and_nothing_flips(device):
    s = walk_state()
    t1 = T1(threshold=0.5, new_length=0.75)
    sim = t1_sim(s, t1, device)
    before = topology_arrays(sim.state)
    pos0 = to_numpy(sim.state.positions).copy()
    sim.run(1)
    assert sim.log("t1_refused").tolist() == [3]
    assert sim.log("t1_flips").tolist() == [0]
    assert sim.log("t1_total_refused").tolist() == [3] and sim.log("t1_total_flips").tolist() == [0]
    for a, b in zip(topology_arrays(sim.state), before):
        assert np.array_equal(a, b)
    assert np.array_equal(to_numpy(sim.state.positions), pos0)
    sim.state.validate(cover=False)


@pytest.mark.parametrize("u, v", [(2, 4), (8, 10), (5, 9)], ids=["two-triangles", "C2-triangle", "C3-is-C4"])
def test_each_refusal_alone(device, u, v):
    """Only one short edge (all others lengthened past the threshold): that branch alone refuses."""
    s = walk_state()
    pos = s.positions
    for p, q in [(2, 4), (8, 10), (5, 9)]:
        if (p, q) != (u, v):
            pos = with_edge_length(pos, p, q, 0.6 * np.sqrt(np.pi * 4 * WALK_R ** 2 / 8))
    s.positions = pos
    assert short_edges(s, 0.5) == [(u, v)]
    t1 = T1(threshold=0.5, new_length=0.75)
    sim = t1_sim(s, t1, device)
    before = topology_arrays(sim.state)
    sim.run(1)
    assert sim.log("t1_refused").tolist() == [1] and sim.log("t1_flips").tolist() == [0]
    for a, b in zip(topology_arrays(sim.state), before):
        assert np.array_equal(a, b)
    sim.state.validate(cover=False)


class Kick(Integrator):
    """Random tangent kicks (the random walk of the T1 tests), drawn on the host."""

    def __init__(self, scale, seed):
        super().__init__()
        self.scale, self.rng = scale, np.random.default_rng(seed)

    def step(self, simulation, forces):
        st = simulation.state
        con, xp = st.constraint, st.device.xp
        noise = xp.asarray(self.rng.normal(scale=self.scale, size=st.positions.shape))
        rad = xp.asarray(st.radius_np()[st.vertex_replica_np()])
        st.positions = con.project_normal(st.positions + con.project_tangent(st.positions, noise), rad)
        simulation.state_changed()


def _non_distinct_candidates(state, threshold):
    out = 0
    sides = to_numpy(state.cell_sides)
    for u, v in short_edges(state, threshold):
        C1, C2, C3, C4 = edge_cells(state, u, v)
        out += sides[C1] > 3 and sides[C2] > 3 and len({C1, C2, C3, C4}) < 4
    return out


@pytest.mark.parametrize("n_cells, seed, passes", [(8, 5, 10), (7, 3, 25)])
def test_small_tiling_walks_meet_non_distinct_cells_and_stay_valid(monkeypatch, n_cells, seed, passes):
    """The issue's case: on tiny tilings a T1 walk meets edges whose four cells are not distinct;
    flipping one leaves an invalid network. The walks reach those edges through flips that fold the
    network, which the fold rule refuses first (tests/test_t1_fold.py); the distinctness rule must
    hold on its own, so the fold rule is off here (CPU; test_each_refusal_alone covers the GPU)."""
    monkeypatch.setattr(folding, "t1_placement", lambda state, u, slot, new_length, untangle=False: (np.zeros(len(u), dtype=bool),) * 2)
    state = svm.init.random_tiling(n_cells, seed=seed)
    sim = svm.Simulation(device="cpu")
    sim.state = state
    t1 = T1(threshold=0.5, new_length=0.75, max_flip_backs=10 ** 9)
    sim.operations.updaters.append(t1)
    kick = Kick(0.15, seed)
    sim.operations.integrator = kick
    kick.step(sim, None)                    # kick, then (T1 pass, kick) per run(1)
    seen = 0
    for _ in range(passes):
        seen += _non_distinct_candidates(sim.state, 0.5)
        sim.run(1)
        sim.state.validate(cover=False)
        assert to_numpy(sim.state.cell_sides).max() <= sim.state.max_sides
    assert seen >= 1
    assert sim.log("t1_total_refused")[0] >= seen
    assert sim.log("t1_total_flips")[0] > 0


def find_edge(state, wanted):
    """The first edge (u, v), u < v, whose sides (C1..C4) and distinctness satisfy ``wanted``."""
    sides = state.cell_sides
    for u, v in topology.edges(state.vertex_neighbors):
        cells = edge_cells(state, int(u), int(v))
        if wanted(*(int(sides[c]) for c in cells), len(set(cells)) == 4):
            return (int(u), int(v)), cells
    raise AssertionError("no such edge in this tiling")


@pytest.mark.parametrize("which", ["C1", "C2"])
def test_a_triangle_may_not_lose_a_side_either_way(device, which):
    s = svm.init.random_tiling(16, seed=0)
    if which == "C1":
        edge, cells = find_edge(s, lambda n1, n2, n3, n4, distinct: n1 == 3 and n2 > 3 and distinct)
    else:
        edge, cells = find_edge(s, lambda n1, n2, n3, n4, distinct: n1 > 3 and n2 == 3 and distinct)
    s.positions = with_edge_length(s.positions, *edge, 0.01)
    assert short_edges(s, 0.04) == [edge]
    sim = t1_sim(s, T1(), device)
    before = topology_arrays(sim.state)
    sim.run(1)
    assert sim.log("t1_flips").tolist() == [0] and sim.log("t1_refused").tolist() == [1]
    for a, b in zip(topology_arrays(sim.state), before):
        assert np.array_equal(a, b)
    sim.state.validate()


def test_a_triangle_may_gain_a_side(device):
    """Only C1 and C2 lose a side: an edge whose end cell is a triangle flips."""
    s = svm.init.random_tiling(16, seed=0)
    sides = s.cell_sides.copy()
    pick, cells = find_edge(s, lambda n1, n2, n3, n4, distinct: n1 > 3 and n2 > 3 and distinct and 3 in (n3, n4))
    s.positions = with_edge_length(s.positions, *pick, 0.01)
    assert short_edges(s, 0.04) == [pick]
    sim = t1_sim(s, T1(), device)
    sim.run(1)
    assert sim.log("t1_flips").tolist() == [1] and sim.log("t1_refused").tolist() == [0]
    new_sides = to_numpy(sim.state.cell_sides)
    assert (new_sides[list(cells)] - sides[list(cells)]).tolist() == [-1, -1, 1, 1]
    sim.state.validate()


# ---------------------------------------------------------------------- conflicts
def _football_with_short_edges(lengths):
    """A truncated icosahedron (one replica) and the edges (u, v) to shrink: two of one hexagon
    (sharing it), one sharing a cell with the second only, one far from all."""
    s = svm.init.regular_tiling("truncated_icosahedron")
    hexagon = int(np.flatnonzero(s.cell_sides == 6)[0])
    row = [int(x) for x in s.cell_vertices[hexagon, :6]]
    e1, e2 = tuple(sorted(row[0:2])), tuple(sorted(row[3:5]))
    cells = {k: set(edge_cells(s, *e)) for k, e in (("e1", e1), ("e2", e2))}
    e3 = e4 = None
    for u, v in topology.edges(s.vertex_neighbors):
        e = (int(u), int(v))
        c = set(edge_cells(s, *e))
        if {e[0], e[1]} & {*e1, *e2}:
            continue
        if e3 is None and c & cells["e2"] and not c & cells["e1"] and edge_index(s.vertex_neighbors, *e) > max(
                edge_index(s.vertex_neighbors, *x) for x in (e1, e2)):
            e3 = e
        if e4 is None and not c & (cells["e1"] | cells["e2"]):
            e4 = e
    chosen = [e1, e2, e3, e4]
    pos = s.positions
    for e, L in zip(chosen, lengths):
        if L is not None:
            pos = with_edge_length(pos, *e, L)
    s.positions = pos
    return s, chosen


def _moved(sim, pos0, e):
    return bool((np.abs(to_numpy(sim.state.positions)[list(e)] - pos0[list(e)]).max(axis=1) > 0).any())


def test_conflicting_short_edges_lowest_index_flips_one_per_cell(device):
    s, (e1, e2, e3, e4) = _football_with_short_edges([0.05, 0.06, None, 0.07])
    vn = s.vertex_neighbors
    assert short_edges(s, 0.1) == sorted([e1, e2, e4])
    assert edge_index(vn, *e1) < edge_index(vn, *e2)
    t1 = T1(threshold=0.1, new_length=0.3)
    sim = t1_sim(s, t1, device)
    pos0 = to_numpy(sim.state.positions).copy()
    sim.run(1)
    # e1 and e2 share the hexagon: only e1 (lower index) flips; e4 touches neither and flips too
    assert sim.log("t1_flips").tolist() == [2] and sim.log("t1_refused").tolist() == [0]
    assert _moved(sim, pos0, e1) and _moved(sim, pos0, e4) and not _moved(sim, pos0, e2)
    sim.state.validate()
    # e2 waited; it flips on the next pass (FIRE stopped every replica: un-stop them for T1)
    sim.operations.integrator.reset()
    pos1 = to_numpy(sim.state.positions).copy()
    sim.run(1)
    assert sim.log("t1_flips").tolist() == [1] and sim.log("t1_total_flips").tolist() == [3]
    assert _moved(sim, pos1, e2)
    sim.state.validate()


def test_a_waiting_candidate_still_blocks_a_higher_one(device):
    """The rule is the per-cell minimum over all candidates, not greedy: e3 shares a cell with e2
    (which waits for e1) but not with e1; e3 has a higher index than e2, so it waits too."""
    s, (e1, e2, e3, e4) = _football_with_short_edges([0.05, 0.06, 0.065, None])
    assert short_edges(s, 0.1) == sorted([e1, e2, e3])
    sim = t1_sim(s, T1(threshold=0.1, new_length=0.3), device)
    pos0 = to_numpy(sim.state.positions).copy()
    sim.run(1)
    assert sim.log("t1_flips").tolist() == [1]
    assert _moved(sim, pos0, e1) and not _moved(sim, pos0, e2) and not _moved(sim, pos0, e3)
    sim.state.validate()


# ---------------------------------------------------------------------- new edge length
def _two_spheres(lengths_in_units, radii=(None, 2.5)):
    """Two truncated icosahedra of different radii, one edge each shrunk to the given length
    (in units of sqrt(<A>) of its replica). Returns the ensemble, the edges (global) and the units."""
    states, edges, units = [], [], []
    offset = 0
    for L, R in zip(lengths_in_units, radii):
        s = svm.init.regular_tiling("truncated_icosahedron", radius=R)
        unit = np.sqrt(4 * np.pi * s.radius_np()[0] ** 2 / s.n_cells)
        hexagon = int(np.flatnonzero(s.cell_sides == 6)[0])
        u, v = (int(x) for x in s.cell_vertices[hexagon, :2])
        s.positions = with_edge_length(s.positions, u, v, L * unit)
        states.append(s)
        edges.append((min(u, v) + offset, max(u, v) + offset))
        units.append(unit)
        offset += s.n_vertices
    return svm.State.concatenate(states), edges, np.array(units)


def _check_new_lengths(sim, edges, expected):
    pos = to_numpy(sim.state.positions)
    vn = to_numpy(sim.state.vertex_neighbors)
    for (u, v), L_new in zip(edges, expected):
        assert v in vn[u]                                  # the edge rotated, its ends still neighbours
        assert geodesic(pos[u], pos[v]) == pytest.approx(L_new, rel=1e-12, abs=0)


def test_reference_preset_new_edge_is_twice_the_old(device):
    t1 = T1(preset="reference")
    assert (t1.threshold, t1.length_factor, t1.new_length) == (0.1, 2.0, None)
    ens, edges, units = _two_spheres([0.03, 0.08])
    old = [geodesic(ens.positions[u], ens.positions[v]) for u, v in edges]
    assert np.allclose(np.array(old) / units, [0.03, 0.08], rtol=1e-12)
    assert short_edges(ens, 0.1) == sorted(edges)
    mids = [(ens.positions[u] + ens.positions[v]) / np.linalg.norm(ens.positions[u] + ens.positions[v])
            for u, v in edges]
    sim = t1_sim(ens, t1, device)
    sim.run(1)
    assert sim.log("t1_flips").tolist() == [1, 1] and sim.log("t1_refused").tolist() == [0, 0]
    _check_new_lengths(sim, edges, [2 * L for L in old])
    pos = to_numpy(sim.state.positions)
    for (u, v), m in zip(edges, mids):               # same midpoint
        assert np.allclose((pos[u] + pos[v]) / np.linalg.norm(pos[u] + pos[v]), m, atol=1e-13)
    sim.state.validate()


def test_default_rule_new_edge_is_0_12_sqrt_mean_area(device):
    t1 = T1()
    assert (t1.threshold, t1.new_length, t1.length_factor) == (0.04, 0.12, None)
    ens, edges, units = _two_spheres([0.01, 0.035])
    assert short_edges(ens, 0.04) == sorted(edges)
    sim = t1_sim(ens, t1, device)
    sim.run(1)
    assert sim.log("t1_flips").tolist() == [1, 1] and sim.log("t1_refused").tolist() == [0, 0]
    _check_new_lengths(sim, edges, 0.12 * units)
    sim.state.validate()


def test_explicit_length_factor_and_new_length(device):
    ens, edges, units = _two_spheres([0.02, 0.05])
    old = [geodesic(ens.positions[u], ens.positions[v]) for u, v in edges]
    sim = t1_sim(ens, T1(threshold=0.06, length_factor=3.5), device)
    sim.run(1)
    _check_new_lengths(sim, edges, [3.5 * L for L in old])
    sim = t1_sim(ens, T1(threshold=0.06, new_length=0.2), device)
    sim.run(1)
    _check_new_lengths(sim, edges, 0.2 * units)
