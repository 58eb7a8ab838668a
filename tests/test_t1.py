"""T1 neighbour exchanges: exact flips, rules, invariants under thousands of flips, ensembles."""
import numpy as np
import pytest

from conftest import to_numpy

import spherevm as svm
from spherevm import topology
from spherevm.plugins.forces import VertexModel
from spherevm.plugins.integrators import FIRE
from spherevm.plugins.updaters import T1


def _cells(state):
    """Cell vertex lists, each rotated to start at its smallest vertex (a canonical form)."""
    out = []
    for row, n in zip(to_numpy(state.cell_vertices), to_numpy(state.cell_sides)):
        r = row[:n].tolist()
        i = r.index(min(r))
        out.append(tuple(r[i:] + r[:i]))
    return out


def _vertex_tables(state):
    """vertex_neighbors / vertex_cells rows rotated to a canonical starting slot."""
    vn, vc = to_numpy(state.vertex_neighbors), to_numpy(state.vertex_cells)
    k = vn.argmin(axis=1)
    idx = (k[:, None] + np.arange(3)[None, :]) % 3
    return np.take_along_axis(vn, idx, 1), np.take_along_axis(vc, idx, 1)


def _check_invariants(state, orientation=True):
    state.validate(orientation=orientation)
    area, _ = svm.analysis.cell_shapes(state)
    per_rep = np.bincount(state.cell_replica_np(), weights=area)
    assert np.allclose(per_rep, 4 * np.pi * state.radius_np() ** 2, rtol=1e-10, atol=0)
    assert to_numpy(state.cell_sides).min() >= 3


def _table(state):
    """The cell table trimmed to the widest cell (the GPU may keep a spare column)."""
    cv = to_numpy(state.cell_vertices)
    return cv[:, :int(to_numpy(state.cell_sides).max())]


def _sim_with_t1(state, t1, force=None, device="cpu"):
    sim = svm.Simulation(device=device)
    sim.state = state
    sim.operations.updaters.append(t1)
    sim.operations.forces.append(force or VertexModel.dimensionless(kr=1.0, p0=3.8))
    sim.operations.integrator = FIRE(dt=0.01)
    return sim


def test_hand_built_flip_on_the_dodecahedron():
    s = svm.init.regular_tiling("dodecahedron")
    u, slot = 0, 0
    v, a, b, c, d, C1, C2, C3, C4 = (int(x[0]) for x in topology.t1_cells(
        s.vertex_neighbors, s.vertex_cells, np.array([u]), np.array([slot])))
    pu, pv = s.positions[u].copy(), s.positions[v].copy()
    before = _cells(s)
    L = 0.3
    topology.t1_flip(s, np.array([u]), np.array([slot]), L)
    s.validate()
    # vertex tables: v = (u, d, a) in cells (C4, C1, C3); u = (v, b, c) in (C3, C2, C4)
    assert s.vertex_neighbors[v].tolist() == [u, d, a] and s.vertex_cells[v].tolist() == [C4, C1, C3]
    assert s.vertex_neighbors[u].tolist() == [v, b, c] and s.vertex_cells[u].tolist() == [C3, C2, C4]
    assert v in s.vertex_neighbors[a] and u not in s.vertex_neighbors[a]
    assert u in s.vertex_neighbors[c] and v not in s.vertex_neighbors[c]
    assert s.cell_sides[[C1, C2, C3, C4]].tolist() == [4, 4, 6, 6]
    after = _cells(s)
    assert set(after[C1]) == set(before[C1]) - {u} and set(after[C2]) == set(before[C2]) - {v}
    assert set(after[C3]) == set(before[C3]) | {v} and set(after[C4]) == set(before[C4]) | {u}
    unchanged = [i for i in range(12) if i not in (C1, C2, C3, C4)]
    assert all(after[i] == before[i] for i in unchanged)
    # positions: same midpoint, geodesic separation L, new edge perpendicular to the old one
    R = s.radius_np()[0]
    nu, nv = s.positions[u], s.positions[v]
    mid_old = (pu + pv) / np.linalg.norm(pu + pv)
    mid_new = (nu + nv) / np.linalg.norm(nu + nv)
    assert np.allclose(mid_old, mid_new, atol=1e-14)
    sep = R * svm.geometry.geodesic_length(nu / R, nv / R)
    assert np.isclose(sep, L, rtol=1e-12)
    assert abs(np.dot(nv - nu, pv - pu)) < 1e-12 * np.linalg.norm(nv - nu) * np.linalg.norm(pv - pu)
    # the new edge points from u (C2 side) to v (C1 side): counter-clockwise rotation of u -> v
    assert np.dot(np.cross(pv - pu, nv - nu), mid_old) > 0


