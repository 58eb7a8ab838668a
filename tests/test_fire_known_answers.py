"""FIRE known answers: single steps and the control logic against an independent reference.

The reference below is written from Bitzek et al., PRL 97, 170201 (2006), in the variant the FIRE
docstring documents (per replica: power, mix or stop, dt/alpha control, then semi-implicit Euler
with re-projection onto the sphere and transport of v into the new tangent plane). It shares no
code with spherevm. The force is a per-replica uniform field projected on the sphere, computed
here too, so every number of one step is known in advance.
"""
import numpy as np
import pytest

import spherevm as svm
from spherevm.plugins.base import Force, ForceResult
from spherevm.plugins.integrators import FIRE

from conftest import to_numpy

PARAMS = dict(dt=0.01, dt_max=0.05, n_min=5, f_inc=1.2, f_dec=0.6, alpha_start=0.15, f_alpha=0.9)


class UniformField(Force):
    """E_r = sum_i (|g_r| R_r - g_r . x_i) >= 0 per replica: the force is g_r projected on the tangent plane."""

    def __init__(self, fields):
        super().__init__()
        self.fields = np.asarray(fields, dtype=np.float64)

    def compute(self, state):
        xp = state.device.xp
        rep = state.vertex_replica
        g = xp.asarray(self.fields)[rep]
        x = state.positions
        n = x / xp.linalg.norm(x, axis=1)[:, None]
        forces = g - (g * n).sum(axis=1)[:, None] * n
        radius = xp.asarray(state.radius_np())
        per_vertex = xp.linalg.norm(g, axis=1) * radius[rep] - (g * x).sum(axis=1)
        energy = xp.bincount(rep, weights=per_vertex, minlength=state.n_replicas)
        return ForceResult(forces=forces, energy=energy)


def reference_forces(x, g):
    n = x / np.linalg.norm(x, axis=1)[:, None]
    return g - (n @ g)[:, None] * n


def reference_fire_step(x, v, radius, dt, alpha, n_pos, active, g, p):
    """One FIRE iteration of one replica (plain NumPy, unit mass). Returns x, v, dt, alpha, n_pos."""
    if not active:                       # a stopped replica does not move; its memory is kept
        return x.copy(), np.zeros_like(v), dt, alpha, n_pos
    F = reference_forces(x, g)
    P = float(np.sum(F * v))
    if P > 0:
        v_norm = np.sqrt(np.sum(v * v))
        f_norm = np.sqrt(np.sum(F * F))
        v = (1.0 - alpha) * v + alpha * v_norm * F / f_norm
        if n_pos >= p["n_min"]:
            dt = min(dt * p["f_inc"], p["dt_max"])
            alpha = alpha * p["f_alpha"]
        n_pos += 1
    else:
        v = np.zeros_like(v)
        dt = dt * p["f_dec"]
        alpha = p["alpha_start"]
        n_pos = 0
    v = v + dt * F
    y = x + dt * v
    x = radius * y / np.linalg.norm(y, axis=1)[:, None]
    n = x / radius
    v = v - np.sum(v * n, axis=1)[:, None] * n
    return x, v, dt, alpha, n_pos


# replica regimes: (power sign, dt, alpha, n_positive, active)
REGIMES = [
    ("+", 0.010, 0.30, 2, True),    # P > 0, fewer than n_min good steps: mix only
    ("+", 0.010, 0.25, 4, True),    # P > 0, n_min - 1 good steps: still no growth
    ("+", 0.020, 0.20, 5, True),    # P > 0 at n_min: dt grows, alpha decays
    ("+", 0.045, 0.12, 9, True),    # P > 0, growth capped at dt_max
    ("-", 0.030, 0.07, 8, True),    # P < 0: v zeroed, dt shrinks, alpha reset, counter reset
    ("0", 0.020, 0.05, 3, True),    # at rest (P = 0): treated as P <= 0
    ("+", 0.033, 0.21, 7, False),   # stopped: does not move, keeps dt, alpha, counter
]


def _setup(device, seed=3, strength=1.0):
    rng = np.random.default_rng(seed)
    n_rep = len(REGIMES)
    state = svm.init.random_tiling(12, replicas=n_rep, seed=seed)
    fields = strength * rng.normal(size=(n_rep, 3))
    sim = svm.Simulation(device=device)
    sim.state = state
    sim.operations.forces.append(UniformField(fields))
    fire = FIRE(force_tol=0.0, energy_tol=0.0, check_every=1000, **PARAMS)
    sim.operations.integrator = fire
    x = to_numpy(sim.state.positions)
    rep = state.vertex_replica_np()
    v = np.zeros_like(x)
    for r, (sign, *_rest) in enumerate(REGIMES):
        m = rep == r
        F = reference_forces(x[m], fields[r])
        n = x[m] / np.linalg.norm(x[m], axis=1)[:, None]
        w = rng.normal(size=F.shape)
        w -= np.sum(w * n, axis=1)[:, None] * n          # tangent, not along F: mixing matters
        if sign == "+":
            v[m] = 0.8 * F + 0.5 * strength * w
        elif sign == "-":
            v[m] = -0.8 * F + 0.5 * strength * w
        assert sign == "0" or np.sign(np.sum(F * v[m])) == (1 if sign == "+" else -1)
    xp = sim.state.device.xp
    fire.velocities = xp.asarray(v)
    fire.replica_dt = xp.asarray([reg[1] for reg in REGIMES], dtype=xp.float64)
    fire.alpha = xp.asarray([reg[2] for reg in REGIMES], dtype=xp.float64)
    fire.n_positive = xp.asarray([reg[3] for reg in REGIMES], dtype=xp.int64)
    active = np.array([reg[4] for reg in REGIMES])
    fire.stopped[~active] = True
    fire.set_active(active)
    ref = dict(x=x, v=v, dt=np.array([reg[1] for reg in REGIMES]), alpha=np.array([reg[2] for reg in REGIMES]),
               n_pos=np.array([reg[3] for reg in REGIMES]), active=active)
    return sim, fire, fields, rep, ref


