"""Time steps from the stiffest mode (protocols.hessian_scale, stable_dt, glassy_dynamics(dt="auto"))."""
import numpy as np
import pytest

import spherevm as svm
from spherevm.plugins.forces import Bending, VertexModel
from spherevm.plugins.integrators import FIRE, Brownian
from spherevm.plugins.updaters import T1
from spherevm.protocols import STABILITY, glassy_dynamics, hessian_scale, stable_dt


def relaxed(device, n=32, replicas=2, B=0.0, kr=1.0, steps=300):
    """Random tilings relaxed by FIRE + T1 without bending, then ``Bending(B)`` added and T1 taken off
    (a fixed topology from there on)."""
    sim = svm.Simulation(device=device, seed=12)
    sim.state = svm.init.random_tiling(n, replicas=replicas, seed=12)
    sim.operations.forces.append(VertexModel.dimensionless(kr=kr, p0=3.775))
    sim.operations.updaters.append(T1())
    sim.operations.integrator = FIRE(dt=0.02)
    sim.minimize(force_tol=1e-8, max_steps=steps)
    sim.operations.updaters.clear()
    sim.operations.forces.append(Bending(B))
    return sim


def dense_hessian_extreme(sim):
    """The largest |eigenvalue| of the Hessian in a tangent basis (two directions per vertex), by
    central differences of the forces, one column at a time (one replica)."""
    state = sim.state
    x0 = state.device.to_numpy(state.positions).copy()
    r = np.linalg.norm(x0, axis=1)[:, None]
    n = x0 / r
    e1 = np.cross(n, np.where(np.abs(n[:, [0]]) < 0.9, [[1.0, 0, 0]], [[0, 1.0, 0]]))
    e1 /= np.linalg.norm(e1, axis=1)[:, None]
    e2 = np.cross(n, e1)
    basis = [(v, e) for v in range(len(x0)) for e in (e1[v], e2[v])]
    h, eps = np.zeros((len(basis), len(basis))), 1e-6

    def forces(x):
        state.positions[...] = state.device.asarray(r * x / np.linalg.norm(x, axis=1)[:, None])
        sim.state_changed()
        return state.device.to_numpy(sim.compute_forces()[0])

    for j, (v, e) in enumerate(basis):
        plus, minus = x0.copy(), x0.copy()
        plus[v] += eps * e
        minus[v] -= eps * e
        df = (forces(minus) - forces(plus)) / (2 * eps)
        h[:, j] = [df[w] @ d for w, d in basis]
    state.positions[...] = state.device.asarray(x0)
    sim.state_changed()
    return np.abs(np.linalg.eigvalsh((h + h.T) / 2)).max()


def test_hessian_scale_is_the_largest_eigenvalue_of_the_hessian(device):
    sim = relaxed(device, n=16, replicas=1, B=3.0)
    before = sim.state.device.to_numpy(sim.state.positions).copy()
    lam = hessian_scale(sim, iterations=300)
    assert np.array_equal(sim.state.device.to_numpy(sim.state.positions), before)   # put back exactly
    assert lam[0] == pytest.approx(dense_hessian_extreme(sim), rel=2e-3)


def test_hessian_scale_follows_the_energy_scale(device):
    """Doubling every stiffness (kP, and B) doubles it; each replica gets its own."""
    sim = relaxed(device, B=2.0)
    lam = hessian_scale(sim)
    assert lam.shape == (2,) and np.all((lam > 10) & (lam < 40))
    vm, bending = sim.operations.forces
    vm.kP, bending.B = 2.0, 4.0
    assert np.allclose(hessian_scale(sim), 2 * lam, rtol=1e-6)


def test_stable_dt_falls_as_one_over_B_once_bending_dominates(device):
    sim = relaxed(device, kr=0.0)
    dt, dt_fire = {}, {}
    for B in (1e3, 1e4):
        sim.operations.forces[1].B = B
        dt[B], dt_fire[B] = stable_dt(sim, "brownian"), stable_dt(sim, "fire")
    assert np.allclose(dt[1e3] / dt[1e4], 10, rtol=0.02)
    assert np.allclose(dt_fire[1e3] / dt_fire[1e4], np.sqrt(10), rtol=0.01)
    lam = hessian_scale(sim)
    assert np.allclose(stable_dt(sim, "brownian", mu=2.0), STABILITY["brownian"] / (2 * lam))
    with pytest.raises(ValueError, match="method must be 'brownian' or 'fire'"):
        stable_dt(sim, "verlet")


def test_stiff_bending_is_stable_with_the_rule_and_not_with_the_usual_step(device):
    """B = 100 on 32 cells (B / R^2 = 39, twice the vertex model's stiffness of about 17): FIRE with
    dt_max from the rule lowers the energy and Brownian dynamics at the rule's step stay finite;
    Brownian at dt = 0.02 explodes at once."""
    sim = relaxed(device, B=100.0, steps=150)
    start = sim.state.copy()
    dt_max = float(stable_dt(sim, "fire").min())
    assert dt_max < 0.1
    sim.operations.integrator = FIRE(dt=dt_max / 10, dt_max=dt_max)
    e0 = sim.state.device.to_numpy(sim.compute_forces()[1]).copy()
    result = sim.minimize(force_tol=1e-8, max_steps=200)
    assert np.all(np.isfinite(result.energy)) and np.all(result.energy < e0)
    dt = float(stable_dt(sim).min())
    sim.operations.integrator = Brownian(dt=dt, T=0.01)
    sim.run(300)
    assert np.all(np.isfinite(sim.state.device.to_numpy(sim.state.positions)))
    sim.state = start
    sim.operations.integrator = Brownian(dt=0.02, T=0.01)
    with pytest.raises(FloatingPointError, match="exploding step"):
        sim.run(100)


def test_glassy_dynamics_auto_dt_and_stopping_rules():
    state = svm.init.random_tiling(16, replicas=2, seed=3)
    kw = dict(T=[0.08, 0.08], steps=10_000, relax_steps=500, seed=3, device="cpu", initial_state=state)
    res = glassy_dynamics(None, 3.9, 0.0, dt="auto", extra_forces=[Bending(0.1)], until_relaxed=True, **kw)
    assert 0.005 < res.dt < 0.05
    assert res.stopped == "relaxed" and res.production_steps < 10_000
    assert np.all(np.isfinite(res.tau_alpha_per_replica)) and res.lag[-1] <= res.production_steps * res.dt
    capped = glassy_dynamics(None, 3.9, 0.0, dt=0.02, max_seconds=1e-3, **{**kw, "relax_steps": 10, "steps": 2000})
    assert capped.stopped == "max_seconds" and capped.production_steps == 1000
    with pytest.raises(ValueError, match="dt must be a positive number or 'auto'"):
        glassy_dynamics(None, 3.9, 0.0, dt="fast", **kw)


def test_auto_dt_refuses_a_step_too_small_to_be_a_healthy_tissue(monkeypatch):
    from spherevm import protocols
    monkeypatch.setattr(protocols, "MIN_AUTO_DT", 1.0)
    with pytest.raises(FloatingPointError, match=r"dt='auto': the stable Brownian step is 0\.0\d+, below 1: the "
                       r"forces are close to singular \(smallest cell area 0\.\d+ <A>"):
        glassy_dynamics(16, 3.9, 0.0, T=0.05, dt="auto", steps=100, relax_steps=10, device="cpu")
