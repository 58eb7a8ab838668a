"""GPU path (CuPy RawKernels) against the NumPy reference. Skipped without CuPy and a GPU.

These are the CPU-vs-GPU agreement tests; the behavioural tests (forces, FIRE, T1, narrowing,
Brownian/Active, GSD, ...) run on the GPU too, through the ``device`` fixture of conftest.py."""
import numpy as np
import pytest
from conftest import (assert_gpu_force_matches_numpy, dynamics_simulation, kick_on_surface, relative_gap,
                      t1_simulations)

import spherevm as svm
from spherevm.constraints.plane import minimum_image
from spherevm.plugins.forces import VertexModel
from spherevm.plugins.integrators import FIRE, Active, Brownian
from spherevm.plugins.updaters import T1

pytestmark = pytest.mark.gpu


@pytest.mark.parametrize("n_cells, replicas", [(200, 1), (64, 16), (1000, 3)])
@pytest.mark.parametrize("model", [VertexModel.dimensionless(kr=1.0, p0=3.7),
                                   VertexModel.dimensionless(kr=0.0, p0=3.9),
                                   VertexModel(kA=0.3, kP=1.7, A0=1.1, P0=3.4)])
def test_forces_and_energies_match_numpy(n_cells, replicas, model):
    assert_gpu_force_matches_numpy(model, svm.init.random_tiling(n_cells, replicas=replicas, seed=n_cells))


def test_per_cell_parameters_on_gpu():
    cpu = svm.init.random_tiling(300, seed=2)
    rng = np.random.default_rng(0)
    model = VertexModel(kA=rng.uniform(0, 2, 300), kP=1.0, A0=rng.uniform(0.5, 1.5, 300), P0=3.8)
    assert relative_gap(model.forces(cpu.to("gpu")), model.forces(cpu)) <= 1e-12


def _fire_sim(state, device, t1=False, p0=3.7):
    sim = svm.Simulation(device=device)
    sim.state = state
    sim.operations.forces.append(VertexModel.dimensionless(kr=1.0, p0=p0))
    if t1:
        sim.operations.updaters.append(T1())
    sim.operations.integrator = FIRE(dt=0.02)
    return sim


def test_fire_steps_match_numpy():
    # with T1s on, no edge collapses: without them the direction of a vanishing edge amplifies
    # round-off (4.8e-8 after 200 steps at p0 = 4.6 was seen on an H200)
    state = svm.init.random_tiling(128, replicas=4, seed=5)
    cpu, gpu = _fire_sim(state, "cpu", t1=True, p0=3.8), _fire_sim(state, "gpu", t1=True, p0=3.8)
    cpu.run(200)
    gpu.run(200)
    assert np.array_equal(gpu.log("t1_total_flips"), cpu.log("t1_total_flips"))
    assert np.abs(gpu.state.positions.get() - cpu.state.positions).max() <= 1e-9
    assert relative_gap(gpu.log("energy"), cpu.log("energy")) <= 1e-9
    assert np.allclose(gpu.log("fire_dt"), cpu.log("fire_dt"), rtol=1e-12)


def test_minimize_with_t1_reaches_the_same_energies():
    state = svm.init.random_tiling(64, replicas=8, seed=6)
    cpu, gpu = _fire_sim(state, "cpu", t1=True), _fire_sim(state, "gpu", t1=True)
    rc = cpu.minimize(force_tol=1e-10, max_steps=20000)
    rg = gpu.minimize(force_tol=1e-10, max_steps=20000)
    assert rc.all_converged and rg.all_converged
    assert np.allclose(rg.energy_per_cell, rc.energy_per_cell, rtol=1e-6, atol=1e-12)
    assert np.array_equal(gpu.log("t1_total_flips"), cpu.log("t1_total_flips"))
    gpu.state.validate()