def _reference_step(ref, fields, rep, radius):
    x, v = ref["x"].copy(), ref["v"].copy()
    for r in range(len(REGIMES)):
        m = rep == r
        x[m], v[m], ref["dt"][r], ref["alpha"][r], ref["n_pos"][r] = reference_fire_step(
            ref["x"][m], ref["v"][m], radius[r], ref["dt"][r], ref["alpha"][r], ref["n_pos"][r],
            ref["active"][r], fields[r], PARAMS)
    ref["x"], ref["v"] = x, v


def _compare(fire, sim, ref, rep):
    x, v = to_numpy(sim.state.positions), to_numpy(fire.velocities)
    for r in range(len(REGIMES)):
        m = rep == r
        np.testing.assert_allclose(x[m], ref["x"][m], rtol=0, atol=1e-14, err_msg=f"positions, replica {r}")
        np.testing.assert_allclose(v[m], ref["v"][m], rtol=0, atol=1e-14, err_msg=f"velocities, replica {r}")
    np.testing.assert_allclose(to_numpy(fire.replica_dt), ref["dt"], rtol=1e-15, atol=0, err_msg="dt")
    np.testing.assert_allclose(to_numpy(fire.alpha), ref["alpha"], rtol=1e-15, atol=0, err_msg="alpha")
    assert to_numpy(fire.n_positive).tolist() == ref["n_pos"].tolist()


def test_one_step_every_regime_matches_the_reference(device):
    sim, fire, fields, rep, ref = _setup(device)
    radius = sim.state.radius_np()
    x0 = ref["x"].copy()
    _reference_step(ref, fields, rep, radius)
    sim.run(1)
    _compare(fire, sim, ref, rep)
    # the control logic, spelled out per regime (not only through the reference)
    p = PARAMS
    dt, alpha, npos = to_numpy(fire.replica_dt), to_numpy(fire.alpha), to_numpy(fire.n_positive)
    assert dt[:2].tolist() == [0.010, 0.010] and alpha[:2].tolist() == [0.30, 0.25] and npos[:2].tolist() == [3, 5]
    assert dt[2] == pytest.approx(0.020 * p["f_inc"], rel=1e-15) and alpha[2] == pytest.approx(0.20 * p["f_alpha"])
    assert dt[3] == p["dt_max"] and alpha[3] == pytest.approx(0.12 * p["f_alpha"]) and npos[3] == 10
    assert dt[4] == pytest.approx(0.030 * p["f_dec"]) and alpha[4] == p["alpha_start"] and npos[4] == 0
    assert dt[5] == pytest.approx(0.020 * p["f_dec"]) and alpha[5] == p["alpha_start"] and npos[5] == 0
    assert (dt[6], alpha[6], npos[6]) == (0.033, 0.21, 7)
    # P <= 0: the old velocity is dropped entirely, v = P_T(x', dt F) only
    m = rep == 4
    F = reference_forces(x0[m], fields[4])
    x1 = to_numpy(sim.state.positions)[m]
    n1 = x1 / np.linalg.norm(x1, axis=1)[:, None]
    v_expect = dt[4] * F - np.sum(dt[4] * F * n1, axis=1)[:, None] * n1
    np.testing.assert_allclose(to_numpy(fire.velocities)[m], v_expect, rtol=0, atol=1e-15)
    # the stopped replica did not move; its velocities are zero
    m = rep == 6
    assert np.array_equal(to_numpy(sim.state.positions)[m], x0[m])
    assert not to_numpy(fire.velocities)[m].any()
    assert fire.loggables["fire_dt"](sim).tolist() == dt.tolist()


def test_several_steps_follow_the_reference(device):
    """Regimes change along the way (counters cross n_min, dt hits dt_max): state carries over."""
    sim, fire, fields, rep, ref = _setup(device, seed=5)
    radius = sim.state.radius_np()
    for _ in range(8):
        _reference_step(ref, fields, rep, radius)
        sim.run(1)
        _compare(fire, sim, ref, rep)
    # something grew on the way, and a replica that started at rest picked up speed
    assert (ref["n_pos"][:4] >= PARAMS["n_min"]).all()
    assert ref["n_pos"][5] > 0


def test_weak_forces_follow_the_reference(device):
    """|F| < 1 per replica (the mixing divides by |F|): the same reference, fields 100 times weaker."""
    sim, fire, fields, rep, ref = _setup(device, seed=5, strength=0.01)
    assert all(np.sqrt(np.sum(reference_forces(ref["x"][rep == r], fields[r]) ** 2)) < 0.2
               for r in range(len(REGIMES)))
    radius = sim.state.radius_np()
    for _ in range(3):
        _reference_step(ref, fields, rep, radius)
        sim.run(1)
        _compare(fire, sim, ref, rep)


def test_reset_restores_dt_alpha_counters_and_zeroes_velocities(device):
    sim, fire, fields, rep, ref = _setup(device)
    sim.run(2)
    fire.reset()
    assert not to_numpy(fire.velocities).any()
    assert to_numpy(fire.replica_dt).tolist() == [PARAMS["dt"]] * len(REGIMES)
    assert to_numpy(fire.alpha).tolist() == [PARAMS["alpha_start"]] * len(REGIMES)
    assert not to_numpy(fire.n_positive).any()
    assert fire.active.all() and not fire.stopped.any()
    assert list(fire.reason) == ["running"] * len(REGIMES) and (fire.steps == -1).all()
