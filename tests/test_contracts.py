"""The seams of the house: operation lists, loggable names, the Minimizer and Integrator
contracts, device paths bound at attach, and surfaces that refuse what they cannot do."""
from types import SimpleNamespace

import numpy as np
import pytest

import spherevm as svm
from conftest import to_numpy
from spherevm.device import Device
from spherevm.plugins.base import Force, ForceResult, Integrator
from spherevm.plugins.forces import VertexModel
from spherevm.plugins.integrators import FIRE, Brownian
from spherevm.plugins.updaters import T1


def _sim(device="cpu", replicas=3, n_cells=24, p0=3.9):
    sim = svm.Simulation(device=device, seed=2)
    sim.state = svm.init.random_tiling(n_cells, replicas=replicas, seed=4)
    sim.operations.forces.append(VertexModel.dimensionless(kr=1.0, p0=p0))
    return sim


# ------------------------------------------------------------------ operation lists
@pytest.mark.parametrize("mutate", [
    lambda ops, x: ops.append(x),
    lambda ops, x: ops.insert(0, x),
    lambda ops, x: ops.extend([x]),
    lambda ops, x: ops.__iadd__([x]),
    lambda ops, x: ops.__setitem__(0, x),
    lambda ops, x: ops.__setitem__(slice(0, 1), [x]),
])
def test_every_mutation_of_an_operation_list_is_checked(mutate):
    sim = _sim()
    with pytest.raises(TypeError, match="expected a spherevm.plugins.Force, got T1"):
        mutate(sim.operations.forces, T1())
    assert len(sim.operations.forces) == 1 and isinstance(sim.operations.forces[0], VertexModel)


def test_replacing_an_operation_detaches_the_old_and_attaches_the_new():
    sim = _sim()
    old, new = sim.operations.forces[0], VertexModel.dimensionless(kr=1.0, p0=3.7)
    sim.operations.forces[0] = new
    assert old._simulation is None and new._simulation is sim
    del sim.operations.forces[0]
    assert new._simulation is None and len(sim.operations.forces) == 0


class Energetic(Force):
    """A user force publishing a loggable named like a built-in."""
    narrowable = True

    def compute(self, state):
        xp = state.device.xp
        return ForceResult(xp.zeros_like(state.positions), xp.zeros(state.n_replicas))

    @property
    def loggables(self):
        return {"energy": lambda sim: 0.0}


def test_a_loggable_named_like_a_builtin_is_refused():
    sim = _sim()
    sim.operations.forces.append(Energetic())
    with pytest.raises(ValueError, match="'energy' of Energetic is already provided by the Simulation"):
        sim.log("energy")


# ------------------------------------------------------------------ the Minimizer
def test_hoomd_style_loop_reaches_the_minimize_result():
    ref = _sim()
    ref.operations.updaters.append(T1())
    ref.operations.integrator = FIRE(dt=0.02, force_tol=1e-9)
    result = ref.minimize(max_steps=20_000, narrow=False)
    assert result.all_converged

    sim = _sim()
    sim.operations.updaters.append(T1())
    fire = sim.operations.integrator = FIRE(dt=0.02, force_tol=1e-9)
    while not fire.done:
        sim.run(100)
    assert fire.converged and fire.done
    assert np.array_equal(fire.steps, result.steps)
    assert list(fire.reason) == list(result.reason)
    assert np.array_equal(sim.state.positions, ref.state.positions)     # stopped replicas do not move


def test_minimize_needs_a_minimizer():
    sim = _sim()
    sim.operations.integrator = Brownian(dt=0.01)
    with pytest.raises(TypeError, match="needs a spherevm.plugins.Minimizer integrator such as FIRE, found Brownian"):
        sim.minimize()


def test_minimize_settings_are_validated_and_kept():
    sim = _sim()
    sim.operations.integrator = fire = FIRE(dt=0.02)
    with pytest.raises(ValueError, match="check_every must be an integer >= 1"):
        sim.minimize(check_every=0)
    sim.minimize(force_tol=1e-6, max_steps=50)
    assert fire.force_tol == 1e-6


# ------------------------------------------------------------------ the Integrator contract
class Recording(Integrator):
    """An integrator that moves nothing and records what updaters asked of it."""

    def __init__(self):
        super().__init__()
        self.reset = []

    def step(self, simulation, forces):
        simulation.state_changed()

    def reset_vertices(self, vertices):
        self.reset.append(np.asarray(vertices))


def test_t1_acts_on_active_replicas_only_and_resets_through_the_contract():
    sim = svm.Simulation(device="cpu")
    sim.state = svm.init.random_tiling(64, replicas=2, seed=3)
    t1 = T1(threshold=0.3, new_length=0.45)            # many short edges in a random tiling
    sim.operations.updaters.append(t1)
    integ = sim.operations.integrator = Recording()
    integ.set_active([False, True])
    sim.run(1)
    flips = sim.log("t1_flips")
    assert flips[0] == 0 and flips[1] > 0
    moved = np.concatenate(integ.reset)
    assert len(moved) == 2 * flips[1]
    assert np.all(sim.state.vertex_replica_np()[moved] == 1)