def test_narrowed_minimisation_on_gpu():
    """Narrowing on the GPU (State.select / write_back, FIRE and T1 device buffers) gives what the
    full GPU run and the CPU give."""
    from test_narrowing import counting_narrowings, mixed_ensemble
    ref = mixed_ensemble("gpu")
    r_full = ref.minimize(force_tol=1e-12, max_steps=3000, narrow=False)
    sim = mixed_ensemble("gpu")
    mp = pytest.MonkeyPatch()
    try:
        calls = counting_narrowings(mp)
        res = sim.minimize(force_tol=1e-12, max_steps=3000)
    finally:
        mp.undo()
    cpu = mixed_ensemble("cpu")
    r_cpu = cpu.minimize(force_tol=1e-12, max_steps=3000)
    assert len(calls) >= 2
    for other in (r_full, r_cpu):
        assert np.array_equal(res.converged, other.converged)
        assert np.array_equal(res.reason, other.reason)
        assert np.allclose(res.energy_per_cell, other.energy_per_cell, rtol=1e-6, atol=1e-12)
    assert np.array_equal(sim.log("t1_total_flips"), cpu.log("t1_total_flips"))
    assert np.array_equal(sim.log("t1_total_flips"), ref.log("t1_total_flips"))
    sim.state.validate(orientation=False)
    assert sim.state.n_replicas == 8


def test_state_round_trip_between_devices():
    cpu = svm.init.random_tiling(100, replicas=2, seed=7)
    back = cpu.to("gpu").to("cpu")
    assert np.array_equal(back.positions, cpu.positions)
    assert np.array_equal(back.cell_vertices, cpu.cell_vertices)


def _table(state):
    """The cell table trimmed to the widest cell (the GPU may keep a spare column)."""
    cv = state.device.to_numpy(state.cell_vertices)
    return cv[:, :int(state.device.to_numpy(state.cell_sides).max())]


@pytest.mark.parametrize("rules, radius", [(dict(threshold=0.3, new_length=0.45), None),
                                           (dict(preset="reference"), 7.0)])
def test_t1_passes_match_numpy_flip_for_flip(rules, radius):
    # random kicks then a T1 pass, many times: the GPU kernels must pick and perform the same flips,
    # with an absolute new length and with the reference preset's factor, at <A> = 1 and <A> != 1
    rng = np.random.default_rng(3)
    state = svm.init.random_tiling(300, replicas=3, seed=15, radius=radius)
    scale = float(np.sqrt(state.mean_cell_area[0]))
    sims = t1_simulations(state, max_flip_backs=10 ** 6, **rules)
    refused = 0
    for _ in range(40):
        kick = rng.normal(scale=0.06 * scale, size=state.positions.shape)
        version = sims["gpu"].state.topology_version
        for sim in sims.values():
            kick_on_surface(sim, kick)
            sim.run_updaters()
        c, g = sims["cpu"], sims["gpu"]
        if c.log("t1_flips").sum():
            assert g.state.topology_version > version, "a pass that flips makes topology caches stale"
        assert np.array_equal(g.log("t1_flips"), c.log("t1_flips"))
        assert np.array_equal(g.log("t1_refused"), c.log("t1_refused"))
        refused += int(c.log("t1_refused").sum())
        assert np.array_equal(_table(g.state), _table(c.state))
        assert np.array_equal(g.state.vertex_cells.get(), c.state.vertex_cells)
        assert np.abs(g.state.positions.get() - c.state.positions).max() <= 1e-12
    assert int(sims["cpu"].log("t1_total_flips").sum()) > 200
    g = sims["gpu"].state
    g.validate(orientation=False)
    assert np.array_equal(sims["gpu"].log("t1_flip_backs"), sims["cpu"].log("t1_flip_backs"))


