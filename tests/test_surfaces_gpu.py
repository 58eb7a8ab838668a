"""Implicit surfaces on the GPU (Implicit<Shape> of constraints/implicit.cuh) against the NumPy
path: forces and energies with per-cell parameters to 1e-12, FIRE with T1, T1 flip for flip (with
and without untangling), Brownian with T1 for 1,000 steps to the same tables, Active dynamics, cell
shapes, narrowed minimisations and bending, on the torus, the ellipsoid, the Gaussian bump and the
user's sinusoid; and the fused small-tissue steps bitwise the general kernels. Skipped without CuPy
and a GPU (conftest.py); the device code itself is compared with NumPy on the CPU by
tests/test_implicit_device.py."""
import pathlib

import numpy as np
import pytest
from conftest import (assert_brownian_with_t1_matches_numpy, assert_gpu_force_matches_numpy, assert_t1_round_matches_numpy,
                      dynamics_simulation, relative_gap, t1_simulations)

import spherevm as svm
from spherevm import shapes, tissue_steps
from spherevm.constraints import Ellipsoid, GaussianBump, Torus
from spherevm.constraints.registry import surface as parse_surface
from spherevm.plugins.forces import Bending, VertexModel
from spherevm.plugins.integrators import FIRE, Active, Brownian
from spherevm.plugins.updaters import T1

pytestmark = pytest.mark.gpu
EXAMPLE = pathlib.Path(__file__).parent / "plugin_example"
SURFACES = {"torus": lambda: Torus(3.0, 1.0), "ellipsoid": lambda: Ellipsoid(1.0, 1.5, 2.0),
            "bump": lambda: GaussianBump(1.5, 1.0, 10.0)}


@pytest.fixture(params=["torus", "ellipsoid", "bump", "sinusoid"])
def surface(request, monkeypatch):
    if request.param == "sinusoid":
        monkeypatch.syspath_prepend(str(EXAMPLE))
        return parse_surface("sinusoid:amplitude=1.5,box=10")
    return SURFACES[request.param]()


def _tissues(surface, n_cells, replicas, seed):
    return svm.State.concatenate([svm.init.random_tiling(n_cells, seed=seed + r, surface=surface)
                                  for r in range(replicas)])


def _gap(gpu_state, cpu_state):
    """Largest distance between the GPU's and the CPU's vertices (nearest images on a periodic surface)."""
    con = cpu_state.constraint
    size = con.size(cpu_state, cpu_state.vertex_replica)
    return np.abs(con.unwrap(gpu_state.positions.get(), cpu_state.positions, size) - cpu_state.positions).max()


def _table(state):
    cv = state.device.to_numpy(state.cell_vertices)
    return cv[:, :int(state.device.to_numpy(state.cell_sides).max())]


def test_forces_and_energies_match_numpy(surface):
    s = _tissues(surface, 120, 3, seed=4)
    rng = np.random.default_rng(0)
    assert_gpu_force_matches_numpy(VertexModel.dimensionless(kr=1.0, p0=3.7), s)
    assert_gpu_force_matches_numpy(VertexModel(kA=rng.uniform(0.5, 2, s.n_cells), kP=rng.uniform(0.5, 2, s.n_cells),
                                               A0=1.0, P0=rng.uniform(3.4, 4.0, s.n_cells)), s)
    area, perimeter = shapes.cell_shapes(s.to("gpu"))
    geom = s.constraint.cell_geometry(s)
    assert relative_gap(area, geom.area) <= 1e-12 and relative_gap(perimeter, geom.perimeter) <= 1e-12


def test_fire_with_t1_matches_numpy(surface):
    state = _tissues(surface, 60, 2, seed=5)
    sims = {}
    for device in ("cpu", "gpu"):
        sim = svm.Simulation(device=device)
        sim.state = state
        sim.operations.forces.append(VertexModel.dimensionless(kr=1.0, p0=3.8))
        sim.operations.updaters.append(T1())
        sim.operations.integrator = FIRE(dt=0.02)
        sim.run(200)
        sims[device] = sim
    c, g = sims["cpu"], sims["gpu"]
    assert np.array_equal(g.log("t1_total_flips"), c.log("t1_total_flips"))
    assert np.array_equal(_table(g.state), _table(c.state))
    assert _gap(g.state, c.state) <= 1e-9
    assert relative_gap(g.log("energy"), c.log("energy")) <= 1e-9


