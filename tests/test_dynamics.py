"""Brownian and active integrators: free-particle laws on the sphere, guards, bad input."""
import numpy as np
import pytest
from conftest import to_numpy

import spherevm as svm
from spherevm.plugins.forces import VertexModel
from spherevm.plugins.integrators import Active, Brownian


def _free(state, integrator, seed=3, device="cpu"):
    sim = svm.Simulation(device=device, seed=seed)
    sim.state = state
    sim.operations.integrator = integrator
    return sim


def test_free_brownian_short_time_msd_and_long_time_decorrelation(device):
    # unit sphere, D = mu T = 1: short times MSD = 4 D t (tangent plane), long times
    # <cos theta> = exp(-2 D t / R^2)
    state = svm.init.random_tiling(200, replicas=8, seed=1, radius=1.0)
    dt = 2e-4
    sim = _free(state, Brownian(dt=dt, T=1.0, mu=1.0, max_step=10.0), device=device)
    x0 = to_numpy(sim.state.positions).copy()
    n = len(x0)
    sim.run(10, check_every=10)
    t = 10 * dt
    msd = ((to_numpy(sim.state.positions) - x0) ** 2).sum(axis=1).mean()
    # chord MSD = 4Dt (1 - Dt/R^2 ...) on the sphere; the spread of the mean is ~ msd/sqrt(n)
    assert abs(msd - 4 * t) < 5 * 4 * t / np.sqrt(n / 2) + 4 * t * (t + 1e-3)
    for t_target in (0.25, 0.5):
        sim.run(int(round(t_target / dt)) - sim.timestep, check_every=1000)
        c = (to_numpy(sim.state.positions) * x0).sum(axis=1).mean()
        expected = np.exp(-2 * t_target)
        sigma = np.sqrt((1 - expected ** 2) / 3 / n)          # spread of <cos theta> over n walkers
        assert abs(c - expected) < 5 * sigma + 0.01
    assert np.allclose(np.linalg.norm(to_numpy(sim.state.positions), axis=1), 1.0, rtol=1e-14)


def test_free_brownian_diffusion_constant_from_single_steps(device):
    # D = mu T = 1 on the unit sphere, from single-step increments. A step moves x by a tangent dr
    # (each component of variance 2 D dt) and projects back, so tan(angle(x, x'))^2 = |dr|^2 exactly and
    # D_hat = <tan^2> / (4 dt) is unbiased. |dr|^2 is exponential (chi2_2): the relative standard error
    # of D_hat is std(tan^2) / mean(tan^2) / sqrt(M) ~ 1 / sqrt(M), M = 10 steps x 3168 walkers ~ 3e4
    # independent increments: ~0.56%. The bound 5 standard errors (~2.8%) lets a 10% error in D through
    # with probability ~0 (it sits ~18 standard errors out); a correct D fails it with p ~ 6e-7.
    state = svm.init.random_tiling(200, replicas=8, seed=1, radius=1.0)
    dt = 2e-4
    sim = _free(state, Brownian(dt=dt, T=1.0, mu=1.0, max_step=10.0), device=device)
    x = to_numpy(sim.state.positions).copy()
    tan2 = []
    for _ in range(10):
        sim.run(1, check_every=1)
        y = to_numpy(sim.state.positions)
        tan2.append((np.cross(x, y) ** 2).sum(axis=1) / (x * y).sum(axis=1) ** 2)
        x = y
    tan2 = np.concatenate(tan2)
    d_hat = tan2.mean() / (4 * dt)
    stderr = tan2.std() / tan2.mean() / np.sqrt(tan2.size)
    assert 0.004 < stderr < 0.008                           # exponential increments: ~1 / sqrt(M)
    assert abs(d_hat - 1.0) < 5 * stderr


def test_brownian_noise_is_tangent_and_reproducible(device):
    state = svm.init.random_tiling(50, seed=2)
    a = _free(state, Brownian(dt=1e-3, T=0.1), seed=9, device=device)
    b = _free(state, Brownian(dt=1e-3, T=0.1), seed=9, device=device)
    c = _free(state, Brownian(dt=1e-3, T=0.1), seed=10, device=device)
    for s in (a, b, c):
        s.run(10)
    assert np.array_equal(to_numpy(a.state.positions), to_numpy(b.state.positions))
    assert not np.allclose(to_numpy(a.state.positions), to_numpy(c.state.positions))


def test_zero_temperature_brownian_descends_the_energy(device):
    sim = _free(svm.init.random_tiling(64, seed=4), Brownian(dt=0.01, T=0.0), device=device)
    sim.operations.forces.append(VertexModel.dimensionless(kr=1.0, p0=3.9))
    e0 = sim.log("energy")[0]
    sim.run(200)
    assert sim.log("energy")[0] < 0.5 * e0


