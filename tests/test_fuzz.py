"""T1 fuzzing (issue 13, items 7 and 10): random tangent kicks and T1 passes with a large threshold,
so that edges flip all the time; after every few passes the network is checked by code written
here, independent of spherevm.topology (which does the flipping) and of the constraint's areas,
and around every pass the folds it made are counted: a cell whose area (the fan about its first
vertex, as the forces measure it) went from positive to <= 0, or a corner whose three edges
turned clockwise. With the fold rule there are none; without it the same fuzzing finds them.

Recorded counts (CPU): the short test makes 3,660 flips (20,319 refused, most of them folds either
way round: kicks without forces tangle the network; 3,345 flips and 2,059 refusals in 6 runs before
the fold rule) in 14 runs of 300 passes, checked every 10 passes; the same fuzzing without the
rule makes folds (the test asserts some). 100 hot Brownian steps on four 12-cell tissues with
threshold 0.8: 481 flips made 76 folded cells and 213 inverted corners without the rule, 492 flips
none with it. The slow one runs until 1,000,000 flips, checked every 200 passes.

Simple polygons (issue 36): ``brute_force_crossings`` (benchmarks/untangle_fuzz.py) finds cells
crossing themselves by its own method (each cell projected flat, every pair of edges intersected);
hot Brownian runs with ``T1(untangle=True)`` on every surface are checked with it after every step:
none is left after ``untangle_pass``. Force-free kicks tangle cells by themselves, so the kick
fuzzing above does not ask for simple polygons."""
import os
import sys
from pathlib import Path

import numpy as np
import pytest

import spherevm as svm
from spherevm import folding
from spherevm.plugins.updaters import T1

from conftest import to_numpy

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "benchmarks"))
from untangle_fuzz import SURFACES, brute_force_crossings, run as untangle_run  # noqa: E402,F401


def _solid_angle(a, b, c):
    """Signed solid angle of the spherical triangle of unit vectors a, b, c (Van Oosterom-Strackee)."""
    num = np.einsum("ij,ij->i", a, np.cross(b, c))
    den = 1 + np.einsum("ij,ij->i", a, b) + np.einsum("ij,ij->i", b, c) + np.einsum("ij,ij->i", c, a)
    return 2 * np.arctan2(num, den)


def fan_areas(state):
    """Signed solid angle of every cell: the fan about its first vertex (how the forces measure it)."""
    pos, cv, sides = to_numpy(state.positions), to_numpy(state.cell_vertices), to_numpy(state.cell_sides)
    unit = pos / np.linalg.norm(pos, axis=1)[:, None]
    col = np.arange(cv.shape[1])[None, :]
    inside = col < sides[:, None]
    nxt = np.where(col + 1 < sides[:, None], np.roll(cv, -1, axis=1), cv[:, :1])
    first = np.repeat(cv[:, 0], sides)
    cell = np.repeat(np.arange(len(sides)), sides)
    return np.bincount(cell, weights=_solid_angle(unit[first], unit[cv[inside]], unit[nxt[inside]]),
                       minlength=len(sides))


def inverted_corners(state):
    """Vertices whose three edges (in table order) turn clockwise about the outward normal."""
    pos, vn = to_numpy(state.positions), to_numpy(state.vertex_neighbors)
    n = pos / np.linalg.norm(pos, axis=1)[:, None]
    e = [pos[vn[:, k]] - pos for k in range(3)]
    negative = sum((np.einsum("ij,ij->i", n, np.cross(e[k], e[(k + 1) % 3])) < 0).astype(int) for k in range(3))
    return negative >= 2


class FoldCounter:
    """Folds made by T1 passes: cells whose area went from > 0 to <= 0, corners newly inverted."""

    def __init__(self):
        self.cells = self.corners = 0

    def around(self, state, run_pass):
        area, inverted = fan_areas(state), inverted_corners(state)
        run_pass()
        self.cells += int(((area > 0) & (fan_areas(state) <= 0)).sum())
        self.corners += int((~inverted & inverted_corners(state)).sum())