@pytest.mark.parametrize("untangle", [False, True])
def test_t1_passes_match_numpy_flip_for_flip(surface, untangle):
    """Random kicks, then a T1 pass, many times: the same flips, refusals, tables and positions."""
    rng = np.random.default_rng(3)
    state = _tissues(surface, 100, 2, seed=15)
    sims = t1_simulations(state, threshold=0.3, new_length=0.45, max_flip_backs=10 ** 6, untangle=untangle)
    for _ in range(30):
        assert_t1_round_matches_numpy(sims, rng.normal(scale=0.04, size=state.positions.shape), _gap)
    assert int(sims["cpu"].log("t1_total_flips").sum()) > 50


def test_brownian_with_t1_matches_numpy_for_1000_steps(surface):
    assert_brownian_with_t1_matches_numpy(_tissues(surface, 64, 2, seed=12), _gap)


@pytest.mark.parametrize("directors", ["cell", "vertex"])
def test_active_matches_numpy(surface, directors):
    state = _tissues(surface, 60, 2, seed=13)
    make = lambda: Active(dt=0.01, v0=0.1, Dr=1.0, T=1e-4, directors=directors)  # noqa: E731
    cpu, gpu = dynamics_simulation(state, "cpu", make()), dynamics_simulation(state, "gpu", make())
    cpu.run(300)
    gpu.run(300)
    assert _gap(gpu.state, cpu.state) <= 1e-9
    assert np.abs(gpu.operations.integrator.directors.get() - cpu.operations.integrator.directors).max() <= 1e-9


def test_narrowed_minimisation_matches_numpy(surface):
    """Minimisations that converge end in the same minima (80 cells: 40- and 60-cell tori do not
    converge in 4,000 iterations, 723 T1s on the 60-cell ones, and runs that do not settle part on
    rounding)."""
    def run(device, narrow):
        sim = svm.Simulation(device=device)
        sim.state = _tissues(surface, 80, 4, seed=21)
        sim.operations.forces.append(VertexModel.dimensionless(kr=1.0, p0=3.75))
        sim.operations.updaters.append(T1())
        sim.operations.integrator = FIRE(dt=0.02)
        return sim, sim.minimize(force_tol=1e-10, max_steps=4000, narrow=narrow)
    (g, rg), (c, rc) = run("gpu", True), run("cpu", True)
    assert rc.converged.all()
    assert np.array_equal(rg.converged, rc.converged) and np.array_equal(rg.reason, rc.reason)
    assert np.allclose(rg.energy_per_cell, rc.energy_per_cell, rtol=1e-6, atol=1e-12)
    assert np.array_equal(g.log("t1_total_flips"), c.log("t1_total_flips"))


def test_bending_matches_numpy(surface):
    """Bending alone (per-replica B) and with the vertex model in Brownian dynamics with T1: its
    normals from the flat facets' vector areas, dE/da added to the vertex model's coefficients."""
    state = _tissues(surface, 100, 2, seed=6)
    assert_gpu_force_matches_numpy(Bending(np.array([0.5, 2.0])), state)
    sims = {}
    for device in ("cpu", "gpu"):
        sims[device] = dynamics_simulation(state, device, Brownian(dt=0.01, T=2e-3))
        sims[device].operations.forces.append(Bending(0.5))
        sims[device].run(300)
    c, g = sims["cpu"], sims["gpu"]
    assert np.array_equal(g.log("t1_total_flips"), c.log("t1_total_flips"))
    assert _gap(g.state, c.state) <= 1e-9
    assert relative_gap(g.log("energy"), c.log("energy")) <= 1e-9


