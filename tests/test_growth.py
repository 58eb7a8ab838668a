"""Cell division, T2 extrusion and the radius schedule (issue 16): invariants checked independently
of the code under test (own Euler count, own signed areas, own trivalence), known answers, per-cell
data following cells, GSD with changing counts, and the refusals."""

import numpy as np
import pytest

import spherevm as svm
from spherevm import growth
from spherevm import random as rng
from spherevm.plugins.forces import VertexModel
from spherevm.plugins.integrators import FIRE
from spherevm.plugins.updaters import T1, Division, Extrusion, RadiusSchedule
from spherevm.plugins.writers import GSD


# ------------------------------------------------------------------ an independent checker
def _area(points, plane, box=None, radius=None):
    """Signed area of one polygon, written here from scratch: shoelace on minimum images (plane),
    sum of the spherical excesses of a fan from the normalised centroid, by Girard's angles, not
    the code's atan2 formula (sphere)."""
    p = np.asarray(points, dtype=np.float64)
    if plane:
        q = p[:, :2].copy()
        for i in range(1, len(q)):
            d = q[i] - q[i - 1]
            q[i] = q[i - 1] + d - box * np.round(d / box)
        return 0.5 * np.sum(q[:, 0] * np.roll(q[:, 1], -1) - np.roll(q[:, 0], -1) * q[:, 1])
    u = p / np.linalg.norm(p, axis=1)[:, None]
    apex = u.sum(axis=0)
    apex /= np.linalg.norm(apex)
    total = 0.0
    for a, b in zip(u, np.roll(u, -1, axis=0)):
        tri = (apex, a, b)
        angles = []
        for k in range(3):
            x, y, z = tri[k], tri[(k + 1) % 3], tri[(k + 2) % 3]
            ty, tz = y - (y @ x) * x, z - (z @ x) * x
            angles.append(np.arccos(np.clip(ty @ tz / np.linalg.norm(ty) / np.linalg.norm(tz), -1, 1)))
        sign = np.sign(apex @ np.cross(a, b))
        total += sign * (sum(angles) - np.pi)
    return radius ** 2 * total


def check_tissue(state, orientation=True, simple=True):
    """Trivalence, two cells per edge (once each way), V - E + F, counter-clockwise cells and the
    total area (signed areas), per replica, from the raw arrays. ``orientation=False`` allows
    folded cells: FIRE and T1 on a tissue growing faster than it relaxes may fold one, which is
    the dynamics' doing, not the table surgery's. ``simple=False`` allows cells that cross
    themselves (``State.validate(simple=False)``): random cuts of unrelaxed cells make some."""
    pos = np.asarray(state.positions)
    cv, sides = np.asarray(state.cell_vertices), np.asarray(state.cell_sides)
    plane = state.box is not None
    for r in range(state.n_replicas):
        v0, v1 = state.vertex_start[r:r + 2]
        c0, c1 = state.cell_start[r:r + 2]
        rows = [cv[c, :sides[c]].tolist() for c in range(c0, c1)]
        assert all(len(row) >= 3 for row in rows)
        assert all(v0 <= v < v1 for row in rows for v in row), "a cell uses another replica's vertex"
        corners = np.bincount(np.concatenate(rows) - v0, minlength=v1 - v0)
        assert np.all(corners == 3), f"replica {r}: not trivalent"
        directed = [(row[i], row[(i + 1) % len(row)]) for row in rows for i in range(len(row))]
        assert len(set(directed)) == len(directed)
        assert set(directed) == {(b, a) for a, b in directed}, "an edge is not shared by two cells"
        n_edges = len(directed) // 2
        chi = (v1 - v0) - n_edges + (c1 - c0)
        assert chi == (0 if plane else 2)
        box = state.box_np()[r] if plane else None
        radius = None if plane else state.radius_np()[r]
        areas = np.array([_area(pos[row], plane, box=box, radius=radius) for row in rows])
        assert not orientation or np.all(areas > 0), f"replica {r}: cell {c0 + int(np.argmin(areas))} is clockwise or folded"
        total = box[0] * box[1] if plane else 4 * np.pi * radius ** 2
        assert abs(areas.sum() - total) < 1e-9 * total
    state.validate(orientation=orientation, simple=simple)


