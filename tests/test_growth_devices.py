"""Growth on both devices (issue 16): capacity of the State's arrays, growth sitting minimisations
out, Active directors following divisions, and the GPU path against the NumPy one (same divisions
from the same Philox draws, positions to rounding). The GPU tests skip without CuPy and a GPU."""
import numpy as np
import pytest

from conftest import to_numpy
from test_growth import check_tissue
from test_narrowing import counting_narrowings

import spherevm as svm
from spherevm import random as rng
from spherevm.device import CPU
from spherevm.plugins.forces import VertexModel
from spherevm.plugins.integrators import FIRE, Active, Brownian
from spherevm.plugins.updaters import T1, Division, Extrusion, RadiusSchedule
from spherevm.plugins.writers import GSD


# ------------------------------------------------------------------ capacity
def test_fit_refills_in_place_and_grows_geometrically():
    a = np.arange(12.0).reshape(4, 3)
    buf, view = CPU.fit(None, a, np.float64)
    assert buf.shape == (4, 3) and np.array_equal(view, a)          # first time: exactly the rows
    small = -np.ones((2, 3))
    buf2, view = CPU.fit(buf, small, np.float64)
    assert buf2 is buf and np.shares_memory(view, buf) and np.array_equal(view, small)
    big = np.ones((5, 3))
    buf3, view = CPU.fit(buf, big, np.float64)
    assert buf3 is not buf and buf3.shape == (8, 3) and np.array_equal(view, big)
    huge = np.ones((20, 3))
    assert CPU.fit(buf3, huge, np.float64)[0].shape == (20, 3)      # at least the rows needed
    assert CPU.fit(buf3, np.ones((3, 4)), np.float64)[0].shape == (3, 4)   # another row shape: new, the rows needed
    # a table whose width changes at every refill (cells gaining sides) must not double each time
    buf = None
    for width in range(3, 40):
        buf, _ = CPU.fit(buf, np.ones((100, width)), np.int32)
        assert buf.shape == (100, width)
    assert CPU.fit(buf3, np.ones((3, 3), np.int32), np.int32)[0].dtype == np.int32
    assert view.flags.c_contiguous


def _rate_sim(device="cpu", n=24, replicas=2, rate=0.08, integrator=None, seed=5, extrusion=False, t1=True):
    sim = svm.Simulation(device=device, seed=seed)
    sim.state = svm.init.random_tiling(n, replicas=replicas, seed=2)
    nc = sim.state.n_cells
    vm = VertexModel(kA=np.linspace(1.0, 2.0, nc), kP=1.0, A0=np.linspace(0.9, 1.1, nc), P0=3.8)
    sim.operations.forces.append(vm)
    if t1:
        sim.operations.updaters.append(T1())
    div = Division(rule="rate", rate=rate, axis="hertwig", dt=1.0)
    sim.operations.updaters.append(div)
    if extrusion:
        sim.operations.updaters.append(Extrusion(area_threshold=0.35))
    sim.operations.updaters.append(RadiusSchedule("constant_area", area=1.0))
    sim.operations.integrator = integrator if integrator is not None else FIRE(dt=0.05)
    return sim, vm, div


def _buffer_id(state, name):
    buf = state._buffers[name]
    return id(buf) if isinstance(buf, np.ndarray) else buf.data.ptr


@pytest.mark.parametrize("device", ["cpu", pytest.param("gpu", marks=pytest.mark.gpu)])
def test_a_growing_state_reallocates_logarithmically_often(device):
    sim, vm, div = _rate_sim(device, rate=0.03)
    buffers, resizes, n_before, v0 = set(), 0, sim.state.n_cells, sim.state.n_vertices
    for _ in range(60):
        sim.run(1)
        if sim.state.n_cells != n_before:
            resizes += 1
            n_before = sim.state.n_cells
            buffers.add(_buffer_id(sim.state, "positions"))
            assert sim.state.positions.flags.c_contiguous and sim.state.cell_vertices.flags.c_contiguous
    growth = sim.state.n_vertices / v0      # the first resize allocates exactly, then capacity doubles
    assert growth > 2.5 and resizes >= 20
    assert len(buffers) <= np.ceil(np.log2(growth)) + 1, (len(buffers), resizes)
    check_tissue(sim.state.to("cpu"), orientation=False)
    assert len(to_numpy(sim.operations.integrator.velocities)) == sim.state.n_vertices


