"""The periodic plane on the GPU (the kernels compiled after its device code, PlaneSurface) against
the NumPy path: forces and energies, FIRE with T1, T1 flip for flip across the boundary, Brownian and Active
dynamics with T1 on the same Philox stream, narrowing, GSD, a planar rigidity sweep and the command
line. Skipped without CuPy and a GPU (conftest.py); the plane's device header is checked on the CPU
by tests/test_cuda_headers.py."""
import json

import numpy as np
import pytest
from conftest import (assert_brownian_with_t1_matches_numpy, assert_gpu_force_matches_numpy, assert_t1_round_matches_numpy,
                      dynamics_simulation, relative_gap, t1_simulations)

import spherevm as svm
from spherevm import cli, sweeps
from spherevm.analysis import rigidity
from spherevm.constraints.plane import minimum_image
from spherevm.plugins.forces import VertexModel
from spherevm.plugins.integrators import FIRE, Active, Brownian
from spherevm.plugins.updaters import T1

pytestmark = pytest.mark.gpu


def _gap(gpu_state, cpu_state):
    """Largest distance between the GPU's and the CPU's vertices, by minimum image (a vertex within
    round-off of the boundary may be stored at either side of the box)."""
    box = cpu_state.box_np()[cpu_state.vertex_replica_np()]
    d = minimum_image(gpu_state.positions.get()[:, :2] - cpu_state.positions[:, :2], box)
    assert np.all(gpu_state.positions.get()[:, 2] == 0)
    return np.abs(d).max()


def _table(state):
    cv = state.device.to_numpy(state.cell_vertices)
    return cv[:, :int(state.device.to_numpy(state.cell_sides).max())]


def _boxes(n_cells, replicas, seed):
    """Replicas in boxes of different shapes and sizes (<A> = 1 and 1.5, square and 1:2)."""
    parts = [svm.init.random_planar_tiling(n_cells, seed=seed + r, box=None if r % 2 == 0 else
                                           (np.sqrt(0.75 * n_cells), 2 * np.sqrt(0.75 * n_cells)))
             for r in range(replicas)]
    return svm.State.concatenate(parts)


# ------------------------------------------------------------------------------------ forces
@pytest.mark.parametrize("n_cells, replicas", [(200, 1), (64, 16), (1000, 3)])
@pytest.mark.parametrize("model", [VertexModel.dimensionless(kr=1.0, p0=3.7),
                                   VertexModel.dimensionless(kr=0.0, p0=3.9),
                                   VertexModel(kA=0.3, kP=1.7, A0=1.1, P0=3.4)])
def test_planar_forces_and_energies_match_numpy(n_cells, replicas, model):
    rg = assert_gpu_force_matches_numpy(model, _boxes(n_cells, replicas, seed=n_cells))
    assert np.all(rg.forces.get()[:, 2] == 0)


def test_planar_per_cell_parameters_and_honeycomb_on_gpu():
    cpu = svm.init.random_planar_tiling(300, seed=2)
    rng = np.random.default_rng(0)
    model = VertexModel(kA=rng.uniform(0, 2, 300), kP=1.0, A0=rng.uniform(0.5, 1.5, 300), P0=3.8)
    assert relative_gap(model.forces(cpu.to("gpu")), model.forces(cpu)) <= 1e-12
    hexagons = svm.init.hexagonal_tiling(6, 8).to("gpu")          # analytic: zero force at p0 = sqrt(8 sqrt 3)
    r = VertexModel(kA=1.0, kP=1.0, A0=1.0, P0=np.sqrt(8 * np.sqrt(3))).compute(hexagons)
    assert abs(float(r.energy[0])) < 1e-24 and float(np.abs(r.forces).max()) < 1e-12


# ------------------------------------------------------------------------------------ FIRE and T1
def _fire_sim(state, device, p0=3.8):
    sim = svm.Simulation(device=device)
    sim.state = state
    sim.operations.forces.append(VertexModel.dimensionless(kr=1.0, p0=p0))
    sim.operations.updaters.append(T1())
    sim.operations.integrator = FIRE(dt=0.02)
    return sim