def _tetrahedron(radius=1.0):
    v = np.array([[1, 1, 1], [1, -1, -1], [-1, 1, -1], [-1, -1, 1]], dtype=float)
    faces = []
    for skip in range(4):
        f = [i for i in range(4) if i != skip]
        a, b, c = v[f]
        if np.cross(b - a, c - a) @ (a + b + c) < 0:
            f = f[::-1]
        faces.append(f)
    return svm.init.from_polygons(v, faces, radius=radius)


def _cube(radius=1.0):
    v = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], dtype=float)
    faces = []
    for axis in range(3):
        for s in (-1, 1):
            f = np.flatnonzero(v[:, axis] == s)
            c = v[f].mean(axis=0)
            e1 = v[f[0]] - c
            e2 = np.cross(c, e1)
            ang = np.arctan2((v[f] - c) @ e2, (v[f] - c) @ e1)
            faces.append(f[np.argsort(ang)].tolist())
    return svm.init.from_polygons(v, faces, radius=radius)


# ------------------------------------------------------------------ random divisions and extrusions
@pytest.mark.parametrize("make", [lambda: svm.init.random_tiling(16, replicas=2, seed=3),
                                  lambda: svm.init_plane.hexagonal_tiling(3, 4)], ids=["sphere", "plane"])
def test_invariants_after_thousands_of_random_divisions_and_extrusions(make):
    """Random cuts of random cells (no relaxation in between), and a T2 attempt on every triangle
    after each; when a replica passes 120 cells, it is restarted from the tiling."""
    state = make()
    gen = np.random.default_rng(11)
    done = {"divide": 0, "extrude": 0, "refused": 0}
    for it in range(700):
        if state.n_cells > 120 * state.n_replicas:
            state = make()
        cells = np.unique(gen.integers(state.n_cells, size=2))
        before = state.n_cells
        change, out = growth.divide(state, cells, gen.normal(size=(len(cells), 3)))
        ok = sum(not isinstance(o, str) for o in out)
        assert state.n_cells == before + ok and len(change.cell_source) == state.n_cells
        assert len(change.vertex_source) == state.n_vertices == before * 0 + state.n_vertices
        done["divide"] += ok
        tri = np.flatnonzero(np.asarray(state.cell_sides) == 3)
        if len(tri):
            before = state.n_cells
            change, out = growth.extrude(state, tri)
            ok = sum(not isinstance(o, str) for o in out)
            assert state.n_cells == before - ok
            done["extrude"] += ok
            done["refused"] += len(out) - ok
        if it % 50 == 0:
            check_tissue(state, simple=False)      # a cut through a non-convex cell may cross it
    check_tissue(state, simple=False)
    assert done["divide"] > 1000 and done["extrude"] > 5, done


def test_divisions_and_extrusions_in_a_relaxing_simulation():
    """Division (a random cell of each replica every 3 steps), T2 of small triangles, T1 and FIRE
    together; the tissue is checked every 50 steps."""
    sim = svm.Simulation(device="cpu", seed=1)
    sim.state = svm.init.random_tiling(16, replicas=2, seed=3)
    sim.operations.forces.append(VertexModel.dimensionless(kr=1.0, p0=3.6))
    sim.operations.updaters.append(T1(threshold=0.1, new_length=0.3))

    def rule(s):
        g = np.random.default_rng(s.timestep)
        return [int(g.integers(a, b)) for a, b in zip(s.state.cell_start[:-1], s.state.cell_start[1:]) if b - a < 40]

    div, ext = Division(rule=rule, axis="random", trigger=3), Extrusion(area_threshold=0.6)
    sim.operations.updaters.extend([div, ext])
    sim.operations.integrator = FIRE(dt=0.05)
    for _ in range(12):
        sim.run(50)
        check_tissue(sim.state)
    assert div.total_divisions.sum() >= 40 and ext.total_extrusions.sum() >= 2
    assert ext.refused["not_triangle"].sum() > 0