def test_the_radius_host_copy_follows_assignments():
    state = svm.init.random_tiling(20, replicas=2, seed=1)
    r = state.radius_np()
    r[0] = 99.0                                     # a copy: the State is not touched
    assert state.radius_np()[0] != 99.0
    state.radius = np.array([2.0, 3.0])
    assert state.radius_np().tolist() == [2.0, 3.0]
    np.testing.assert_allclose(state.mean_cell_area, 4 * np.pi * np.array([4.0, 9.0]) / 20)


def test_constant_area_touches_nothing_until_n_changes():
    """No rescale by a rounding of R at every step (that would also drop every cache)."""
    sim, vm, div = _rate_sim(rate=0.0)
    sched = sim.operations.updaters[-1]
    sched.update(sim, 0)
    r, x = sim.state.radius, sim.state.positions
    for t in range(1, 4):
        sched.update(sim, t)
    assert sim.state.radius is r and sim.state.positions is x
    svm.growth.divide(sim.state, [0], [[0.0, 0.0, 1.0]])
    sched.update(sim, 4)
    assert sim.state.radius is not r
    np.testing.assert_allclose(sim.state.mean_cell_area, 1.0, rtol=1e-14)


# ------------------------------------------------------------------ growth sits minimisations out
def test_minimize_holds_growth_back_and_the_next_run_goes_on():
    sim, vm, div = _rate_sim(rate=0.5, extrusion=True)
    sim.operations.updaters.append(RadiusSchedule(lambda s: 2.0 + 0.001 * s.timestep))
    sim.run(1)
    grown = sim.state.n_cells
    assert grown > 48
    radius = sim.state.radius_np()
    res = sim.minimize(max_steps=300)
    t = sim.timestep
    assert t > 100 and sim.state.n_cells == grown and len(vm.kA) == grown      # no division, no T2
    np.testing.assert_array_equal(sim.state.radius_np(), radius)               # nor a new radius
    assert sim.checkpoint()["simulation/held_back"].tolist() == [1]
    assert res.reason.shape == (2,)
    expected = rng.uniform(sim.seed, rng.STREAM_DIVISION, t, np.arange(grown), 1)[:, 0] < -np.expm1(-0.5)
    refused = div.refusals.sum()
    sim.operations.integrator.reset()
    sim.run(1)                     # the held-back updaters run at t, with one step of time elapsed
    assert div.last_divisions.sum() + div.refusals.sum() - refused == expected.sum() > 0
    np.testing.assert_allclose(sim.state.radius_np(), 2.0 + 0.001 * t)
    assert sim.checkpoint()["simulation/held_back"].tolist() == [0]


def test_a_restart_from_the_end_of_a_minimisation_runs_the_held_back_growth(tmp_path):
    """The checkpoint says the last update pass was a minimisation's: the restarted run divides
    at that timestep, as the uninterrupted one does (bitwise on the CPU)."""
    pytest.importorskip("gsd")
    path = tmp_path / "q.gsd"
    a, _, div_a = _rate_sim(rate=0.3)
    a.run(2)
    a.operations.writers.append(GSD(trigger=10 ** 6, filename=path))     # the final frames only
    a.minimize(max_steps=60)
    a.operations.writers[0].close()
    b, _, div_b = _rate_sim(rate=0.3)           # per-cell parameters of the tissue before it grew
    b.create_state_from_gsd(path)
    assert b.timestep == a.timestep and b.state.n_cells == a.state.n_cells
    for sim in (a, b):
        sim.run(1)
    assert div_a.last_divisions.sum() > 0
    np.testing.assert_array_equal(div_b.last_divisions, div_a.last_divisions)
    assert b.state.positions.tobytes() == a.state.positions.tobytes()
    np.testing.assert_array_equal(b.state.cell_vertices, a.state.cell_vertices)


# ------------------------------------------------------------------ Active directors follow divisions
def _basis(normal):
    """The tangent basis Active documents: e1 = n x (x, or y near the x axis), e2 = n x e1."""
    ref = np.where(np.abs(normal[:, [0]]) < 0.9, [[1.0, 0, 0]], [[0, 1.0, 0]])
    e1 = np.cross(normal, ref)
    e1 /= np.linalg.norm(e1, axis=1)[:, None]
    return e1, np.cross(normal, e1)