def check_network(state):
    """Every invariant of a closed trivalent tiling of spheres, from the raw arrays."""
    pos = to_numpy(state.positions)
    vn, vc = to_numpy(state.vertex_neighbors), to_numpy(state.vertex_cells)
    cv, sides = to_numpy(state.cell_vertices), to_numpy(state.cell_sides)
    vs, cs = np.asarray(state.vertex_start), np.asarray(state.cell_start)
    radius = to_numpy(state.radius)
    nv, nc = len(pos), len(sides)
    assert np.isfinite(pos).all()
    vrep = np.repeat(np.arange(len(vs) - 1), np.diff(vs))
    crep = np.repeat(np.arange(len(cs) - 1), np.diff(cs))
    assert np.allclose(np.linalg.norm(pos, axis=1), radius[vrep], rtol=1e-12)
    # cells: 3 <= sides, padding exactly after the sides, vertices in the cell's replica, no repeats
    assert (sides >= 3).all() and (sides <= cv.shape[1]).all()
    col = np.arange(cv.shape[1])[None, :]
    inside = col < sides[:, None]
    assert ((cv >= 0) == inside).all()
    assert (vrep[np.where(inside, cv, 0)][inside] == np.repeat(crep, sides)).all()
    for c in range(nc):
        ring = cv[c, :sides[c]]
        assert len(set(ring.tolist())) == sides[c], f"cell {c} repeats a vertex"
    # directed edges: each (u -> v) of a cell ring appears exactly once, its reverse exactly once
    nxt = np.where(col + 1 < sides[:, None], np.roll(cv, -1, axis=1), cv[:, :1])
    u, v = cv[inside], nxt[inside]
    cell_of = np.repeat(np.arange(nc), sides)
    key = u.astype(np.int64) * nv + v
    assert len(np.unique(key)) == len(key)
    assert np.isin(v.astype(np.int64) * nv + u, key).all()
    # trivalent vertices, reciprocal neighbour lists, vertex tables agreeing with the cell rings
    assert np.bincount(u, minlength=nv).tolist() == [3] * nv
    assert (vn >= 0).all() and (vn < nv).all() and (vc >= 0).all() and (vc < nc).all()
    assert all(i in vn[j] for i in range(nv) for j in vn[i])
    edge_cell = dict(zip(key.tolist(), cell_of.tolist()))
    for i in range(nv):
        assert sorted(vc[i].tolist()) == sorted(edge_cell[i * nv + j] for j in vn[i])
    # Euler characteristic and total area (signed solid angles of each cell's fan) per replica
    edges_per_rep = np.bincount(vrep[u], minlength=len(vs) - 1) // 2
    chi = np.diff(vs) - edges_per_rep + np.diff(cs)
    assert (chi == 2).all(), chi
    unit = pos / np.linalg.norm(pos, axis=1)[:, None]
    first = np.repeat(cv[:, 0], sides)
    fan = (u != first) & (v != first)
    omega = np.bincount(cell_of[fan], weights=_solid_angle(unit[first[fan]], unit[u[fan]], unit[v[fan]]),
                        minlength=nc)
    total = np.bincount(crep, weights=omega, minlength=len(cs) - 1)
    # kicks without forces may fold a cell or grow it past what a fan measures (A - 4 pi): the closed
    # network still tiles the sphere a whole number of times (T1 itself folds nothing: FoldCounter)
    wrapped = np.remainder(total + 1e-9, 4 * np.pi) - 1e-9
    assert np.allclose(wrapped, 0, rtol=0, atol=1e-9), total


def fuzz(state, seed, passes, device, check_every, kick=0.08, threshold=0.25, folds=None):
    """Kick, T1 pass, repeat; check the network every ``check_every`` passes (and count the folds
    each pass makes into ``folds``, a FoldCounter). Returns the flips and the refusals."""
    rng = np.random.default_rng(seed)
    sim = svm.Simulation(device=device)
    sim.state = state
    t1 = T1(threshold=threshold, new_length=1.5 * threshold, max_flip_backs=10 ** 9)
    sim.operations.updaters.append(t1)
    st, con = sim.state, sim.state.constraint
    for k in range(1, passes + 1):
        noise = st.device.asarray(rng.normal(scale=kick, size=st.positions.shape))
        st.positions = con.project_normal(st.positions + con.project_tangent(st.positions, noise),
                                          st.radius[st.vertex_replica])
        sim.state_changed()
        if folds is None:
            sim.run_updaters()
        else:
            folds.around(sim.state, sim.run_updaters)
        if k % check_every == 0 or k == passes:
            check_network(sim.state)
    return int(sim.log("t1_total_flips").sum()), int(sim.log("t1_total_refused").sum())


def test_fuzz_thousands_of_flips_and_no_fold(device):
    flips = refused = 0
    folds = FoldCounter()
    for seed in range(14):
        f, r = fuzz(svm.init.random_tiling(60, replicas=2, seed=seed), seed, passes=300, device=device,
                    check_every=10, folds=folds)
        flips, refused = flips + f, refused + r
    print(f"fuzz: {flips} flips, {refused} refused")
    assert flips > 3000, flips
    assert folds.cells == 0 and folds.corners == 0, (folds.cells, folds.corners)


def test_fuzz_finds_the_folds_the_rule_refuses(monkeypatch):
    """Without the rule the same fuzzing makes folds: the counter sees what the rule prevents."""
    monkeypatch.setattr(folding, "t1_placement", lambda state, u, slot, new_length, untangle=False: (np.zeros(len(u), dtype=bool),) * 2)
    folds = FoldCounter()
    for seed in range(2):
        fuzz(svm.init.random_tiling(60, replicas=2, seed=seed), seed, passes=100, device="cpu", check_every=50,
             folds=folds)
    assert folds.cells + folds.corners > 10, (folds.cells, folds.corners)