# ------------------------------------------------------------------ known answers
@pytest.mark.parametrize("angle", [0.1, 0.7, 1.3, 2.9])
def test_a_regular_hexagon_divides_into_two_equal_halves(angle):
    state = svm.init_plane.hexagonal_tiling(4, 4)
    m = [np.cos(angle), np.sin(angle), 0.0]
    change, out = growth.divide(state, [5], [m])
    daughter = out[0]
    areas = state.constraint.cell_areas_np(state)
    mother = int(change.cell_map[5])
    assert areas[mother] == pytest.approx(0.5, rel=1e-12) and areas[daughter] == pytest.approx(0.5, rel=1e-12)
    assert abs(areas[mother] - areas[daughter]) < 1e-12 * areas[mother]
    assert change.new_cells.sum() == 1 and change.cell_source[daughter] == 5
    assert np.asarray(state.cell_sides)[[mother, daughter]].tolist() == [5, 5]
    check_tissue(state)


def test_a_regular_square_on_the_sphere_divides_into_two_equal_halves():
    state = _cube(radius=1.3)
    a0 = state.constraint.cell_areas_np(state)[2]
    _, out = growth.divide(state, [2], [[0.3, -0.8, 0.5]])
    areas = state.constraint.cell_areas_np(state)
    assert areas[2] == pytest.approx(a0 / 2, rel=1e-12) and areas[out[0]] == pytest.approx(a0 / 2, rel=1e-12)
    check_tissue(state)


def test_hertwig_cuts_perpendicular_to_the_long_axis():
    """Pointy-top hexagons stretched 2x along y: the daughters sit one above the other (along y).
    (Stretched along x, the perpendicular cut would pass through the top and bottom corners: refused.)"""
    hexes = svm.init_plane.hexagonal_tiling(4, 4)
    pos = np.asarray(hexes.positions).copy()
    pos[:, 1] *= 2.0
    rows = [np.asarray(hexes.cell_vertices)[c].tolist() for c in range(hexes.n_cells)]
    state = svm.init.from_polygons(pos, rows, box=hexes.box_np()[0] * [1.0, 2.0])
    sim = svm.Simulation(device="cpu")
    sim.state = state
    div = Division(rule=lambda s: [5], axis="hertwig", trigger=1)
    sim.operations.updaters.append(div)
    sim.operations.integrator = FIRE()
    div.update(sim, 0)
    s = sim.state
    centres = np.asarray(s.constraint.cell_geometry(s).center)
    d = centres[5] - centres[s.n_cells - 1]
    d[:2] -= s.box_np()[0] * np.round(d[:2] / s.box_np()[0])
    assert abs(d[1]) > 0.5 and abs(d[0]) < 1e-12
    assert div.total_divisions.tolist() == [1]
    check_tissue(s)


def test_division_then_matching_extrusion_restores_the_tissue():
    state = _tetrahedron()
    before = (state.n_cells, state.n_vertices, sorted(np.asarray(state.cell_sides).tolist()))
    _, out = growth.divide(state, [0], [[0.2, 1.0, -0.4]])
    assert state.n_cells == 5 and state.n_vertices == 6
    halves = [0, out[0]]
    tri = [c for c in halves if state.cell_sides[c] == 3]
    check_tissue(state)
    assert len(tri) == 1   # a triangle cut through its centre: a triangle and a quadrilateral
    assert sorted(np.asarray(state.cell_sides).tolist()) == [3, 3, 4, 4, 4]
    _, back = growth.extrude(state, tri)
    assert not isinstance(back[0], str)
    assert (state.n_cells, state.n_vertices, sorted(np.asarray(state.cell_sides).tolist())) == before
    check_tissue(state)