@pytest.mark.parametrize("graphs", [True, False])
def test_brownian_with_t1_matches_numpy_for_1000_steps(graphs):
    state = svm.init.random_tiling(128, replicas=2, seed=12)
    cpu = dynamics_simulation(state, "cpu", Brownian(dt=0.01, T=2e-3))
    gpu = dynamics_simulation(state, "gpu", Brownian(dt=0.01, T=2e-3))
    cpu.run(1000)
    gpu.run(1000, graphs=graphs)
    assert int(gpu.operations.updaters[0]._gpu["log_count"].get()[0]) == 0, "no flip log under dynamics"
    flips = cpu.log("t1_total_flips")
    assert flips.sum() > 0 and np.array_equal(gpu.log("t1_total_flips"), flips)
    assert np.array_equal(_table(gpu.state), _table(cpu.state))
    assert np.array_equal(gpu.state.vertex_neighbors.get(), cpu.state.vertex_neighbors)
    assert np.abs(gpu.state.positions.get() - cpu.state.positions).max() <= 1e-9


@pytest.mark.parametrize("surface", ["sphere", "plane"])
def test_untangling_matches_numpy_flip_for_flip(surface):
    """T1(untangle=True): kicks that cross edges, then a pass (short and crossed edges) and
    untangle_pass (crossed edges alone), many times: the GPU (t1_detect's bow-tie test) makes
    NumPy's flips and refusals, tables and positions."""
    from spherevm import folding
    rng = np.random.default_rng(4)
    make = svm.init.random_tiling if surface == "sphere" else svm.init.random_planar_tiling
    state = make(300, replicas=3, seed=16)
    sims = t1_simulations(state, untangle=True, max_flip_backs=10 ** 6)
    crossed = untangled = 0
    for _ in range(30):
        kick = rng.normal(scale=0.04, size=state.positions.shape)
        for sim in sims.values():
            kick_on_surface(sim, kick)
        crossed += len(folding.inverted_edges(sims["cpu"].state)[0])
        made = {dev: (sim.run_updaters(), sim.operations.updaters[0].untangle_pass(sim))[1]
                for dev, sim in sims.items()}
        c, g = sims["cpu"], sims["gpu"]
        assert made["gpu"] == made["cpu"]
        untangled += made["cpu"]
        assert np.array_equal(g.log("t1_flips"), c.log("t1_flips"))       # the pass's and untangle_pass's
        assert np.array_equal(g.log("t1_refused"), c.log("t1_refused"))
        assert np.array_equal(_table(g.state), _table(c.state))
        assert np.array_equal(g.state.vertex_cells.get(), c.state.vertex_cells)
        gap = g.state.positions.get() - c.state.positions
        if surface == "plane":      # a vertex within round-off of the boundary may be on either side
            gap = minimum_image(gap[:, :2], c.state.box_np()[c.state.vertex_replica_np()])
        assert np.abs(gap).max() <= 1e-12
    assert crossed > 100 and untangled > 10
    assert np.array_equal(sims["gpu"].log("t1_total_flips"), sims["cpu"].log("t1_total_flips"))


@pytest.mark.parametrize("executor", [dict(graphs=False, fused=False), dict(graphs=True, fused=False),
                                      dict(fused=True)])
def test_hot_brownian_with_untangling_matches_numpy(executor):
    """Hot Brownian dynamics with T1(untangle=True): the step-by-step pass, the CUDA graphs and the
    fused small-tissue steps (t1_stage.cuh) flip what NumPy flips, and leave no crossed edge that
    an untangle_pass would flip."""
    state = svm.init.random_tiling(64, replicas=2, seed=12)
    sims = {dev: dynamics_simulation(state, dev, Brownian(dt=0.02, T=0.05)) for dev in ("cpu", "gpu")}
    for sim in sims.values():
        sim.operations.updaters[0].untangle = True
    sims["cpu"].run(200)
    sims["gpu"].run(200, **executor)
    cpu, gpu = sims["cpu"], sims["gpu"]
    flips = cpu.log("t1_total_flips")
    assert flips.sum() > 50 and np.array_equal(gpu.log("t1_total_flips"), flips)
    assert np.array_equal(_table(gpu.state), _table(cpu.state))
    assert np.abs(gpu.state.positions.get() - cpu.state.positions).max() <= 1e-9