def test_flip_then_inverse_restores_the_network_and_positions():
    s = svm.init.random_tiling(60, seed=2)
    ref = s.copy()
    rng = np.random.default_rng(0)
    for _ in range(20):
        u = int(rng.integers(s.n_vertices))
        slot = int(rng.integers(3))
        _, _, _, _, _, C1, C2, _, _ = topology.t1_cells(s.vertex_neighbors, s.vertex_cells,
                                                         np.array([u]), np.array([slot]))
        if s.cell_sides[C1[0]] <= 3 or s.cell_sides[C2[0]] <= 3:
            continue
        v = s.vertex_neighbors[u, slot]
        R = s.radius_np()[0]
        old = R * svm.geometry.geodesic_length(s.positions[u] / R, s.positions[v] / R)
        topology.t1_flip(s, np.array([u]), np.array([slot]), 0.2)
        s.validate(orientation=False)
        back = int(np.flatnonzero(s.vertex_neighbors[u] == v)[0])
        topology.t1_flip(s, np.array([u]), np.array([back]), old, sense=-1)
        assert _cells(s) == _cells(ref)
        for x, y in zip(_vertex_tables(s), _vertex_tables(ref)):
            assert np.array_equal(x, y)
        assert np.allclose(s.positions, ref.positions, atol=1e-12)
        s = ref.copy()


def test_triangles_may_not_lose_a_side_refusals_are_counted(device):
    s = svm.init.random_tiling(4, seed=0)          # a tetrahedral tiling: four triangles
    assert s.cell_sides.tolist() == [3, 3, 3, 3]
    t1 = T1(threshold=100.0, new_length=101.0)
    sim = _sim_with_t1(s, t1, device=device)
    sim.run(1)
    assert sim.log("t1_flips").tolist() == [0] and sim.log("t1_refused").tolist() == [6]
    assert np.array_equal(to_numpy(sim.state.cell_sides), s.cell_sides)
    assert np.array_equal(_table(sim.state), s.cell_vertices)


def test_conflicting_flips_lowest_edge_first_one_per_cell(device):
    s = svm.init.regular_tiling("truncated_icosahedron")
    # shrink two edges of the same hexagon: only the lower-index edge may flip this pass
    hexagon = int(np.flatnonzero(s.cell_sides == 6)[0])
    row = s.cell_vertices[hexagon, :6]
    pairs = [(row[0], row[1]), (row[3], row[4])]
    pos = s.positions.copy()
    for p, q in pairs:
        m = 0.5 * (pos[p] + pos[q])
        pos[p] = pos[p] + 0.49 * (m - pos[p]) * 2
        pos[q] = pos[q] + 0.49 * (m - pos[q]) * 2
    R = s.radius_np()[0]
    s.positions = R * pos / np.linalg.norm(pos, axis=1)[:, None]
    t1 = T1(threshold=0.1, new_length=0.3)
    u, slot, _ = t1.short_edges(s)
    assert len(u) == 2
    index = 3 * u + slot
    sim = _sim_with_t1(s, t1, device=device)
    sim.run(0)
    sim.run_updaters()
    assert sim.log("t1_flips").tolist() == [1]
    low = int(np.argmin(index))
    high = 1 - low
    assert to_numpy(sim.state.cell_sides)[hexagon] == 5
    # the low edge's vertices were rotated: they moved; the high edge's did not
    moved = np.abs(to_numpy(sim.state.positions) - s.positions).max(axis=1) > 0
    lo_pair = [u[low], s.vertex_neighbors[u[low], slot[low]]]
    hi_pair = [u[high], s.vertex_neighbors[u[high], slot[high]]]
    assert moved[lo_pair].all() and not moved[hi_pair].any()
    # the flipped edge's ends now have other neighbours; the higher edge waits for the next pass
    sim.run_updaters()
    assert sim.log("t1_flips").tolist() == [1]
    assert sim.log("t1_total_flips").tolist() == [2]
    sim.state.validate()


