"""The flat-facet metric (spherevm.geometry.flat, spherevm.constraints.flat) on the sphere:
``Sphere(metric="flat")``. Exact gradients, the areas of planar tilings, convergence to the geodesic
metric at second order, a minimisation with T1, GSD round trip, and the GPU's refusal."""
import pickle
import sys
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

import spherevm as svm
from spherevm.constraints import FlatSphere, Sphere
from spherevm.device import Device
from spherevm.geometry import flat
from spherevm.plugins.forces import VertexModel
from spherevm.plugins.integrators import FIRE, Brownian
from spherevm.plugins.updaters import T1
from spherevm.testing import check_force

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "benchmarks"))
from flat_metric import differences, slope  # noqa: E402


def _flat(state):
    state.constraint = Sphere(metric="flat")
    return state


# ------------------------------------------------------------------ the constraint
def test_metric_argument_repr_and_pickle():
    f = Sphere(metric="flat")
    assert type(f) is FlatSphere and isinstance(f, Sphere) and f.metric == "flat"
    assert repr(f) == "Sphere(metric='flat')" and repr(Sphere()) == "Sphere()"
    assert type(Sphere(metric="geodesic")) is Sphere and Sphere().metric == "geodesic"
    assert type(pickle.loads(pickle.dumps(f))) is FlatSphere
    with pytest.raises(ValueError, match=r"metric must be one of \('geodesic', 'flat'\), got 'chord'"):
        Sphere(metric="chord")
    with pytest.raises(ValueError, match="FlatSphere measures with the flat metric, got metric='geodesic'"):
        FlatSphere(metric="geodesic")


def test_lengths_are_chords():
    s = _flat(svm.init.random_tiling(32, seed=2))
    u, v = np.arange(5), s.vertex_neighbors[:5, 0]
    assert np.array_equal(s.constraint.edge_lengths(s, u, v), np.linalg.norm(s.positions[v] - s.positions[u], axis=1))
    assert s.constraint.chord_length(0.3, s.radius_np()) == 0.3


# ------------------------------------------------------------------ forces
@pytest.mark.parametrize("params", [dict(kA=1.0, kP=1.0, A0=1.0, P0=3.8), dict(kA=3.0, kP=0.0, A0=0.7, P0=0.0),
                                    dict(kA=0.0, kP=2.0, A0=0.0, P0=4.2)])
def test_forces_are_minus_the_gradient_and_tangent(params):
    s = _flat(svm.init.random_tiling(40, replicas=2, seed=3))
    report = check_force(VertexModel(**params), s, samples=20)
    report.assert_ok()
    forces = VertexModel(**params).compute(s).forces
    assert np.abs((forces * s.positions).sum(axis=1)).max() <= 1e-13 * np.abs(forces).max() * s.radius_np().max()


def test_per_cell_parameters_on_the_flat_metric():
    s = _flat(svm.init.random_tiling(30, replicas=2, seed=9))
    rng = np.random.default_rng(1)
    vm = VertexModel(kA=rng.uniform(0.5, 2, s.n_cells), kP=rng.uniform(0.5, 2, s.n_cells), A0=1.0,
                     P0=rng.uniform(3.4, 4.0, s.n_cells))
    check_force(vm, s, samples=20).assert_ok()


def test_a_missing_centre_or_sign_term_is_caught():
    """The FD check fails for the gradient with the perimeter term's sign flipped, or with the area
    term's 1/A left out (what a forgotten chain-rule factor gives)."""
    s = _flat(svm.init.random_tiling(24, replicas=1, seed=4))
    con = s.constraint
    bad = [lambda g, a, p, v: FlatSphere.shape_gradient(con, s, g, a, None if p is None else -p, v),
           lambda g, a, p, v: FlatSphere.shape_gradient(con, s, g, None, p, a[:, None] * g.area_vector)]
    for wrong in bad:
        con.shape_gradient = lambda state, g, a, p, v=None, wrong=wrong: wrong(g, a, p, v)
        assert not check_force(VertexModel(kA=1.0, kP=1.0, A0=0.8, P0=3.6), s, samples=8).ok
    del con.shape_gradient
    assert check_force(VertexModel(kA=1.0, kP=1.0, A0=0.8, P0=3.6), s, samples=8).ok