@pytest.mark.parametrize("directors", ["cell", "vertex"])
def test_active_matches_numpy(directors):
    state = svm.init.random_tiling(100, replicas=2, seed=13)
    make = lambda: Active(dt=0.01, v0=0.1, Dr=1.0, T=1e-4, directors=directors)  # noqa: E731
    cpu, gpu = dynamics_simulation(state, "cpu", make()), dynamics_simulation(state, "gpu", make())
    cpu.run(300)
    gpu.run(300)
    assert np.abs(gpu.state.positions.get() - cpu.state.positions).max() <= 1e-9
    assert np.abs(gpu.operations.integrator.directors.get() - cpu.operations.integrator.directors).max() <= 1e-9


def test_gsd_written_on_gpu_restores_on_cpu(tmp_path):
    sim = dynamics_simulation(svm.init.random_tiling(64, replicas=2, seed=14), "gpu", Brownian(dt=0.01, T=1e-3))
    sim.operations.writers.append(svm.plugins.writers.GSD(50, tmp_path / "g.gsd"))
    sim.run(200)
    back = svm.init.from_gsd(tmp_path / "g.gsd", device="cpu")
    assert np.array_equal(back.positions, sim.state.positions.get())
    assert np.array_equal(back.cell_vertices, sim.state.cell_vertices.get())


@pytest.mark.parametrize("read_half_way", [True, False])
def test_flip_back_memory_matches_numpy_across_passes(read_half_way):
    """Many passes between two reads: the GPU's flip log, replayed pass by pass, gives NumPy's
    separated pairs and re-join counts exactly. Without the read half-way more flips are logged
    than the log has rows, so a pass must replay it before it could overflow."""
    rng = np.random.default_rng(5)
    state = svm.init.random_tiling(300, replicas=2, seed=16)
    sims = t1_simulations(state, threshold=0.3, new_length=0.45, max_flip_backs=10 ** 6)
    c, g = (sims[d].operations.updaters[0] for d in ("cpu", "gpu"))
    for i in range(60):
        kick = rng.normal(scale=0.08, size=state.positions.shape)
        for sim in sims.values():
            kick_on_surface(sim, kick)
            sim.run_updaters()
        if i == 29 and read_half_way:
            g._sync_counters()          # a read half-way: the log starts again from empty
    rows = len(g._gpu["log"])
    g._sync_counters()
    assert np.array_equal(g.total_flips, c.total_flips)
    if not read_half_way:
        assert c.total_flips.sum() > rows, "more flips than the log's rows between two reads"
    assert c._rejoins.sum() > 0, "some pairs were joined again"
    assert np.array_equal(g._separated, c._separated) and np.array_equal(g._rejoins, c._rejoins)
    assert np.array_equal(g.flip_backs, c.flip_backs)


def test_flip_log_is_replayed_before_a_pass_could_write_past_its_end():
    """A log of four rows, the rows after it watched: a pass whose candidates might not fit must
    replay the log (and grow it) first, so no flip is ever written past the log's end, and the
    replayed memory is NumPy's."""
    import cupy as cp
    rng = np.random.default_rng(7)
    state = svm.init.random_tiling(300, replicas=2, seed=16)
    sims = t1_simulations(state, threshold=0.3, new_length=0.45, max_flip_backs=10 ** 6)
    c, g = (sims[d].operations.updaters[0] for d in ("cpu", "gpu"))
    guard = cp.full((64, 6), -7, dtype=cp.int32)
    g._gpu_buffers(sims["gpu"].state)["log"] = guard[:4]
    for i in range(6):
        kick = rng.normal(scale=0.08, size=state.positions.shape)
        for sim in sims.values():
            kick_on_surface(sim, kick)
            sim.run_updaters()
        assert bool((guard[4:] == -7).all()), f"pass {i} wrote past the end of the log"
        if i == 0:
            assert c.total_flips.sum() > 4, "the first pass flips more than the small log holds"
    g._sync_counters()
    assert np.array_equal(g._separated, c._separated) and np.array_equal(g._rejoins, c._rejoins)