def test_planar_fire_steps_match_numpy():
    state = _boxes(128, 4, seed=5)
    cpu, gpu = _fire_sim(state, "cpu"), _fire_sim(state, "gpu")
    cpu.run(200)
    gpu.run(200)
    assert cpu.log("t1_total_flips").sum() > 0
    assert np.array_equal(gpu.log("t1_total_flips"), cpu.log("t1_total_flips"))
    assert _gap(gpu.state, cpu.state) <= 1e-9
    assert relative_gap(gpu.log("energy"), cpu.log("energy")) <= 1e-9
    assert np.allclose(gpu.log("fire_dt"), cpu.log("fire_dt"), rtol=1e-12)


def test_planar_minimize_with_t1_reaches_the_same_energies():
    state = _boxes(64, 8, seed=6)
    cpu, gpu = _fire_sim(state, "cpu", p0=3.7), _fire_sim(state, "gpu", p0=3.7)
    rc = cpu.minimize(force_tol=1e-10, max_steps=20000)
    rg = gpu.minimize(force_tol=1e-10, max_steps=20000)
    assert rc.all_converged and rg.all_converged
    assert np.allclose(rg.energy_per_cell, rc.energy_per_cell, rtol=1e-6, atol=1e-12)
    assert np.array_equal(gpu.log("t1_total_flips"), cpu.log("t1_total_flips"))
    gpu.state.validate()


def test_planar_t1_passes_match_numpy_flip_for_flip():
    """Random kicks, then a T1 pass, many times: the same flips, tables and positions, with flips
    across the periodic boundary among them."""
    rng = np.random.default_rng(3)
    state = _boxes(300, 3, seed=15)
    sims = t1_simulations(state, threshold=0.3, new_length=0.45, max_flip_backs=10 ** 6)
    across = 0
    for _ in range(40):
        assert_t1_round_matches_numpy(sims, rng.normal(scale=0.06, size=state.positions.shape), _gap)
        cs = sims["cpu"].state
        raw = cs.positions[cs.vertex_neighbors, :2] - cs.positions[:, None, :2]
        across += int((np.abs(raw) > cs.box_np()[cs.vertex_replica][:, None] / 2).any(axis=-1).sum())
    assert int(sims["cpu"].log("t1_total_flips").sum()) > 200 and across > 0
    sims["gpu"].state.validate(orientation=False)
    assert np.array_equal(sims["gpu"].log("t1_flip_backs"), sims["cpu"].log("t1_flip_backs"))


# ------------------------------------------------------------------------------------ dynamics
def test_planar_brownian_with_t1_matches_numpy_for_1000_steps():
    assert_brownian_with_t1_matches_numpy(_boxes(128, 2, seed=12), _gap)


@pytest.mark.parametrize("directors", ["cell", "vertex"])
def test_planar_active_matches_numpy(directors):
    state = _boxes(100, 2, seed=13)
    make = lambda: Active(dt=0.01, v0=0.1, Dr=1.0, T=1e-4, directors=directors)  # noqa: E731
    cpu, gpu = dynamics_simulation(state, "cpu", make()), dynamics_simulation(state, "gpu", make())
    cpu.run(300)
    gpu.run(300)
    assert _gap(gpu.state, cpu.state) <= 1e-9
    dg, dc = gpu.operations.integrator.directors.get(), cpu.operations.integrator.directors
    assert np.abs(dg - dc).max() <= 1e-9 and np.all(dg[:, 2] == 0)