# ------------------------------------------------------------------ the fused small-tissue steps
def _ensemble(surface, sizes):
    return svm.State.concatenate([svm.init.random_tiling(n, seed=3 + i, surface=surface) for i, n in enumerate(sizes)])


def test_fused_steps_are_the_general_kernels_trajectory(surface):
    """Brownian + T1 on tissues of mixed sizes, fused (the vertex model's stage with 4 coefficients
    a cell), in CUDA graphs and step by step: the same State bitwise (no contracted multiply-adds in
    an implicit surface's modules: its functions round as written wherever they are inlined)."""
    from test_tissue_steps import assert_same, three_runs
    state = _ensemble(surface, (60, 150))
    assert tissue_steps.why_not(dynamics_simulation(state, "gpu", Brownian(dt=0.01, T=0.05))) is None
    runs = three_runs(state, 300, T=0.05, check_every=100)
    assert_same(runs)
    assert runs[-1][2][0].sum() > 0, "T1 flipped"


@pytest.mark.parametrize("directors", ["cell", "vertex"])
def test_fused_active_dynamics_are_the_general_kernels_trajectory(surface, directors):
    from test_tissue_steps import assert_same, three_runs
    active = lambda: Active(dt=0.01, v0=0.3, Dr=0.5, T=0.02, directors=directors)   # noqa: E731
    assert_same(three_runs(_ensemble(surface, (60, 100)), 150, integrator=active, check_every=64))


def test_fused_minimisation_is_the_general_one(surface):
    from conftest import assert_same_minimizations, minimizations, sweep_like
    from test_tissue_steps import MINIMIZE_WAYS
    sizes = (60, 150, 80)
    p0 = np.linspace(3.7, 3.9, len(sizes))
    assert tissue_steps.why_not(sweep_like(_ensemble(surface, sizes), p0), minimizing=True) is None
    *others, step = minimizations(_ensemble(surface, sizes), p0, MINIMIZE_WAYS,
                                  calls=({"max_steps": 2000, "check_every": 90},))
    for other in others:
        assert_same_minimizations(other, step)


def test_division_grows_the_same_tissue_on_both_devices(surface):
    """Division (its draws on the device, its surgery on the host) with Brownian dynamics and T1."""
    state = _tissues(surface, 80, 1, seed=7)
    sims = {}
    for device in ("cpu", "gpu"):
        sims[device] = dynamics_simulation(state, device, Brownian(dt=1e-3, T=1e-3))
        sims[device].operations.updaters.insert(0, svm.plugins.updaters.Division(rule="rate", rate=5.0, dt=1e-3))
        sims[device].run(20)
    c, g = sims["cpu"].state, sims["gpu"].state
    assert c.n_cells > 84 and g.n_cells == c.n_cells
    assert np.array_equal(_table(g), _table(c))
    assert _gap(g, c) <= 1e-9
    g.validate()


def test_extrusion_removes_the_same_cells_on_both_devices(surface):
    """Extrusion (T2 of the triangles its rule picks; surgery on the host) in Brownian dynamics with
    T1: the same network and positions on both devices, a valid tiling of the surface (crossed cells
    aside: random tilings under T1 make a few without extrusion too, docs/validation.md)."""
    seed = next(k for k in range(1, 40) if (_tissues(surface, 80, 2, seed=k).cell_sides == 3).any())
    state = _tissues(surface, 80, 2, seed=seed)
    triangles = np.flatnonzero(state.cell_sides == 3)[:2].tolist()
    sims = {}
    for device in ("cpu", "gpu"):
        sims[device] = dynamics_simulation(state, device, Brownian(dt=1e-3, T=1e-3))
        once = iter([triangles])
        sims[device].operations.updaters.insert(
            0, svm.plugins.updaters.Extrusion(rule=lambda sim, once=once: next(once, [])))
        sims[device].run(20)
    c, g = sims["cpu"].state, sims["gpu"].state
    assert c.n_cells == g.n_cells == state.n_cells - len(triangles)
    assert np.array_equal(_table(g), _table(c))
    assert _gap(g, c) <= 1e-9
    g.validate(simple=False)