def test_active_mask_length_is_checked():
    sim = _sim()
    sim.operations.integrator = FIRE()
    with pytest.raises(ValueError, match="active mask has 2 entries, but the state has 3 replicas"):
        sim.operations.integrator.set_active([True, False])


# ------------------------------------------------------------------ device and surface seams
def test_device_path_is_looked_up_once_and_gpu_surfaces_are_checked():
    vm = VertexModel()
    cpu_state = svm.init.random_tiling(16)
    assert vm.implementation("compute", cpu_state) == vm._compute_cpu
    assert vm.implementation("compute", cpu_state) is vm.implementation("compute", cpu_state)
    # a state on the GPU (only its device and surface matter here) on a surface the kernels do not know
    fake = SimpleNamespace(device=Device("gpu", np), constraint=svm.constraints.Sphere(metric="flat"))
    with pytest.raises(ValueError, match=r"VertexModel on the GPU supports GeodesicSphere, PeriodicPlane, ImplicitSurface "
                                         r"surfaces only, but the state is on Sphere\(metric='flat'\)"):
        vm.implementation("compute", fake)
    sphere = SimpleNamespace(device=Device("gpu", np), constraint=svm.constraints.Sphere())
    assert vm.implementation("compute", sphere) == vm._compute_gpu


class Unmeasured(svm.constraints.Constraint):
    """A surface that does not measure cells (no metric): the stub a new surface starts as."""


def test_a_stub_surface_is_refused_at_attach():
    state = svm.init.random_tiling(16)
    state.constraint = Unmeasured()
    sim = svm.Simulation(device="cpu")
    sim.state = state
    with pytest.raises(NotImplementedError, match=r"VertexModel needs cell_geometry, shape_gradient"):
        sim.operations.forces.append(VertexModel())
    assert len(sim.operations.forces) == 0


# ------------------------------------------------------------------ the shape-gradient contract
def _flat(state):
    state.constraint = svm.constraints.Sphere(metric="flat")
    return state


def _sinusoid():
    """The user's ImplicitSurface subclass of tests/plugin_example, loaded from its file."""
    import importlib.util
    import pathlib
    path = pathlib.Path(__file__).parent / "plugin_example" / "spherevm_sinusoid.py"
    spec = importlib.util.spec_from_file_location("spherevm_sinusoid", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module.Sinusoid(amplitude=1.0)


def _on(surface):
    return lambda: svm.init.random_tiling(24, replicas=2, seed=5, surface=surface())


SURFACES = {"Sphere": lambda: svm.init.random_tiling(24, replicas=2, seed=5, radius=1.7),
            "FlatSphere": lambda: _flat(svm.init.random_tiling(24, replicas=2, seed=5, radius=1.7)),
            "PeriodicPlane": lambda: svm.init_plane.random_planar_tiling(24, replicas=2, seed=5),
            "Torus": _on(lambda: svm.constraints.Torus(2.0, 1.0)), "Ellipsoid": _on(svm.constraints.Ellipsoid),
            "GaussianBump": _on(svm.constraints.GaussianBump), "ImplicitSurface": _on(_sinusoid)}


def test_every_surface_with_a_shape_gradient_is_checked_against_the_contract():
    base = svm.constraints.Constraint.shape_gradient
    implementing = {name for name in svm.constraints.__all__
                    if name != "Constraint" and getattr(svm.constraints, name).shape_gradient is not base}
    assert implementing == set(SURFACES)


@pytest.mark.parametrize("surface", sorted(SURFACES))
@pytest.mark.parametrize("left_out", [(0,), (1,), (2,), (0, 1), (0, 2), (1, 2), (0, 1, 2)])
def test_a_none_coefficient_leaves_out_its_term_only(device, surface, left_out):
    """``shape_gradient`` with some of d_area, d_perimeter, d_area_vector None equals the full
    gradient with those coefficients zero (constraints/base.py), on every surface and device."""
    state = SURFACES[surface]().to(device)
    con, xp = state.constraint, state.device.xp
    geometry = con.cell_geometry(state, area_vectors=True)
    rng = np.random.default_rng(7)
    coef = [xp.asarray(rng.normal(size=shape)) for shape in ((state.n_cells,), (state.n_cells,), (state.n_cells, 3))]
    zeroed = [xp.zeros_like(c) if i in left_out else c for i, c in enumerate(coef)]
    given = [None if i in left_out else c for i, c in enumerate(coef)]
    want = to_numpy(con.shape_gradient(state, geometry, *zeroed))
    got = to_numpy(con.shape_gradient(state, geometry, *given))
    assert got.shape == (state.n_vertices, 3)
    assert np.abs(want).max() > 0 or left_out == (0, 1, 2)
    assert np.allclose(got, want, rtol=0, atol=1e-14 * max(np.abs(want).max(), 1.0))