# ------------------------------------------------------------------ refusals and bad input
def test_a_cut_through_a_triangle_corner_is_refused_and_counted():
    state = _tetrahedron()
    ed = growth.Editor(state)
    cen, n, q = ed.centre(0)
    m = np.cross(n, q[0] - cen)                    # the cut runs through the centre and corner 0
    sim = svm.Simulation(device="cpu")
    sim.state = state
    div = Division(rule=lambda s: [0], axis=lambda s, cells: [m])
    sim.operations.updaters.append(div)
    sim.operations.integrator = FIRE()
    sim.run(1)
    assert sim.state.n_cells == 4 and div.refused["through_vertex"].tolist() == [1]
    assert div.total_divisions.tolist() == [0]
    check_tissue(sim.state)


def test_extrusions_that_would_break_the_tissue_are_refused_and_counted():
    sim = svm.Simulation(device="cpu")
    sim.state = _tetrahedron()
    ext = Extrusion(rule=lambda s: [0])
    sim.operations.updaters.append(ext)
    sim.operations.integrator = FIRE()
    sim.run(1)
    assert sim.state.n_cells == 4 and ext.refused["neighbours"].tolist() == [1]
    sim2 = svm.Simulation(device="cpu")
    sim2.state = svm.init_plane.hexagonal_tiling(3, 4)
    ext2 = Extrusion(area_threshold=2.0)          # every hexagon is selected, none is a triangle
    sim2.operations.updaters.append(ext2)
    sim2.operations.integrator = FIRE()
    sim2.run(1)
    assert sim2.state.n_cells == 12 and ext2.refused["not_triangle"].tolist() == [12]
    assert sim.log("extrusion_refused").tolist() == [1]


@pytest.mark.parametrize("kwargs, name", [
    (dict(rule="rate", rate=-1.0), "rate"), (dict(rule="rate", rate=float("nan")), "rate"),
    (dict(rule="rate", rate=float("inf")), "rate"), (dict(rule="area", area_threshold=-2), "area_threshold"),
    (dict(rule="area", area_threshold=float("nan")), "area_threshold"), (dict(rule="rate"), "rate"),
    (dict(rule="often", rate=1), "rule"), (dict(rate=1, axis="sideways"), "axis"),
    (dict(rate=1, max_cells=0), "max_cells"), (dict(rate=1, dt=-1), "dt")])
def test_bad_division_parameters_name_themselves(kwargs, name):
    with pytest.raises(ValueError, match=name):
        Division(**kwargs)


@pytest.mark.parametrize("kwargs, name", [(dict(area_threshold=-0.1), "area_threshold"),
                                          (dict(area_threshold=float("inf")), "area_threshold"),
                                          (dict(), "area_threshold"), (dict(rule="tiny"), "rule")])
def test_bad_extrusion_parameters_name_themselves(kwargs, name):
    with pytest.raises(ValueError, match=name):
        Extrusion(**kwargs)


# ------------------------------------------------------------------ the updaters in a simulation
def _grow_sim(n_cells=24, replicas=2, **division):
    sim = svm.Simulation(device="cpu", seed=5)
    sim.state = svm.init.random_tiling(n_cells, replicas=replicas, seed=2)
    n = sim.state.n_cells
    vm = VertexModel(kA=np.linspace(1.0, 2.0, n), kP=1.0, A0=np.linspace(0.9, 1.1, n), P0=3.8)
    sim.operations.forces.append(vm)
    sim.operations.updaters.append(T1())
    div = Division(**division)
    sim.operations.updaters.append(div)
    sim.operations.integrator = FIRE(dt=0.05)
    return sim, vm, div


def test_per_cell_parameters_and_lineage_follow_their_cells():
    sim, vm, div = _grow_sim(rule="rate", rate=0.05, axis="random", dt=1.0)
    kA0 = np.linspace(1.0, 2.0, sim.state.n_cells)
    fire = sim.operations.integrator
    for _ in range(10):
        sim.run(5)
        assert len(vm.kA) == sim.state.n_cells and len(div.lineage) == sim.state.n_cells
        assert len(fire.velocities) == sim.state.n_vertices
    assert div.total_divisions.sum() > 5
    np.testing.assert_array_equal(vm.kA, kA0[div.lineage])
    np.testing.assert_array_equal(vm.A0, np.linspace(0.9, 1.1, len(kA0))[div.lineage])
    assert np.all(sim.state.cell_replica_np() == (div.lineage >= 24))   # lineages stay in their replica
    assert sim.log("division_total").tolist() == div.total_divisions.tolist()
    check_tissue(sim.state, orientation=False)
    n = sim.state.n_cells
    sim.minimize(max_steps=200)                    # growth sits minimisations out (tests/test_growth_devices.py)
    assert sim.state.n_cells == n and len(vm.kA) == n
    check_tissue(sim.state, orientation=False)