# ------------------------------------------------------------------ areas
@pytest.mark.parametrize("name, n_sides, edge_per_radius, area_per_edge2", [
    # regular dodecahedron: R = a sqrt(3) (1 + sqrt 5) / 4, area 3 sqrt(25 + 10 sqrt 5) a^2
    ("dodecahedron", {5: 12}, 4 / (np.sqrt(3) * (1 + np.sqrt(5))), 3 * np.sqrt(25 + 10 * np.sqrt(5))),
    # truncated icosahedron: R = a sqrt(58 + 18 sqrt 5) / 4, area 3 (10 sqrt 3 + sqrt(25 + 10 sqrt 5)) a^2
    ("truncated_icosahedron", {5: 12, 6: 20}, 4 / np.sqrt(58 + 18 * np.sqrt(5)),
     3 * (10 * np.sqrt(3) + np.sqrt(25 + 10 * np.sqrt(5)))),
])
def test_planar_cells_are_the_inscribed_polyhedron(name, n_sides, edge_per_radius, area_per_edge2):
    """Cells whose vertices are coplanar are the faces of the inscribed polyhedron: their flat
    areas are the faces' areas (regular pentagons and hexagons of edge a) and add up to its area."""
    s = _flat(svm.init.regular_tiling(name, radius=1.7))
    g = s.constraint.cell_geometry(s)
    a = edge_per_radius * 1.7
    face = {5: np.sqrt(5 * (5 + 2 * np.sqrt(5))) / 4 * a * a, 6: 3 * np.sqrt(3) / 2 * a * a}
    assert np.allclose(g.area, [face[k] for k in s.cell_sides], rtol=1e-13, atol=0)
    assert np.allclose(g.perimeter, s.cell_sides * a, rtol=1e-13, atol=0)
    assert g.area.sum() == pytest.approx(area_per_edge2 * a * a, rel=1e-13)
    assert sorted(np.bincount(s.cell_sides).nonzero()[0]) == sorted(n_sides)


def test_vector_areas_close_and_fall_short_of_the_sphere():
    """On a closed surface the cells' vector areas add up to 0; each |a_c| is the area of the cell's
    projection onto a plane, below the spherical patch's, so sum A_c < 4 pi R^2, short by about
    0.22 (h/R)^2 (docs/surfaces.md; 0.014 here): below (h/R)^2 / 2."""
    s = _flat(svm.init.random_tiling(200, replicas=2, seed=6))
    g = s.constraint.cell_geometry(s)
    R = s.radius_np()[0]
    for r in range(2):
        mine = s.cell_replica_np() == r
        assert np.abs(g.area_vector[mine].sum(axis=0)).max() < 1e-12 * R * R
        assert 0 < 1 - g.area[mine].sum() / (4 * np.pi * R * R) < 0.5 * 4 * np.pi / 200
    assert np.all(g.area > 0)
    # the formula for one polygon agrees with the corner sums
    c = 7
    poly = s.positions[s.cell_vertices[c, :s.cell_sides[c]]]
    assert np.allclose(flat.vector_area(poly), g.area_vector[c], rtol=1e-13, atol=0)
    assert flat.perimeter(poly) == pytest.approx(g.perimeter[c], rel=1e-14)


def test_convergence_to_the_geodesic_metric_is_second_order():
    """Mean relative area and perimeter differences over N = 64 .. 4096 (4 tilings each) fall as
    (h / R)^2, h = sqrt(<A>). The slopes measured for seeds 1..8 lie in [1.995, 2.003] (areas),
    [2.004, 2.020] (perimeters) and [1.97, 2.03] (the total shortfall): a first- or fourth-order
    error would be off by 1 or 2."""
    rows = np.array([differences(n, 4, seed=1) for n in (64, 256, 1024, 4096)])
    h = rows[:, 0]
    assert slope(h, rows[:, 1]) == pytest.approx(2.0, abs=0.03)
    assert slope(h, rows[:, 2]) == pytest.approx(2.0, abs=0.05)
    assert slope(h, rows[:, 3]) == pytest.approx(2.0, abs=0.1)
    assert np.all(np.diff(rows[:, 1:], axis=0) < 0)