def test_planar_narrowed_minimisation_on_gpu():
    """Narrowing a planar ensemble on the GPU gives what the full GPU run and the CPU give."""
    def run(device, narrow):
        sim = _fire_sim(_boxes(32, 6, seed=21), device, p0=3.75)
        return sim, sim.minimize(force_tol=1e-11, max_steps=5000, narrow=narrow)
    (g, rg), (f, rf), (c, rc) = run("gpu", True), run("gpu", False), run("cpu", True)
    for other in (rf, rc):
        assert np.array_equal(rg.converged, other.converged) and np.array_equal(rg.reason, other.reason)
        assert np.allclose(rg.energy_per_cell, other.energy_per_cell, rtol=1e-6, atol=1e-12)
    assert np.array_equal(g.log("t1_total_flips"), c.log("t1_total_flips"))
    assert np.array_equal(g.state.box_np(), c.state.box_np())


def test_planar_gsd_written_on_gpu_restores_on_cpu(tmp_path):
    pytest.importorskip("gsd")
    sim = dynamics_simulation(_boxes(64, 2, seed=14), "gpu", Brownian(dt=0.01, T=1e-3))
    sim.operations.writers.append(svm.plugins.writers.GSD(50, tmp_path / "g.gsd"))
    sim.run(200)
    back = svm.init.from_gsd(tmp_path / "g.gsd", device="cpu")
    assert np.array_equal(back.positions, sim.state.positions.get())
    assert np.array_equal(back.box_np(), sim.state.box_np())
    assert sim.log("t1_total_flips").sum() > 0
    assert np.array_equal(_table(back), _table(sim.state))      # the GPU may keep a spare column


# ------------------------------------------------------------------------------------ sweeps and CLI
PLANE_SWEEP = dict(cells=[16, 24], p0=[3.6, 3.8, 4.1], replicas=4, seed=2, surface="plane")


def test_planar_sweep_on_gpu_gives_the_cpu_records(tmp_path):
    """The same replicas, outcomes, classification and T1 flips as on the CPU, energies of the rigid
    ones to 1e-6; the FIRE step counts may differ by a check interval or two (round-off moves the
    step at which a tolerance is first met)."""
    sweep = sweeps.RigiditySweep(**PLANE_SWEEP)
    cpu = sweeps.run_sweep(sweep, tmp_path / "cpu", executor=sweeps.InProcessExecutor(), device="cpu")
    gpu = sweeps.run_sweep(sweep, tmp_path / "gpu", device="gpu")
    a, b = cpu.records, gpu.records
    for col in ("n_cells", "p0", "p0_index", "replica", "tiling_seed", "reason", "t1_flips"):
        assert list(b[col]) == list(a[col]), col
    status = rigidity.classify(b["energy_per_cell"], b["reason"])
    assert list(status) == list(rigidity.classify(a["energy_per_cell"], a["reason"]))
    rigid = status == "rigid"
    assert rigid.any() and (~rigid).any()
    assert np.allclose(b["energy_per_cell"][rigid], a["energy_per_cell"][rigid], rtol=1e-6)
    assert np.allclose(b["mean_shape_index"], a["mean_shape_index"], rtol=1e-6)
    assert np.all(np.abs(np.asarray(b["steps"]) - np.asarray(a["steps"])) <= 2 * sweep.check_every)
    assert json.loads((tmp_path / "gpu" / "manifest.json").read_text())["parameters"]["surface"] == "plane"


def test_cli_minimize_on_the_plane_with_gpu_and_auto(tmp_path, capsys):
    """``--device gpu`` runs the plane on the GPU and ``auto`` picks the GPU for it, with the CPU's
    energies per replica."""
    rows = {}
    for device in ("cpu", "gpu", "auto"):
        rc = cli.main(["minimize", "--surface", "plane", "--cells", "24", "--replicas", "2", "--max-steps", "2000",
                       "--seed", "3", "--device", device])
        captured = capsys.readouterr()
        assert rc == 0, captured.err
        rows[device] = np.array([float(line.split()[1]) for line in captured.out.splitlines()[1:] if line.strip()])
        if device != "cpu":
            assert captured.err.rstrip().endswith("on gpu") or " on gpu" in captured.err
    np.testing.assert_allclose(rows["gpu"], rows["cpu"], rtol=1e-6, atol=1e-14)
    np.testing.assert_allclose(rows["auto"], rows["gpu"], rtol=1e-6, atol=1e-14)