def test_new_vertices_start_at_rest():
    sim, vm, div = _grow_sim(rule=lambda s: [3, 30], axis="hertwig", trigger=svm.trigger.Periodic(1000, phase=1000))
    fire = sim.operations.integrator
    sim.run(4)
    fire.velocities[:] = 1.0
    div.update(sim, 4)
    v = np.asarray(fire.velocities)
    assert div.total_divisions.tolist() == [1, 1] and len(v) == sim.state.n_vertices
    moved = np.flatnonzero((v == 0).all(axis=1))
    assert len(moved) == 4                          # two new vertices per division
    assert np.all(v[np.setdiff1d(np.arange(len(v)), moved)] == 1.0)


def test_the_rate_rule_draws_philox_per_cell():
    sim, vm, div = _grow_sim(rule="rate", rate=0.3, axis="random", dt=0.5)
    n = sim.state.n_cells
    u = rng.uniform(sim.seed, rng.STREAM_DIVISION, 0, np.arange(n), 1)[:, 0]
    expected = np.flatnonzero(u < 1 - np.exp(-0.3 * 0.5))
    chosen = div.choose(sim, 0)
    np.testing.assert_array_equal(np.sort(chosen), expected)
    div.update(sim, 0)
    assert div.total_divisions.sum() + sum(r.sum() for r in div.refused.values()) == len(expected)


def test_max_cells_caps_each_replica_and_area_rule():
    sim, vm, div = _grow_sim(rule="area", area_threshold=0.0, max_cells=30)
    sim.run(3)
    assert sim.state.cells_per_replica.tolist() == [30, 30]
    check_tissue(sim.state)


# ------------------------------------------------------------------ radius schedule
def test_radius_schedule_constant_area_fixed_and_callable():
    sim, vm, div = _grow_sim(rule="rate", rate=0.1, axis="hertwig", dt=1.0)
    sched = RadiusSchedule("constant_area", area=1.0)
    sim.operations.updaters.append(sched)
    sim.run(10)
    np.testing.assert_allclose(sim.state.mean_cell_area, 1.0, rtol=1e-12)
    assert np.all(sim.state.cells_per_replica > 24)
    check_tissue(sim.state, orientation=False)
    sim.operations.updaters.remove(sched)
    sim.operations.updaters.append(RadiusSchedule("fixed"))
    r = sim.state.radius_np().copy()
    sim.run(5)
    np.testing.assert_array_equal(sim.state.radius_np(), r)
    sim.operations.updaters.append(RadiusSchedule(lambda s: 2.0 + 0.01 * s.timestep))
    sim.run(1)
    np.testing.assert_allclose(sim.state.radius_np(), 2.0 + 0.01 * 15)
    check_tissue(sim.state, orientation=False)
    sim.operations.updaters.append(RadiusSchedule(lambda s: -1.0))
    with pytest.raises(ValueError, match="positive and finite"):
        sim.run(1)


def test_radius_schedule_refuses_bad_modes_and_a_radius_function_off_the_sphere():
    with pytest.raises(ValueError, match="mode"):
        RadiusSchedule("sometimes")
    sim = svm.Simulation(device="cpu")
    sim.state = svm.init_plane.hexagonal_tiling(3, 4)
    with pytest.raises(ValueError, match="radius function needs a surface sized by one radius.*mode='constant_area'"):
        sim.operations.updaters.append(RadiusSchedule(lambda s: 2.0))


