"""The periodic plane: geometry, gradients, topology, tilings, operations, GSD and bad input."""
from types import SimpleNamespace

import numpy as np
import pytest
import scipy.spatial

import spherevm as svm
from spherevm.constraints import PeriodicPlane, Sphere
from spherevm.device import Device
from spherevm.plugins.forces import VertexModel
from spherevm.plugins.integrators import FIRE, Active, Brownian
from spherevm.plugins.updaters import T1

HEX_PERIMETER = np.sqrt(8 * np.sqrt(3))


def _energy(state, vm):
    return vm.compute(state).energy


def _moved(state, positions):
    s = state.copy()
    s.positions = s.constraint.project_normal(positions, s.box[s.vertex_replica])
    return s


# ------------------------------------------------------------------ geometry
@pytest.mark.parametrize("nx, ny", [(3, 4), (5, 6), (8, 4)])
def test_honeycomb_is_analytic(nx, ny):
    s = svm.init.hexagonal_tiling(nx, ny)
    g = s.constraint.cell_geometry(s)
    assert s.n_cells == nx * ny and s.n_vertices == 2 * nx * ny
    np.testing.assert_allclose(g.area, 1.0, rtol=1e-13)
    np.testing.assert_allclose(g.perimeter, HEX_PERIMETER, rtol=1e-13)
    assert abs(HEX_PERIMETER - 3.72242) < 1e-5
    np.testing.assert_allclose(s.mean_cell_area, 1.0, rtol=1e-13)
    c = g.center
    assert np.all(c[:, :2] >= 0) and np.all(c[:, :2] < s.box_np()[0]) and np.all(c[:, 2] == 0)


def test_honeycomb_has_zero_force_at_its_own_shape_index():
    s = svm.init.hexagonal_tiling(4, 6)
    vm = VertexModel(kA=1.0, kP=1.0, A0=1.0, P0=HEX_PERIMETER)
    r = vm.compute(s)
    assert abs(r.energy[0]) < 1e-24 and np.abs(r.forces).max() < 1e-12


@pytest.mark.parametrize("n, seed, box", [(30, 0, None), (40, 3, (4.0, 10.0)), (16, 5, None)])
@pytest.mark.parametrize("params", [dict(kr=1.0, p0=3.7), dict(kr=0.2, p0=4.1), dict(kr=5.0, p0=3.2, a0=1.3)])
def test_forces_are_minus_the_energy_gradient(n, seed, box, params):
    s = svm.init.random_planar_tiling(n, seed=seed, box=box)
    vm = VertexModel.dimensionless(**params)
    f = vm.compute(s).forces
    assert np.all(f[:, 2] == 0)
    # every vertex (so cells straddling the boundary are included), both in-plane directions
    h = 1e-6
    fd = np.zeros((s.n_vertices, 2))
    for ax in (0, 1):
        for v in range(s.n_vertices):
            e = []
            for sgn in (1, -1):
                p = s.positions.copy()
                p[v, ax] += sgn * h
                e.append(_energy(_moved(s, p), vm)[0])
            fd[v, ax] = -(e[0] - e[1]) / (2 * h)
    scale = np.abs(f).max()
    np.testing.assert_allclose(f[:, :2], fd, atol=1e-7 * max(scale, 1))
    # the boundary is actually crossed by some edge
    d = s.positions[s.vertex_neighbors] - s.positions[:, None]
    assert (np.abs(d[..., :2]) > s.box_np()[0] / 2).any()