# ------------------------------------------------------------------ operations
def test_fire_with_t1_minimises_on_the_flat_metric():
    sim = svm.Simulation(device="cpu")
    sim.state = _flat(svm.init.random_tiling(64, replicas=2, seed=1))
    sim.operations.forces.append(VertexModel.dimensionless(kr=1.0, p0=3.7))
    sim.operations.updaters.append(T1())
    sim.operations.integrator = FIRE(dt=0.02)
    result = sim.minimize(force_tol=1e-10, max_steps=3000)
    assert result.converged.all()
    assert (sim.log("t1_total_flips") > 0).all()
    s = sim.state
    assert np.abs(VertexModel.dimensionless(kr=1.0, p0=3.7).compute(s).forces).max() < 1e-9
    assert np.allclose(np.linalg.norm(s.positions, axis=1), s.radius_np()[s.vertex_replica_np()], rtol=1e-14)
    s.validate()
    # the same tilings minimised under the geodesic metric end elsewhere
    geo = svm.Simulation(device="cpu")
    geo.state = svm.init.random_tiling(64, replicas=2, seed=1)
    geo.operations.forces.append(VertexModel.dimensionless(kr=1.0, p0=3.7))
    geo.operations.updaters.append(T1())
    geo.operations.integrator = FIRE(dt=0.02)
    geo.minimize(force_tol=1e-10, max_steps=3000)
    assert not np.allclose(geo.log("energy"), sim.log("energy"), rtol=1e-3)


def test_brownian_dynamics_runs_on_the_flat_metric():
    sim = svm.Simulation(device="cpu", seed=3)
    sim.state = _flat(svm.init.random_tiling(40, seed=2))
    sim.operations.forces.append(VertexModel.dimensionless(kr=1.0, p0=3.8))
    sim.operations.updaters.append(T1())
    sim.operations.integrator = Brownian(dt=0.005, T=0.1)
    sim.run(50)
    s = sim.state
    assert np.allclose(np.linalg.norm(s.positions, axis=1), s.radius_np()[0], rtol=1e-14)
    assert np.isfinite(sim.log("energy")).all() and sim.log("t1_total_flips")[0] >= 0


def test_validation_judges_the_tiling_on_the_sphere():
    """The tiling checks add up the exact spherical areas (the flat ones fall short of 4 pi R^2)."""
    s = _flat(svm.init.random_tiling(50, seed=3))
    geodesic = Sphere().cell_geometry(s).area
    assert np.array_equal(s.constraint.tiling_areas_np(s), geodesic)
    assert abs(s.constraint.cell_areas_np(s).sum() / (4 * np.pi * s.radius_np()[0] ** 2) - 1) > 1e-3
    s.validate()


def test_gsd_round_trip_keeps_the_metric(tmp_path):
    from spherevm import gsdio
    s = _flat(svm.init.random_tiling(20, seed=1))
    path = tmp_path / "flat.gsd"
    sim = svm.Simulation(device="cpu")
    sim.state = s
    with svm.plugins.writers.GSD(filename=path) as w:
        w.write(sim, 0)
    back = gsdio.read_state(path)
    assert type(back.constraint) is FlatSphere and repr(back.constraint) == "Sphere(metric='flat')"
    assert np.array_equal(back.positions, s.positions)
    # the default sphere's stored constraint is what it always was
    assert bytes(gsdio._constraint_json(Sphere())) == b'{"class": "Sphere", "name": "sphere", "params": {}}'


def test_states_of_two_metrics_are_not_concatenated():
    flat_state = _flat(svm.init.random_tiling(20, seed=1))
    with pytest.raises(ValueError, match=r"one constraint type .*\['FlatSphere', 'Sphere'\]"):
        svm.State.concatenate([flat_state, svm.init.random_tiling(20, seed=2)])


# ------------------------------------------------------------------ the GPU
@pytest.mark.parametrize("operation, name", [(VertexModel(), "compute"), (FIRE(dt=0.01), "move"),
                                             (Brownian(dt=0.01, T=0.1), "step"), (T1(), "update")])
def test_gpu_kernels_refuse_the_flat_metric(operation, name):
    """Checked on a State whose device says GPU (only its device and surface matter here)."""
    state = SimpleNamespace(device=Device("gpu", np), constraint=Sphere(metric="flat"))
    with pytest.raises(ValueError, match=rf"{type(operation).__name__} on the GPU supports GeodesicSphere, "
                                         r"PeriodicPlane, ImplicitSurface surfaces only, but the state is on "
                                         r"Sphere\(metric='flat'\); "
                                         r"use device='cpu'"):
        operation.implementation(name, state)
    geodesic = SimpleNamespace(device=Device("gpu", np), constraint=Sphere())
    assert operation.implementation(name, geodesic) == getattr(operation, f"_{name}_gpu")


@pytest.mark.gpu
def test_a_flat_sphere_state_on_the_gpu_is_refused_at_attach():
    sim = svm.Simulation(device="gpu")
    sim.state = _flat(svm.init.random_tiling(20, seed=1)).to("gpu")
    with pytest.raises(ValueError, match=r"VertexModel on the GPU supports GeodesicSphere.*Sphere\(metric='flat'\)"):
        sim.operations.forces.append(VertexModel())
    assert len(sim.operations.forces) == 0