def test_at_most_one_flip_per_cell_per_pass_under_stress():
    # CPU only: the host helpers short_edges / select (the GPU pass does this in t1_detect)
    s = svm.init.random_tiling(200, seed=5)
    t1 = T1(threshold=0.5, new_length=0.6)
    u, slot, lengths = t1.short_edges(s)
    flip, refused, cells, _ = t1.select(s, u, slot, lengths)
    assert flip.sum() > 5
    used = cells[flip].reshape(-1)
    assert len(np.unique(used)) == len(used)
    # every waiting candidate conflicts with a lower-index flip or candidate
    index = 3 * u + slot
    for i in np.flatnonzero(~flip & ~refused):
        others = (~refused) & (index < index[i])
        assert np.isin(cells[i], cells[others]).any()


def _random_walk_with_t1(state, seed, passes, kick=0.08, threshold=0.25, device="cpu"):
    """Random tangent kicks followed by a T1 pass, `passes` times."""
    rng = np.random.default_rng(seed)
    t1 = T1(threshold=threshold, new_length=1.5 * threshold, max_flip_backs=10 ** 9)
    sim = svm.Simulation(device=device)
    sim.state = state
    sim.operations.updaters.append(t1)
    con, st = sim.state.constraint, sim.state
    for _ in range(passes):
        noise = st.device.asarray(rng.normal(scale=kick, size=st.positions.shape))
        rad = st.radius[st.vertex_replica]
        st.positions = con.project_normal(st.positions + con.project_tangent(st.positions, noise), rad)
        sim.run_updaters()
        yield sim, t1


def test_thousands_of_random_flips_keep_every_invariant(device):
    total = 0
    for seed in range(8):
        state = svm.init.random_tiling(40 + 10 * seed, seed=seed)
        for sim, t1 in _random_walk_with_t1(state, seed, passes=80, device=device):
            _check_invariants(sim.state, orientation=False)
        total += int(sim.log("t1_total_flips").sum())
        assert sim.state.max_sides >= to_numpy(sim.state.cell_sides).max()
    assert total > 1000


def test_ensemble_and_single_replicas_flip_identically(device):
    ens = svm.init.random_tiling(50, replicas=3, seed=7)
    t1 = T1(threshold=0.3, new_length=0.45)
    sim_e = _sim_with_t1(ens, t1, device=device)
    sim_e.run(30)
    for r in range(3):
        t1r = T1(threshold=0.3, new_length=0.45)
        sim_r = _sim_with_t1(ens.replica(r), t1r, device=device)
        sim_r.run(30)
        assert sim_r.log("t1_total_flips")[0] == sim_e.log("t1_total_flips")[r] > 0
        mine = sim_e.state.replica(r)
        assert _cells(mine) == _cells(sim_r.state)
        assert np.allclose(to_numpy(mine.positions), to_numpy(sim_r.state.positions), rtol=0, atol=1e-12)


def test_reference_preset(device):
    t1 = T1(preset="reference")
    assert t1.threshold == 0.1 and t1.length_factor == 2.0 and t1.new_length is None
    s = svm.init.random_tiling(100, seed=3)
    sim = _sim_with_t1(s, t1, device=device)
    u, slot, lengths = t1.short_edges(sim.state)
    sim.run_updaters()
    if len(u):
        assert sim.log("t1_flips").sum() >= 1


@pytest.mark.parametrize("n_cells", [32, 64, 128] + [pytest.param(n, marks=pytest.mark.slow) for n in (256, 512, 1024)])
def test_fire_with_t1_converges(n_cells, device):
    sim = _sim_with_t1(svm.init.random_tiling(n_cells, replicas=2, seed=n_cells), T1(),
                       VertexModel.dimensionless(kr=1.0, p0=3.7), device=device)
    sim.operations.integrator = FIRE(dt=0.02)
    res = sim.minimize(force_tol=1e-10, max_steps=50000)
    assert res.all_converged, res.table()
    _check_invariants(sim.state)