def hot_brownian_folds(device, steps=100):
    """The issue's case: large thresholds on tiny spheres, hot Brownian dynamics with T1 each step."""
    sim = svm.Simulation(device=device, seed=1)
    sim.state = svm.init.random_tiling(12, replicas=4, seed=2)
    sim.operations.forces.append(svm.plugins.forces.VertexModel.dimensionless(kr=1.0, p0=3.8))
    t1 = T1(threshold=0.8, new_length=1.2, max_flip_backs=10 ** 9)
    sim.operations.updaters.append(t1)
    sim.operations.integrator = svm.plugins.integrators.Brownian(dt=0.01, T=0.2)
    folds = FoldCounter()
    for _ in range(steps):
        folds.around(sim.state, sim.run_updaters)
        sim.integrate()
        sim.check_finite()
    return folds, int(sim.log("t1_total_flips").sum())


def test_hot_tiny_spheres_flip_without_folding(device):
    folds, flips = hot_brownian_folds(device)
    assert flips > 200 and folds.cells == 0 and folds.corners == 0, (flips, folds.cells, folds.corners)


def test_hot_tiny_spheres_folded_without_the_rule(monkeypatch):
    monkeypatch.setattr(folding, "t1_placement", lambda state, u, slot, new_length, untangle=False: (np.zeros(len(u), dtype=bool),) * 2)
    folds, _ = hot_brownian_folds("cpu")
    assert folds.cells > 10 and folds.corners > 10, (folds.cells, folds.corners)


@pytest.mark.slow
def test_fuzz_a_million_flips(device):
    if device == "cpu" and not os.environ.get("SPHEREVM_LONG"):
        # with the fold checks the CPU needs ~11 min for this (647 s on the 2-core VM): more than the
        # whole default run may take; the GPU variant runs by default, the CPU one on request
        pytest.skip("1e6 flips on the CPU take ~11 minutes; run with SPHEREVM_LONG=1")
    state = svm.init.random_tiling(400, replicas=16, seed=99)
    flips = 0
    chunk = 0
    while flips < 1_000_000:
        f, _ = fuzz(state, chunk, passes=1000, device=device, check_every=200)
        flips += f
        chunk += 1
    assert flips >= 1_000_000


@pytest.mark.parametrize("surface, cells, flips", [("sphere", 64, 400), ("plane", 64, 400), ("torus", 128, 200),
                                                   ("ellipsoid", 64, 200), ("bump", 64, 150)])
def test_untangling_leaves_no_crossed_cell_in_hot_dynamics(surface, cells, flips):
    """Hot Brownian dynamics (T = 0.1, dt = 0.02) with T1(untangle=True) and its untangle_pass after
    every step, from the random tilings (benchmarks/untangle_fuzz.py, every surface): after every
    pass no cell crosses itself by the brute-force test, while the dynamics crossed many and the
    pass had to send some replicas back (its flips alone leave crossed cells: the next test)."""
    out = untangle_run(surface, flips, cells=cells, replicas=4, T=0.1, dt=0.02, relax=0, seed=2)
    assert out["left"] == 0 and out["flips"] >= flips and out["met"] > flips // 2 and out["refused_steps"] > 0, out


@pytest.mark.parametrize("relax, where", [(0, "exploding step"), (5, "while relaxing: exploding step")])
def test_a_fuzz_run_that_blows_up_reports_it_and_keeps_its_counts(relax, where):
    """A hot run can end on an exploding step (a random tiling's tiny cell): the fuzz run stops
    there, says why and returns what it counted (a long count is summed over runs), instead of
    losing the whole run to the exception."""
    out = untangle_run("plane", 10**6, cells=64, replicas=2, T=0.1, dt=0.5, relax=relax, seed=2)
    assert out["stopped"].startswith(where) and out["flips"] < 10**6 and out["seconds"] > 0, out


@pytest.mark.parametrize("surface", ["sphere", "ellipsoid"])
def test_untangling_by_flips_alone_leaves_crossed_cells(surface):
    """The same runs with the replica steps never refused (``untangle_pass(revert=False)``): the
    brute-force test finds cells left crossed, the cases no flip undoes."""
    out = untangle_run(surface, 200, cells=64, replicas=4, T=0.1, dt=0.02, relax=0, seed=2, revert=False)
    assert out["left"] > 10 and out["refused_steps"] == 0, out


@pytest.mark.slow
@pytest.mark.parametrize("surface", list(SURFACES))
def test_untangling_a_million_hot_flips(surface):
    """docs/validation.md's count: 10^6 flips of hot Brownian dynamics on 8 tissues of 256 cells
    (T = 0.05, dt = 0.02), no crossed cell left after any pass. 195-290 flips a second on the 2-core
    VM (the bump 112): 1 to 2.5 hours per surface, so run with SPHEREVM_LONG=1 (or
    ``python benchmarks/untangle_fuzz.py --flips 1000000``)."""
    if not os.environ.get("SPHEREVM_LONG"):
        pytest.skip("10^6 hot flips take hours on the CPU; run with SPHEREVM_LONG=1")
    out = untangle_run(surface, 1_000_000)
    assert out["left"] == 0 and out["flips"] >= 1_000_000, out