def _active_sim(mode, device="cpu"):
    sim = svm.Simulation(device=device, seed=9)
    sim.state = svm.init.random_tiling(30, replicas=2, seed=4)
    sim.operations.forces.append(VertexModel.dimensionless(kr=1.0, p0=3.8))
    div = Division(rule=lambda s: [3, 40, 41], axis="random", trigger=svm.trigger.Periodic(10 ** 6, phase=10 ** 6))
    sim.operations.updaters.append(div)
    sim.operations.integrator = Active(dt=0.01, v0=0.1, Dr=0.5, directors=mode)
    return sim, div


@pytest.mark.parametrize("mode", ["cell", "vertex"])
def test_active_directors_follow_divisions(mode):
    """Mothers (and every old vertex) keep their directors bitwise; each daughter (created vertex)
    gets the documented Philox angle in the tangent plane at her centre (at the vertex)."""
    sim, div = _active_sim(mode)
    act = sim.operations.integrator
    sim.run(4)
    before = np.array(act.directors)
    seen = []
    follow = act.resized
    act.resized = lambda change: (seen.append(change), follow(change))
    t = sim.timestep
    div.update(sim, t)
    change, d, state = seen[0], np.asarray(act.directors), sim.state
    assert div.total_divisions.sum() == 3
    if mode == "cell":
        old, born = ~change.new_cells, np.flatnonzero(change.new_cells)
        assert len(d) == state.n_cells
        np.testing.assert_array_equal(d[old], before[change.cell_source[old]])
        angle = rng.TWO_PI * rng.uniform(sim.seed, rng.STREAM_DIVISION, t, change.cell_source[born], 3)[:, 2]
        normal = state.constraint.cell_centers(state)[born]
    else:
        old, born = change.vertex_source >= 0, np.flatnonzero(change.vertex_source < 0)
        assert len(d) == state.n_vertices and len(born) == 6
        np.testing.assert_array_equal(d[old], before[change.vertex_source[old]])
        angle = rng.TWO_PI * rng.uniform(sim.seed, rng.STREAM_VERTEX_BIRTH, t, born, 1)[:, 0]
        normal = state.positions[born] / np.linalg.norm(state.positions[born], axis=1)[:, None]
    e1, e2 = _basis(normal)
    np.testing.assert_allclose(d[born], np.cos(angle)[:, None] * e1 + np.sin(angle)[:, None] * e2, atol=1e-14)
    assert len(set(np.round(angle, 12))) == len(born)          # independent draws, not one shared angle


def test_active_with_division_and_extrusion_runs_and_keeps_unit_tangent_directors():
    sim = svm.Simulation(device="cpu", seed=3)
    sim.state = svm.init.random_tiling(24, replicas=2, seed=8)
    sim.operations.forces.append(VertexModel.dimensionless(kr=1.0, p0=3.7))
    sim.operations.updaters += [T1(), Division(rule="rate", rate=0.5, dt=1.0, trigger=10, max_cells=60),
                                Extrusion(area_threshold=0.4, trigger=10), RadiusSchedule("constant_area")]
    sim.operations.integrator = Active(dt=0.01, v0=0.2, Dr=1.0, T=1e-4)
    sim.run(300)
    d = sim.operations.integrator.directors
    n = sim.state.constraint.cell_centers(sim.state)
    assert sim.state.n_cells > 60 and len(d) == sim.state.n_cells
    np.testing.assert_allclose(np.linalg.norm(d, axis=1), 1.0, atol=1e-12)
    assert np.abs((d * n).sum(axis=1)).max() < 0.05          # tangent at the last step's centroid
    check_tissue(sim.state, orientation=False)


# ------------------------------------------------------------------ the GPU against NumPy
def _table(state):
    cv = to_numpy(state.cell_vertices)
    return cv[:, :int(to_numpy(state.cell_sides).max())]


@pytest.mark.gpu
def test_the_rate_rules_device_draws_are_the_host_draws():
    cpu, _, div_c = _rate_sim("cpu", n=200, replicas=3)
    gpu, _, div_g = _rate_sim("gpu", n=200, replicas=3)
    for t in (0, 1, 17, 2**32 + 5):
        for p in (1e-3, 0.05, 0.5):
            a = div_c._rate_cells_cpu(cpu, t, p)
            b = div_g._rate_cells_gpu(gpu, t, p)
            assert len(a) > 0 or p < 0.01
            np.testing.assert_array_equal(b, a)