def test_flipping_back_and_forth_is_detected_and_reported(device):
    # every edge is "short" (edges are ~0.6 sqrt(<A>)) and every new edge too: the same pairs flip
    # back and forth forever (a new edge of 60 cell sizes, as this test once used, folds the network
    # and is refused now)
    t1 = T1(threshold=1.0, new_length=1.1, max_flip_backs=5)
    sim = _sim_with_t1(svm.init.random_tiling(16, replicas=2, seed=1), t1, device=device)
    res = sim.minimize(force_tol=1e-14, max_steps=5000, check_every=1)
    assert list(res.reason) == ["t1_oscillation", "t1_oscillation"]
    assert not res.converged.any() and np.all(res.steps < 5000)
    assert np.all(sim.log("t1_flip_backs") >= 5)


@pytest.mark.parametrize("kw, match", [
    (dict(threshold=0), "threshold"), (dict(threshold=-1), "threshold"),
    (dict(threshold=0.1, new_length=0.1), "new_length"), (dict(threshold=0.1, new_length=0.05), "new_length"),
    (dict(preset="cellgpu"), "preset"), (dict(length_factor=0), "length_factor"),
    (dict(max_flip_backs=0), "max_flip_backs"),
])
def test_bad_t1_parameters(kw, match):
    with pytest.raises(ValueError, match=match):
        T1(**kw)


def test_flip_back_bookkeeping_only_where_something_halts_on_it(device):
    """Under Brownian dynamics T1 keeps no flip-back record by default (nothing halts on it and it
    grows with every flip), with ``count_flip_backs=True`` it does; the flips are the same."""
    from spherevm.plugins.integrators import Brownian
    runs = {}
    for count in (None, True):
        sim = svm.Simulation(device=device, seed=4)
        sim.state = svm.init.random_tiling(60, replicas=2, seed=8)
        sim.operations.forces.append(VertexModel.dimensionless(kr=1.0, p0=3.9))
        t1 = T1(threshold=0.2, new_length=0.3, count_flip_backs=count)
        sim.operations.updaters.append(t1)
        sim.operations.integrator = Brownian(dt=0.005, T=0.5)
        sim.run(300)
        runs[count] = (sim, t1)
    (quiet, t_quiet), (counted, t_counted) = runs[None], runs[True]
    assert not t_quiet.counting(quiet) and t_counted.counting(counted)
    flips = counted.log("t1_total_flips")
    assert flips.sum() > 20 and np.array_equal(quiet.log("t1_total_flips"), flips)
    assert np.array_equal(to_numpy(quiet.state.positions), to_numpy(counted.state.positions))
    t_counted._sync_counters(), t_quiet._sync_counters()
    assert len(t_counted._separated) > 0 and len(t_quiet._separated) == 0
    assert quiet.log("t1_flip_backs").sum() == 0 and counted.log("t1_flip_backs").sum() > 0
    # under FIRE (a Minimizer) or with no integrator the record is kept
    quiet.operations.integrator = FIRE()
    assert t_quiet.counting(quiet)
    with pytest.raises(ValueError, match="count_flip_backs"):
        T1(count_flip_backs="yes")


# ------------------------------------------------------------------ untangle (docs/validation.md)
def _brownian(untangle, T, device="cpu", seed=3, dt=0.02, state=None):
    """Brownian dynamics with T1(untangle=untangle) of two 48-cell tissues (or ``state``)."""
    sim = svm.Simulation(device=device, seed=seed)
    sim.state = svm.init.random_tiling(48, replicas=2, seed=seed) if state is None else state
    sim.operations.forces.append(svm.plugins.forces.VertexModel.dimensionless(kr=1.0, p0=3.8))
    t1 = T1(untangle=untangle)
    sim.operations.updaters.append(t1)
    sim.operations.integrator = svm.plugins.integrators.Brownian(dt=dt, T=T)
    return sim, t1


def test_untangling_changes_nothing_where_no_edge_is_crossed():
    from spherevm import folding
    relaxed, _ = _brownian(False, T=0.0)
    relaxed.operations.integrator = FIRE(dt=0.02)
    relaxed.run(300)
    runs = {}
    for untangle in (False, True):
        sim, _ = _brownian(untangle, T=0.002, dt=0.05, state=relaxed.state.copy())
        for _ in range(100):
            assert len(folding.inverted_edges(sim.state)[0]) == 0      # nothing for untangling to take
            sim.run(1)
        runs[untangle] = sim
    assert np.array_equal(runs[False].state.positions, runs[True].state.positions)
    assert runs[True].log("t1_total_flips").sum() > 0


