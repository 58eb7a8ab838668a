"""FIRE minimisation on the sphere: per-replica control, stop criteria, exact minima."""
import numpy as np
import pytest

from conftest import to_numpy

import spherevm as svm
from spherevm.plugins.forces import VertexModel
from spherevm.plugins.integrators import FIRE


def _sim(state, model, device, dt=0.02):
    sim = svm.Simulation(device=device)
    sim.state = state
    sim.operations.forces.append(model)
    sim.operations.integrator = FIRE(dt=dt)
    return sim


def test_floppy_regime_reaches_zero_energy_to_round_off(device):
    sim = _sim(svm.init.random_tiling(64, replicas=3, seed=3), VertexModel.dimensionless(kr=0.0, p0=5.0), device)
    e0 = sim.log("energy_per_cell")
    res = sim.minimize(force_tol=1e-14, energy_tol=1e-26, max_steps=5000)
    assert res.all_converged
    assert np.all(e0 > 0.5)
    assert np.all(res.energy_per_cell < 1e-26)
    sim.state.validate(orientation=False)  # kA = 0: cells may fold over


def test_energy_falls_by_orders_of_magnitude(device):
    sim = _sim(svm.init.random_tiling(64, replicas=2, seed=4), VertexModel.dimensionless(kr=1.0, p0=4.6), device)
    e0 = sim.log("energy_per_cell")
    res = sim.minimize(force_tol=1e-12, energy_tol=1e-24, max_steps=3000)
    assert np.all(res.energy_per_cell < 1e-4 * e0)
    norms = np.linalg.norm(sim.device.to_numpy(sim.state.positions), axis=1)
    assert np.allclose(norms, sim.state.radius_np()[0], rtol=1e-14)


def _at_own_minimum():
    s = svm.init.regular_tiling("dodecahedron")
    area, perim = svm.analysis.cell_shapes(s)
    return s, area[0], perim[0]


def test_exact_minimum_stays_put(device):
    s, a, p = _at_own_minimum()
    pos0 = s.positions.copy()
    sim = _sim(s, VertexModel(kA=1.0, kP=1.0, A0=a, P0=p), device)
    res = sim.minimize(force_tol=1e-12, max_steps=100)
    assert res.converged[0] and res.reason[0] == "force" and res.steps[0] == 0
    assert np.array_equal(to_numpy(sim.state.positions), pos0)
    # and if FIRE is made to run anyway, it does not drift off
    sim.run(200)
    assert np.abs(to_numpy(sim.state.positions) - pos0).max() < 1e-12


def test_converged_replicas_stop_while_others_go_on(device):
    s, a, p = _at_own_minimum()
    rand = svm.init.random_tiling(12, seed=9, radius=float(s.radius_np()[0]))
    ens = svm.State.concatenate([s, rand])
    model = VertexModel(kA=1.0, kP=1.0, A0=a, P0=p)
    sim = _sim(ens, model, device)
    pos0 = to_numpy(sim.state.positions).copy()
    res = sim.minimize(force_tol=1e-12, max_steps=50, check_every=5)
    assert list(res.converged) == [True, False]
    assert list(res.reason) == ["force", "max_steps"] and list(res.steps) == [0, 50]
    n0 = s.n_vertices
    pos = to_numpy(sim.state.positions)
    assert np.array_equal(pos[:n0], pos0[:n0])
    assert not np.allclose(pos[n0:], pos0[n0:])


def test_replicas_minimise_as_if_alone(device):
    ens = svm.init.random_tiling(32, replicas=2, seed=12)
    model = VertexModel.dimensionless(kr=1.0, p0=4.6)
    res_ens = _sim(ens, model, device).minimize(max_steps=300, force_tol=0)
    for r in range(2):
        res_one = _sim(ens.replica(r), model, device).minimize(max_steps=300, force_tol=0)
        assert np.isclose(res_one.energy[0], res_ens.energy[r], rtol=1e-10, atol=1e-15)


@pytest.mark.parametrize("kw, match", [
    (dict(dt=0), "dt must be positive"), (dict(dt=-0.1), "dt must be positive"),
    (dict(dt=float("nan")), "dt must be positive"), (dict(dt=0.1, dt_max=0.01), "dt_max must be >= dt"),
    (dict(n_min=-1), "n_min"), (dict(f_dec=1.5), "f_dec < 1"), (dict(f_dec=1.0), "f_dec < 1"),
    (dict(alpha_start=1.0), "alpha_start < 1"), (dict(alpha_start=1.5), "alpha_start < 1"),
    (dict(f_alpha=1.0 + 1e-12), "f_alpha <= 1"), (dict(f_inc=0.999), "f_inc must be >= 1"),
])
def test_fire_bad_parameters(kw, match):
    with pytest.raises(ValueError, match=match):
        FIRE(**kw)


def test_fire_defaults_and_boundary_parameters():
    # the defaults are Bitzek et al. (2006)'s, with dt_max = 10 dt and the documented tolerances;
    # dt is the one the docs, the CLI and the sweeps use (issue 14.7: it was 0.01 against their 0.02)
    f = FIRE()
    assert (f.dt, f.dt_max, f.n_min, f.f_inc, f.f_dec, f.alpha_start, f.f_alpha) == (0.02, 0.2, 5, 1.1, 0.5, 0.1, 0.99)
    from spherevm.cli import build_parser
    from spherevm.sweeps import RigiditySweep
    cli = build_parser()
    assert cli.parse_args(["minimize"]).dt == cli.parse_args(["rigidity"]).dt == f.dt
    assert RigiditySweep(cells=[16], p0=[3.8], replicas=1).dt == f.dt
    assert (f.force_tol, f.energy_tol, f.check_every) == (1e-10, 1e-20, 10)
    assert FIRE(dt=0.03).dt_max == pytest.approx(0.3, rel=1e-15)
    # the closed ends of the ranges are allowed
    FIRE(dt=0.1, dt_max=0.1)
    FIRE(f_inc=1.0)
    FIRE(f_alpha=1.0)


def test_reset_vertices_zeroes_only_those_vertices(device):
    sim = _sim(svm.init.random_tiling(16, seed=2), VertexModel.dimensionless(kr=1.0, p0=3.6), device)
    sim.run(5)
    fire = sim.operations.integrator
    v0 = to_numpy(fire.velocities).copy()
    assert np.all(np.linalg.norm(v0, axis=1) > 0)
    fire.reset_vertices(sim.state.device.xp.asarray(np.array([0, -1, 7], dtype=np.int32)))  # -1: padding
    v1 = to_numpy(fire.velocities)
    assert not v1[[0, 7]].any()
    keep = np.ones(len(v0), bool)
    keep[[0, 7]] = False
    assert np.array_equal(v1[keep], v0[keep])


def test_minimize_bad_arguments_and_missing_pieces(device):
    sim = svm.Simulation(device=device)
    with pytest.raises(RuntimeError, match="set sim.state first"):
        sim.minimize()
    sim.state = svm.init.random_tiling(16)
    with pytest.raises(RuntimeError, match="no force"):
        sim.minimize(max_steps=1)
    sim.operations.forces.append(VertexModel())
    with pytest.raises(ValueError, match="force_tol"):
        sim.minimize(force_tol=-1)
    with pytest.raises(ValueError, match="check_every"):
        sim.minimize(check_every=0)