@pytest.mark.gpu
@pytest.mark.parametrize("integrator", ["fire", "brownian"])
def test_growth_on_the_gpu_follows_the_cpu(integrator):
    """Division (rate rule, Hertwig), T2, T1, the radius schedule and per-cell parameters: the same
    divisions, extrusions and flips at every step, the same tables, positions to rounding."""
    make = (lambda: FIRE(dt=0.05)) if integrator == "fire" else (lambda: Brownian(dt=0.01, T=1e-3))
    cpu, vm_c, div_c = _rate_sim("cpu", n=40, replicas=3, rate=0.01, integrator=make(), extrusion=True)
    gpu, vm_g, div_g = _rate_sim("gpu", n=40, replicas=3, rate=0.01, integrator=make(), extrusion=True)
    for _ in range(12):
        cpu.run(5)
        gpu.run(5)
        assert np.array_equal(gpu.state.cell_start, cpu.state.cell_start)
        np.testing.assert_array_equal(div_g.total_divisions, div_c.total_divisions)
        np.testing.assert_array_equal(gpu.log("extrusion_total"), cpu.log("extrusion_total"))
        np.testing.assert_array_equal(gpu.log("t1_total_flips"), cpu.log("t1_total_flips"))
        np.testing.assert_array_equal(_table(gpu.state), _table(cpu.state))
        assert np.abs(gpu.state.positions.get() - cpu.state.positions).max() <= 1e-9
    assert div_c.total_divisions.sum() > 20
    np.testing.assert_array_equal(vm_g.kA, vm_c.kA)
    np.testing.assert_array_equal(div_g.lineage, div_c.lineage)
    np.testing.assert_allclose(gpu.state.radius_np(), cpu.state.radius_np(), rtol=1e-15)
    check_tissue(gpu.state.to("cpu"), orientation=False)


@pytest.mark.gpu
@pytest.mark.parametrize("mode", ["cell", "vertex"])
def test_active_directors_follow_divisions_on_the_gpu(mode):
    sims = {dev: _active_sim(mode, dev) for dev in ("cpu", "gpu")}
    for dev, (sim, div) in sims.items():
        sim.run(20)
        div.update(sim, sim.timestep)
        sim.run(50)
    (c, _), (g, _) = sims["cpu"], sims["gpu"]
    assert g.state.n_cells == c.state.n_cells == 63
    np.testing.assert_array_equal(_table(g.state), _table(c.state))
    assert np.abs(g.operations.integrator.directors.get() - c.operations.integrator.directors).max() <= 1e-9
    assert np.abs(g.state.positions.get() - c.state.positions).max() <= 1e-9


def _grown_and_quenched(device, narrow, monkeypatch=None):
    sim, vm, div = _rate_sim(device, n=32, replicas=6, rate=0.02, extrusion=True)
    sim.run(30)
    n, lineage, totals = sim.state.n_cells, div.lineage.copy(), div.total_divisions.copy()
    calls = counting_narrowings(monkeypatch) if monkeypatch is not None else None
    res = sim.minimize(force_tol=1e-6, max_steps=5000, narrow=narrow)
    assert sim.state.n_cells == n and sim.state.n_replicas == 6
    np.testing.assert_array_equal(div.lineage, lineage)           # widened back, row for row
    np.testing.assert_array_equal(div.total_divisions, totals)
    return res, sim, calls


def test_a_quench_with_growth_attached_narrows_and_widens_back(monkeypatch):
    """Growth updaters are held back, so minimize may narrow: their per-cell and per-replica rows
    follow, and the result is bitwise the unnarrowed one."""
    res, sim, calls = _grown_and_quenched("cpu", narrow=True, monkeypatch=monkeypatch)
    ref, ref_sim, _ = _grown_and_quenched("cpu", narrow=False)
    assert len(calls) >= 1
    assert np.array_equal(res.reason, ref.reason)
    assert sim.state.positions.tobytes() == ref_sim.state.positions.tobytes()


@pytest.mark.gpu
def test_a_quench_of_a_grown_tissue_on_the_gpu_reaches_what_the_cpu_reaches():
    (rc, c, _), (rg, g, _) = _grown_and_quenched("cpu", True), _grown_and_quenched("gpu", True)
    assert np.array_equal(rg.reason, rc.reason)
    assert np.allclose(rg.energy_per_cell, rc.energy_per_cell, rtol=1e-6, atol=1e-12)
    np.testing.assert_array_equal(g.log("division_total"), c.log("division_total"))