def test_untangling_flips_the_crossed_edges_and_changes_that_trajectory():
    from spherevm import folding
    sims = {u: _brownian(u, T=0.1) for u in (False, True)}
    for _ in range(40):
        for untangle, (sim, t1) in sims.items():
            sim.run(1)
            if untangle:
                t1.untangle_pass(sim)
    plain, untangled = sims[False][0].state, sims[True][0].state
    assert len(folding.inverted_edges(untangled)) < len(folding.inverted_edges(plain)) or \
        not np.array_equal(plain.positions, untangled.positions)
    assert sims[True][1].total_flips.sum() > sims[False][1].total_flips.sum()


def test_untangle_is_a_flag_and_untangles_on_both_devices(device):
    from spherevm import folding
    with pytest.raises(ValueError, match="untangle must be True or False, got 1"):
        T1(untangle=1)
    sim, t1 = _brownian(True, T=0.1, device=device)
    for _ in range(40):                 # steps until one leaves a crossed edge that a flip undoes
        sim.run(1)
        crossed = len(folding.inverted_edges(sim.state)[0])
        step = int(to_numpy(sim.log("t1_flips")).sum())
        made = t1.untangle_pass(sim)
        if made:
            break
    assert made > 0 and len(folding.inverted_edges(sim.state)[0]) < crossed
    assert int(to_numpy(sim.log("t1_flips")).sum()) == step + made     # added to the step's count


ROWS = ("positions", "vertex_neighbors", "vertex_cells", "cell_sides")


def _pinched(state, replica):
    """Push the first vertex of replica ``replica``'s first cell of six or more sides to beyond its
    fourth: the cell is pinched across (edges two apart and more cross), which no flip undoes."""
    cv, sides = to_numpy(state.cell_vertices), to_numpy(state.cell_sides)
    cells = np.arange(int(state.cell_start[replica]), int(state.cell_start[replica + 1]))
    c = int(cells[np.flatnonzero(sides[cells] >= 6)[0]])
    pos = to_numpy(state.positions).copy()
    w, far = cv[c, 0], cv[c, 3]
    pos[w] = pos[far] + 0.5 * (pos[far] - pos[w])
    pos[w] *= np.linalg.norm(pos[far]) / np.linalg.norm(pos[w])
    return pos


def test_an_untangling_run_restarts_bitwise(device, tmp_path):
    """Hot Brownian steps, untangle_pass after each, a checkpoint at a step whose pass refuses
    (written in the step, before its pass): restored, then its pass made, the run goes on as the
    uninterrupted one to the bit, that refusal included (the checkpoint holds the rows the previous
    pass kept)."""
    def run(sim, t1, steps):
        refused = []
        for _ in range(steps):
            sim.run(1)
            t1.untangle_pass(sim)
            refused.append(int(t1.untangle_refused.sum()))
        return refused

    tissues = svm.init.random_tiling(64, replicas=4, seed=8)
    whole, t1 = _brownian(True, T=0.1, device=device, state=tissues)
    refused = run(whole, t1, 40)
    k = next(i + 1 for i in range(2, 30) if refused[i] > refused[i - 1])    # step k's pass refuses
    first, t1_first = _brownian(True, T=0.1, device=device, state=tissues)
    first.operations.writers.append(svm.plugins.writers.GSD(k, tmp_path / "ck.gsd"))
    run(first, t1_first, k)
    first.operations.writers[0].close()
    second, t1_second = _brownian(True, T=0.1, device=device, state=tissues)
    second.create_state_from_gsd(tmp_path / "ck.gsd")
    assert second.timestep == k
    t1_second.untangle_pass(second)
    assert int(t1_second.untangle_refused.sum()) == refused[k - 1] > refused[k - 2]
    run(second, t1_second, 40 - k)
    assert t1_second.untangle_refused.tolist() == t1.untangle_refused.tolist()
    for name in ("positions", "vertex_neighbors", "cell_vertices"):
        assert to_numpy(getattr(second.state, name)).tobytes() == to_numpy(getattr(whole.state, name)).tobytes()