@pytest.mark.parametrize("surface", ["sphere", "plane", "torus:R=3,r=1", "bump:height=1.5,width=1,box=12"])
def test_a_new_mean_area_scales_every_length(surface):
    """RadiusSchedule(area=2) on tilings of <A> = 1, nothing else moving: the surface's every
    parameter and every vertex position scale by sqrt(2)."""
    sim = svm.Simulation(device="cpu", seed=3)
    sim.state = svm.init.tilings_on(surface, 64, [(1, 0), (1, 1)])
    before = sim.state.copy()
    sim.operations.updaters.append(RadiusSchedule("constant_area", area=2.0))
    sim.operations.integrator = FIRE(dt=1e-12)
    sim.run(1)
    assert np.allclose(sim.state.size_np(), np.sqrt(2) * before.size_np(), rtol=1e-14)
    assert np.allclose(sim.state.positions, np.sqrt(2) * before.positions, rtol=0, atol=1e-12)
    assert np.allclose(sim.state.mean_cell_area, 2.0, rtol=1e-12)


@pytest.mark.parametrize("surface", ["plane", "torus:R=3,r=1", "bump:height=1.5,width=1,box=12"])
def test_the_size_schedule_keeps_the_mean_area_on_any_surface(surface):
    """Cells divide; with mode="constant_area" every length of the surface (the plane's box, the
    torus's radii, the bump's box, height and width) scales so that <A> stays what it was, its shape
    kept, every vertex on the new surface and the tiling valid."""
    sim = svm.Simulation(device="cpu", seed=3)
    sim.state = svm.init.tilings_on(surface, 64, [(1, 0), (1, 1)])
    shape = sim.state.size_np() / sim.state.size_np()[:, :1]
    area0 = sim.state.mean_cell_area.copy()
    start = sim.state.copy()

    def covered(state):           # the cells' flat areas over the surface's: below 1 by the flat facets' cut
        areas = np.bincount(state.cell_replica_np(), weights=state.constraint.cell_areas_np(state))
        return areas / state.constraint.total_area_np(state.size_np())
    sim.operations.forces.append(VertexModel.dimensionless(kr=1.0, p0=3.8))
    sim.operations.updaters.append(T1())
    sim.operations.updaters.append(Division(rule="rate", rate=0.5, dt=0.1))
    sim.operations.updaters.append(RadiusSchedule("constant_area"))
    sim.operations.integrator = FIRE(dt=0.02)
    sim.run(6)
    s = sim.state
    assert np.all(s.cells_per_replica > 64)
    assert np.allclose(s.mean_cell_area, area0, rtol=1e-12)
    assert np.allclose(s.size_np() / s.size_np()[:, :1], shape, rtol=1e-12)
    size = s.constraint.size(s, s.vertex_replica)
    assert np.abs(s.constraint.distance_to_surface(s.positions, size)).max() < 1e-9
    assert np.all(covered(s) > covered(start) - 0.01)     # the cells cover the grown surface as before
    s.validate(simple=False)


# ------------------------------------------------------------------ GSD with changing counts
def test_gsd_round_trip_with_changing_counts(tmp_path):
    pytest.importorskip("gsd")
    path = tmp_path / "grow.gsd"
    sim, vm, div = _grow_sim(rule="rate", rate=0.2, axis="random", replicas=1, dt=1.0)
    sim.operations.updaters.append(Extrusion(area_threshold=0.3))
    sim.operations.writers.append(GSD(1, path))
    snapshots = []
    for _ in range(8):
        sim.run(1)
        snapshots.append(sim.state.copy())
    sim.operations.writers[0].close()
    counts = {s.n_cells for s in snapshots}
    assert len(counts) > 2
    with svm.gsdio.Reader(path) as reader:
        assert len(reader) == 9
        for i, snap in enumerate(snapshots, start=1):
            back = reader.state(i)
            assert back.n_cells == snap.n_cells and back.n_vertices == snap.n_vertices
            np.testing.assert_array_equal(back.positions, snap.positions)
            np.testing.assert_array_equal(back.cell_vertices[:, :snap.max_sides], snap.cell_vertices)
            np.testing.assert_array_equal(back.vertex_neighbors, snap.vertex_neighbors)
            check_tissue(back, simple=False)       # FIRE steps of dt = 1 on a growing tissue cross cells