# ------------------------------------------------------------------ topology
@pytest.mark.parametrize("n", [8, 12, 50, 200])
@pytest.mark.parametrize("seed", [0, 7])
def test_every_tiling_is_a_torus_covering_the_box(n, seed):
    s = svm.init.random_planar_tiling(n, replicas=2, seed=seed, box=None if n != 50 else (5.0, 10.0))
    nv, nc = s.vertices_per_replica, s.cells_per_replica
    assert np.all(nv - 3 * nv // 2 + nc == 0)
    area = np.bincount(s.cell_replica_np(), weights=s.constraint.cell_areas_np(s))
    np.testing.assert_allclose(area, s.box_np().prod(axis=1), rtol=1e-12)
    assert np.all(s.constraint.cell_areas_np(s) > 0)


_QHULL = scipy.spatial.Delaunay


class _ShuffledDelaunay:
    """scipy's Delaunay with its triangles listed in another order, each from another corner;
    ``sizes`` records how many points each call triangulated."""
    sizes: list = []

    def __init__(self, points):
        self.sizes.append(len(points))
        tri = _QHULL(points).simplices
        rng = np.random.default_rng(len(points))
        tri = tri[rng.permutation(len(tri))]
        self.simplices = np.take_along_axis(tri, (rng.integers(0, 3, len(tri))[:, None] + np.arange(3)) % 3, axis=1)


def _same_network(a, b):
    assert a is not None and b is not None
    return all(np.array_equal(x, y) for x, y in zip(a, b))


def test_large_tessellations_do_not_depend_on_the_images_triangulated_or_their_order(monkeypatch):
    """From MARGIN_MIN_CELLS on only the images within MARGIN_CELL_SIDES of the box are triangulated
    and the kept triangles are put in a canonical order: the margin, all 3 x 3 images, and a
    triangulation listing its triangles in another order and from other corners give the same
    tessellation to the bit; a margin too thin for some empty circle falls back to the full images.
    Below MARGIN_MIN_CELLS the full images are triangulated and Qhull's order is kept (the tilings
    of earlier versions), so there the shuffled triangulation numbers the network otherwise."""
    from spherevm import init_plane
    rng = np.random.default_rng(9)
    cases = [(1000, (50.0, 20.0), None), (600, (16.0, 37.5), None), (32, (9.8, 3.27), 8), (400, (16.0, 25.0), 100)]
    for n, box, least in cases:
        box = np.array(box)
        with monkeypatch.context() as m:
            if least is not None:       # the canonical path at a smaller N, as a small tiling would take it
                m.setattr(init_plane, "MARGIN_MIN_CELLS", least)
            full = None
            while full is None:         # a simple network (most 32-point draws in this box are not)
                pts = rng.uniform(0, 1, (n, 2)) * box
                full = init_plane.periodic_voronoi(pts, box, margin=False)
            _ShuffledDelaunay.sizes = []
            m.setattr(scipy.spatial, "Delaunay", _ShuffledDelaunay)
            assert _same_network(init_plane.periodic_voronoi(pts, box), full)
            assert _same_network(init_plane.periodic_voronoi(pts, box, margin=False), full)
            if n >= 400:
                assert _ShuffledDelaunay.sizes[0] < 0.5 * 9 * n           # the margin path ran
                m.setattr(init_plane, "MARGIN_CELL_SIDES", 0.3)       # no empty circle fits: the full images
                assert _same_network(init_plane.periodic_voronoi(pts, box), full)
                assert _ShuffledDelaunay.sizes[-1] == 9 * n
    pts = rng.uniform(0, 1, (400, 2)) * 20.0
    box = np.array([20.0, 20.0])
    plain = init_plane.periodic_voronoi(pts, box)
    with monkeypatch.context() as m:
        _ShuffledDelaunay.sizes = []
        m.setattr(scipy.spatial, "Delaunay", _ShuffledDelaunay)
        shuffled = init_plane.periodic_voronoi(pts, box)
    assert _ShuffledDelaunay.sizes == [9 * 400]
    assert not _same_network(shuffled, plain)
    np.testing.assert_allclose(np.sort(shuffled[0], axis=0), np.sort(plain[0], axis=0), atol=1e-12)


def test_replicas_are_reproducible_and_may_differ_in_box():
    a = svm.init.random_planar_tiling(20, replicas=3, seed=4)
    b = svm.init.random_planar_tiling(20, replicas=1, seed=4)
    np.testing.assert_array_equal(a.replica(0).positions, b.positions)
    big = svm.init.random_planar_tiling(30, seed=1, box=(5.0, 9.0))
    mixed = svm.State.concatenate([b, big])
    mixed.validate()
    np.testing.assert_allclose(mixed.mean_cell_area, [1.0, 1.5])
    np.testing.assert_allclose(np.bincount(mixed.cell_replica_np(), weights=mixed.constraint.cell_areas_np(mixed)),
                               [20.0, 45.0], rtol=1e-12)
    part = mixed.select(mixed.selection([1]))
    np.testing.assert_array_equal(part.box_np(), [[5.0, 9.0]])


def test_check_rejects_a_wrong_euler_characteristic_and_positions_outside_the_box():
    s = svm.init.hexagonal_tiling(3, 4)
    bad = s.copy()
    bad.positions[0, 0] += s.box_np()[0, 0]
    with pytest.raises(ValueError, match="outside its periodic box"):
        bad.validate()
    bad = s.copy()
    bad.positions[0, 2] = 0.1
    with pytest.raises(ValueError, match="off the surface"):
        bad.validate()


def test_sphere_check_still_wants_two():
    s = svm.init.random_tiling(20, seed=1)
    assert s.constraint.euler_characteristic == 2
    s.validate()


# ------------------------------------------------------------------ invariances
def test_energy_is_invariant_under_translation_and_choice_of_image():
    s = svm.init.random_planar_tiling(40, replicas=2, seed=2)
    vm = VertexModel.dimensionless(kr=1.0, p0=3.75)
    e0 = _energy(s, vm)
    rng = np.random.default_rng(0)
    for _ in range(5):
        shift = np.zeros(3)
        shift[:2] = rng.normal(size=2) * 10
        np.testing.assert_allclose(_energy(_moved(s, s.positions + shift), vm), e0, rtol=1e-11)
    p = s.positions.copy()
    lx, ly = s.box_np()[0]
    p[::3, 0] += lx
    p[1::3, 1] -= 2 * ly
    np.testing.assert_allclose(_energy(_moved(s, p), vm), e0, rtol=1e-11)


def test_a_new_box_is_seen_by_the_cached_tables():
    s = svm.init.random_planar_tiling(30, seed=2)
    vm = VertexModel.dimensionless(kr=1.0, p0=3.8)
    vm.compute(s)                                                   # fills the cache
    scaled = s.copy()
    scaled.positions = s.positions * 2.0
    scaled.box = s.box * 2.0
    np.testing.assert_allclose(scaled.constraint.cell_areas_np(scaled), 4.0 * s.constraint.cell_areas_np(s),
                               rtol=1e-13)
    s.positions = s.positions * 2.0
    s.box = s.box * 2.0                                             # the same State, a new box array
    np.testing.assert_allclose(s.constraint.cell_areas_np(s), scaled.constraint.cell_areas_np(scaled), rtol=1e-15)


def test_projections_and_lengths():
    con = PeriodicPlane()
    box = np.array([[2.0, 3.0]])
    x = np.array([[-0.5, 7.0, 0.3], [2.0, -1e-17, -1.0]])
    p = con.project_normal(x, box)
    np.testing.assert_allclose(p, [[1.5, 1.0, 0.0], [0.0, 0.0, 0.0]], atol=1e-15)
    assert np.all(p[:, :2] < box) and np.all(p[:, :2] >= 0)
    np.testing.assert_array_equal(con.normal(x), [[0, 0, 1]] * 2)
    np.testing.assert_array_equal(con.project_tangent(x, x)[:, 2], 0)
    assert con.chord_length(1.7, box) == 1.7
    np.testing.assert_allclose(con.distance_to_surface(x, box), [0.3, 1.0])
    np.testing.assert_allclose(con.total_area_np(box), [6.0])


# ------------------------------------------------------------------ operations
def _sim(state, p0, kr=0.0, seed=1):
    sim = svm.Simulation(device="cpu", seed=seed)   # the GPU's agreement: tests/test_plane_gpu.py
    sim.state = state
    sim.operations.forces.append(VertexModel.dimensionless(kr=kr, p0=p0))
    return sim


def test_fire_floppy_above_and_rigid_below_the_transition():
    energies = {}
    for p0 in (3.9, 3.6):
        sim = _sim(svm.init.random_planar_tiling(40, seed=3), p0)
        fire = FIRE(dt=0.01, force_tol=1e-10, energy_tol=1e-16)
        sim.operations.integrator = fire
        sim.operations.updaters.append(T1(trigger=10))   # without T1 edges collapse to zero and FIRE stalls
        for _ in range(200):
            if fire.done:
                break
            sim.run(100)
        energies[p0] = sim.compute_forces()[1][0] / sim.state.n_cells
        sim.state.validate(orientation=False)
        assert fire.done
    assert energies[3.9] < 1e-12
    assert energies[3.6] > 1e-2


def test_brownian_with_hot_t1_keeps_a_valid_torus():
    state = svm.init.random_planar_tiling(20, replicas=2, seed=6)
    sim = _sim(state, 3.9, kr=1.0, seed=3)
    sim.operations.integrator = Brownian(dt=0.01, T=0.2)
    t1 = T1(threshold=0.2, new_length=0.3, trigger=1)
    sim.operations.updaters.append(t1)
    for _ in range(6):
        sim.run(50)
        sim.state.validate(orientation=False)
    assert t1.total_flips.sum() > 10
    s = sim.state
    np.testing.assert_allclose(np.bincount(s.cell_replica_np(), weights=s.constraint.cell_areas_np(s)),
                               s.box_np().prod(axis=1), rtol=1e-9)
    assert np.all(s.positions[:, 2] == 0)


@pytest.mark.parametrize("directors", ["cell", "vertex"])
def test_active_directors_stay_in_the_plane_and_diffuse_by_angle(directors):
    """Directors start as unit vectors in the plane, stay there, and turn about z by Gaussian angles
    of variance 2 Dr dt per step: <cos(dtheta)> = exp(-Dr t) after time t."""
    state = svm.init.random_planar_tiling(400, seed=4)
    sim = _sim(state, 3.9, kr=1.0, seed=8)
    dr, dt, steps = 1.0, 0.01, 50
    sim.operations.integrator = Active(dt=dt, v0=0.05, Dr=dr, directors=directors)
    sim.run(1)
    d0 = sim.operations.integrator.directors.copy()
    sim.run(steps)
    d = sim.operations.integrator.directors
    assert np.all(d[:, 2] == 0) and np.all(d0[:, 2] == 0)
    np.testing.assert_allclose(np.linalg.norm(d, axis=1), 1.0, rtol=1e-14)
    cos = (d * d0).sum(axis=1)
    expected = np.exp(-dr * dt * steps)
    assert abs(cos.mean() - expected) < 4 * cos.std() / np.sqrt(len(cos))
    assert np.all(sim.state.positions[:, 2] == 0)


def test_t1_flip_across_the_boundary_rotates_about_the_midpoint():
    s = svm.init.hexagonal_tiling(3, 4)
    con = s.constraint
    vn = s.vertex_neighbors
    d = s.positions[vn] - s.positions[:, None]
    u, slot = np.argwhere(np.abs(d[..., 0]) > s.box_np()[0, 0] / 2)[0]     # an edge crossing x = 0
    v = vn[u, slot]
    pu = s.positions[u].copy()
    before = con.unwrap(s.positions[v], pu, s.box_np()[0])
    mid = con.project_normal(0.5 * (s.positions[u] + before), s.box_np()[0])
    svm.topology.t1_flip(s, np.array([u]), np.array([slot]), 0.5)
    s.validate()
    a, b = s.positions[u], con.unwrap(s.positions[v], s.positions[u], s.box_np()[0])
    assert abs(np.linalg.norm(b - a) - 0.5) < 1e-12
    np.testing.assert_allclose(con.unwrap(0.5 * (a + b), mid, s.box_np()[0]), mid, atol=1e-12)
    assert abs(np.dot(b - a, before - pu)) < 1e-12


def test_gpu_paths_serve_the_plane_and_refuse_other_surfaces():
    """The CUDA paths are compiled per surface (geometry/surface.cuh): the plane binds them, a
    surface without kernels is refused naming the ones that have them."""
    plane = SimpleNamespace(device=Device("gpu", np), constraint=PeriodicPlane())
    flat = SimpleNamespace(device=Device("gpu", np), constraint=svm.constraints.Sphere(metric="flat"))
    for op, name in ((VertexModel(), "compute"), (FIRE(), "move"), (Brownian(dt=0.01, T=0.1), "step"),
                     (T1(), "update")):
        assert op.implementation(name, plane).__name__ == f"_{name}_gpu"
        with pytest.raises(ValueError, match="Sphere, PeriodicPlane, ImplicitSurface surfaces only.*metric='flat'"):
            op.implementation(name, flat)


# ------------------------------------------------------------------ GSD
def test_gsd_round_trip_of_a_planar_state(tmp_path):
    gsd = pytest.importorskip("gsd.hoomd")
    s = svm.init.random_planar_tiling(25, replicas=2, seed=1, box=(4.0, 6.25))
    sim = _sim(s, 3.8, kr=1.0)
    path = tmp_path / "plane.gsd"
    sim.operations.writers.append(svm.plugins.writers.GSD(1, path))
    sim.operations.integrator = Brownian(dt=0.01, T=0.1)
    sim.run(3)
    back = svm.init.from_gsd(path, validate=True)
    assert isinstance(back.constraint, PeriodicPlane) and back.radius is None
    np.testing.assert_array_equal(back.positions, sim.state.positions)
    np.testing.assert_array_equal(back.box_np(), sim.state.box_np())
    with gsd.open(path) as traj:
        frame = traj[-1]
        np.testing.assert_allclose(frame.configuration.box, [4.0, 6.25, 0, 0, 0, 0])
        assert frame.configuration.dimensions == 2
        p = frame.particles.position
        assert np.all(np.abs(p[:, :2]) <= np.array([2.0, 3.125]) + 1e-6)


# ------------------------------------------------------------------ bad input
@pytest.mark.parametrize("box", [0.0, -1.0, np.inf, np.nan, (1.0, 2.0, 3.0)])
def test_bad_boxes_are_refused(box):
    with pytest.raises(ValueError, match="box"):
        svm.init.random_planar_tiling(20, box=box)


def test_too_few_cells_and_bad_honeycombs_are_refused():
    with pytest.raises(ValueError, match="n_cells"):
        svm.init.random_planar_tiling(7)
    with pytest.raises(ValueError, match="ny"):
        svm.init.hexagonal_tiling(3, 5)
    with pytest.raises(ValueError, match="nx"):
        svm.init.hexagonal_tiling(2, 4)
    svm.init.random_planar_tiling(svm.init.MIN_PLANAR_CELLS, seed=0)


def test_from_polygons_checks_its_input():
    s = svm.init.hexagonal_tiling(3, 4)
    cells = [row[:k].tolist() for row, k in zip(s.cell_vertices, s.cell_sides)]
    box = s.box_np()[0]
    again = svm.init.from_polygons(s.positions, cells, box=box)
    np.testing.assert_array_equal(again.positions, s.positions)
    p = s.positions.copy()
    p[2, 0] = box[0] + 0.1
    with pytest.raises(ValueError, match="vertices must lie in the box"):
        svm.init.from_polygons(p, cells, box=box)
    with pytest.raises(ValueError, match="not both"):
        svm.init.from_polygons(s.positions, cells, radius=1.0, box=box)
    with pytest.raises(ValueError, match="box must be positive"):
        svm.init.from_polygons(s.positions, cells, box=(-1.0, 2.0))


def test_surface_and_size_must_match():
    s = svm.init.hexagonal_tiling(3, 4)
    arrays = dict(positions=s.positions, cell_vertices=s.cell_vertices, cell_sides=s.cell_sides,
                  vertex_neighbors=s.vertex_neighbors, vertex_cells=s.vertex_cells, vertex_start=s.vertex_start,
                  cell_start=s.cell_start)
    with pytest.raises(ValueError, match="box is given.*needs radius"):
        svm.State(**arrays, box=s.box_np(), constraint=Sphere())
    with pytest.raises(ValueError, match="needs box"):
        svm.State(**arrays, radius=2.0, constraint=PeriodicPlane())
    sphere = svm.init.random_tiling(20)
    with pytest.raises(ValueError, match="one constraint type"):
        svm.State.concatenate([sphere, s])


def test_minimize_narrows_a_planar_ensemble_bitwise():
    def run(narrow):
        state = svm.State.concatenate([svm.init.random_planar_tiling(16, seed=k, box=(4.0, 4.0 + k)) for k in range(4)])
        sim = _sim(state, 3.7, kr=1.0)
        sim.operations.integrator = FIRE(dt=0.01, force_tol=1e-9)
        sim.operations.updaters.append(T1(trigger=10))
        sim.minimize(max_steps=20000, narrow=narrow)
        return sim.state
    a, b = run(True), run(False)
    np.testing.assert_array_equal(a.positions, b.positions)
    np.testing.assert_array_equal(a.box_np(), b.box_np())


def test_t1_refuses_a_box_of_fewer_than_16_cells_per_replica():
    """Smaller boxes let edges reach half the box under T1 (docs/plane.md): refused at attach."""
    sim = svm.Simulation(device="cpu")
    sim.state = svm.State.concatenate([svm.init.random_planar_tiling(16, seed=0),
                                       svm.init.random_planar_tiling(14, seed=0)])
    with pytest.raises(ValueError, match=r"^T1 needs at least 16 cells per replica on a periodic plane, but replica 1 "
                                         r"has 14: in a smaller box edges reach half the box"):
        sim.operations.updaters.append(T1())
    sim.state = svm.init.random_planar_tiling(16, replicas=2, seed=0)
    sim.operations.updaters.append(T1())
    sim.operations.integrator = Brownian(dt=0.01, T=0.01)
    sim.run(2)


def test_a_run_stops_at_the_step_a_cell_stops_closing():
    """Hot Brownian steps on tiny periodic boxes: an edge reaches half the box; the run's check (every
    step on the CPU) names the timestep, replica and edge at the step it happens, not later."""
    import re
    from spherevm import simplicity
    from spherevm.plugins.forces import VertexModel
    from spherevm.plugins.integrators import Brownian

    def hot():
        sim = svm.Simulation(device="cpu", seed=2)
        sim.state = svm.init.random_planar_tiling(10, replicas=16, seed=1)
        sim.operations.forces.append(VertexModel.dimensionless(kr=1, p0=3.8))
        sim.operations.integrator = Brownian(dt=0.005, T=0.5, max_step=5)
        return sim

    with pytest.raises(ValueError, match=r"at timestep \d+: replica \d+: edge \d+ -> \d+ of cell \d+ reached half "
                                         r"the box") as caught:
        hot().run(100)
    t = int(re.search(r"at timestep (\d+)", str(caught.value)).group(1))
    before = hot()
    before.run(t - 1)
    assert len(simplicity.open_cells(before.state)[0]) == 0, "every cell closed the step before"
    before.operations.integrator.step(before, before.compute_forces()[0])
    assert len(simplicity.open_cells(before.state)[0]) > 0, "and one stopped closing at that step"