@pytest.mark.parametrize("local_rounds", [3, 0])
def test_untangle_pass_sends_back_a_replica_its_flips_leave_crossed(device, local_rounds, monkeypatch):
    """docs/validation.md: in a replica still not simple after untangle_pass's flips, the vertices
    of the cells at fault take back their positions from the last call (``local_rounds``: rounds of
    that), and failing that the whole replica its rows, to the bit (its step is refused and
    counted); the other replicas keep their moves; a wider cell table since then keeps its width.
    With revert=False nothing goes back (nor are rows kept); a replica that the last call left
    crossed has nothing to go back to."""
    from spherevm import simplicity
    from spherevm.plugins.updaters import untangle
    assert untangle.LOCAL_ROUNDS == 3
    monkeypatch.setattr(untangle, "LOCAL_ROUNDS", local_rounds)
    sim = svm.Simulation(device=device, seed=1)
    sim.state = svm.init.random_tiling(60, replicas=3, seed=4)
    t1 = T1(untangle=True)
    sim.operations.updaters.append(t1)
    assert t1.untangle_pass(sim) == 0                       # every replica simple: its rows kept
    kept = {k: to_numpy(getattr(sim.state, k)).copy() for k in ROWS + ("cell_vertices",)}
    xp = sim.state.device.xp
    sim.state.cell_vertices = xp.concatenate([sim.state.cell_vertices, xp.full((sim.state.n_cells, 1), -1,
                                                                              dtype=xp.int32)], axis=1)
    pos = _pinched(sim.state, 1)
    pinched = np.flatnonzero(np.any(pos != kept["positions"], axis=1))
    for w in (int(sim.state.vertex_start[2]) - 1, int(sim.state.vertex_start[2])):   # far ones move, simply
        pos[w] = np.linalg.norm(pos[w]) * (pos[w] + [1e-3, 0, 0]) / np.linalg.norm(pos[w] + [1e-3, 0, 0])
    sim.state.positions = xp.asarray(pos)
    sim.state_changed()
    assert simplicity.counts(sim.state)["crossed"].tolist()[1] > 0
    t1.untangle_pass(sim)
    assert t1.untangle_refused.tolist() == [0, 1, 0] and to_numpy(sim.log("t1_untangle_refused")).tolist() == [0, 1, 0]
    vrep, crep = sim.state.vertex_replica_np(), sim.state.cell_replica_np()
    back = vrep == 1 if local_rounds == 0 else np.isin(np.arange(len(vrep)), pinched)   # what went back
    assert len(pinched) == 1 and np.count_nonzero(vrep == 1) > 100
    for name in ROWS:
        now, rep = to_numpy(getattr(sim.state, name)), (crep == 1 if name == "cell_sides" else back)
        want = np.where(rep.reshape((-1,) + (1,) * (now.ndim - 1)), kept[name], pos if name == "positions"
                        else kept[name])
        assert np.array_equal(now, want), name
    table = to_numpy(sim.state.cell_vertices)
    assert table.shape[1] == kept["cell_vertices"].shape[1] + 1 and (table[:, -1] == -1).all()
    assert np.array_equal(table[:, :-1], kept["cell_vertices"])
    sim.state.validate()
    sim.state.positions = xp.asarray(_pinched(sim.state, 0))
    t1.untangle_pass(sim, revert=False)                      # flips alone: nothing goes back
    assert t1.untangle_refused.tolist() == [0, 1, 0] and simplicity.counts(sim.state)["crossed"].tolist()[0] > 0
    t1.untangle_pass(sim)                                    # the last call with revert left replica 0 simple
    assert t1.untangle_refused.tolist() == [1, 1, 0] and simplicity.counts(sim.state)["crossed"].sum() == 0
    crossed = sim.state.copy()
    crossed.positions = xp.asarray(_pinched(crossed, 0))
    again = svm.Simulation(device=device)
    again.state = crossed
    t1 = T1(untangle=True)
    again.operations.updaters.append(t1)
    for _ in range(2):                                       # never seen simple: nothing to go back to
        t1.untangle_pass(again)
    assert t1.untangle_refused.tolist() == [0, 0, 0] and simplicity.counts(again.state)["crossed"].tolist()[0] > 0