def test_per_replica_temperatures(device):
    state = svm.init.random_tiling(100, replicas=2, seed=5, radius=3.0)
    sim = _free(state, Brownian(dt=1e-3, T=[0.0, 1.0]), device=device)
    x0 = to_numpy(sim.state.positions).copy()
    sim.run(5)
    moved = np.linalg.norm(to_numpy(sim.state.positions) - x0, axis=1)
    nv = state.vertices_per_replica[0]
    assert moved[:nv].max() < 1e-14 and moved[nv:].min() > 1e-6   # T = 0: re-projection round-off only
    with pytest.raises(ValueError, match="T has 3 values"):
        _free(state, Brownian(dt=1e-3, T=[0.0, 1.0, 2.0]), device=device)


def test_free_active_particles_director_and_msd(device):
    # a huge sphere (R = 200) is locally flat: persistent random walk, l_p = v0/Dr
    v0, Dr, dt = 1.0, 1.0, 2e-3
    state = svm.init.random_tiling(400, replicas=4, seed=6, radius=200.0)
    sim = _free(state, Active(dt=dt, v0=v0, Dr=Dr, directors="vertex", max_step=10.0), device=device)
    x0 = to_numpy(sim.state.positions).copy()
    d0 = to_numpy(sim.operations.integrator.directors).copy()
    n = len(x0)
    for t_target in (0.05, 0.5, 2.0):
        sim.run(int(round(t_target / dt)) - sim.timestep, check_every=500)
        t = sim.timestep * dt
        d = to_numpy(sim.operations.integrator.directors)
        x = to_numpy(sim.state.positions)
        assert np.allclose(np.linalg.norm(d, axis=1), 1.0, atol=1e-12)
        assert np.abs((d * x).sum(axis=1)).max() < 1e-9 * 200
        corr = (d * d0).sum(axis=1).mean()
        assert abs(corr - np.exp(-Dr * t)) < 5 * np.sqrt(0.5 / n) + 0.01
        msd = ((x - x0) ** 2).sum(axis=1).mean()
        expected = 2 * v0 ** 2 / Dr ** 2 * (Dr * t - 1 + np.exp(-Dr * t))
        assert abs(msd - expected) < 0.1 * expected
    # ballistic at short times, diffusive with D = v0^2 / (2 Dr) at long times
    assert 2 * v0 ** 2 / Dr ** 2 * (Dr * 0.05 - 1 + np.exp(-Dr * 0.05)) == pytest.approx((v0 * 0.05) ** 2, rel=0.05)


def test_cell_directors_drive_vertices(device):
    state = svm.init.random_tiling(64, seed=7)
    sim = _free(state, Active(dt=1e-3, v0=0.5, Dr=0.0), device=device)
    x0 = to_numpy(sim.state.positions).copy()
    sim.run(10)
    assert np.linalg.norm(to_numpy(sim.state.positions) - x0, axis=1).max() > 0
    d = to_numpy(sim.operations.integrator.directors)
    assert d.shape == (64, 3)
    apex = to_numpy(sim.state.constraint.cell_centers(sim.state))
    assert np.abs((d * apex).sum(axis=1)).max() < 1e-12


def test_exploding_step_and_nan_stop_the_run_with_names(tmp_path, device):
    sim = _free(svm.init.random_tiling(32, seed=8), Brownian(dt=10.0, T=1.0, max_step=0.5), device=device)
    with pytest.raises(FloatingPointError, match=r"timestep 0: replica 0, vertex \d+"):
        sim.run(5)      # on the GPU the check (default every 100 steps) comes at the run's end
    sim = _free(svm.init.random_tiling(32, seed=8), Brownian(dt=1e-3, T=0.0), device=device)
    sim.operations.writers.append(svm.plugins.writers.GSD(1, tmp_path / "t.gsd"))
    sim.run(3)
    sim.state.positions[4] = np.nan
    # every step checked (the CPU's default), so the run stops before the writer sees the NaN
    with pytest.raises(FloatingPointError, match="replica 0, vertex 4"):
        sim.run(3, check_every=1)
    last = svm.init.from_gsd(tmp_path / "t.gsd")
    assert np.isfinite(last.positions).all()


@pytest.mark.parametrize("cls, kw, match", [
    (Brownian, dict(dt=0), "dt"), (Brownian, dict(dt=-1), "dt"), (Brownian, dict(dt=0.1, T=-1), "T"),
    (Brownian, dict(dt=0.1, mu=-1), "mu"), (Active, dict(dt=0.1, v0=-1, Dr=1), "v0"),
    (Active, dict(dt=0.1, v0=1, Dr=-1), "Dr"), (Active, dict(dt=0.1, v0=1, Dr=1, directors="edge"), "directors"),
])
def test_bad_dynamics_parameters(cls, kw, match):
    with pytest.raises(ValueError, match=match):
        cls(**kw)
