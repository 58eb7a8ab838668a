"""Third-party plugins through the entry-point group ``spherevm.plugins``, with nothing installed.

``tests/plugin_example/`` holds a tiny distribution as pip would leave it in site-packages: the
module ``spherevm_line_tension.py`` and ``spherevm_line_tension-0.1.dist-info/`` (METADATA and
entry_points.txt). Putting that folder on ``sys.path`` is all importlib.metadata needs to find it.
"""
from __future__ import annotations

import pathlib
import sys

import numpy as np
import pytest

import spherevm as svm
from spherevm import plugins

EXAMPLE = pathlib.Path(__file__).parent / "plugin_example"
TENSION = 0.7


@pytest.fixture
def line_tension_path(monkeypatch):
    """The example distribution on sys.path, for this test only."""
    monkeypatch.syspath_prepend(str(EXAMPLE))
    monkeypatch.delitem(sys.modules, "spherevm_line_tension", raising=False)
    yield
    sys.modules.pop("spherevm_line_tension", None)


@pytest.fixture
def LineTension(line_tension_path):
    return plugins.load("line_tension")


def _state(n_cells=20, replicas=2, seed=3):
    return svm.init.random_tiling(n_cells, replicas=replicas, seed=seed)


def test_not_found_without_the_distribution():
    assert "line_tension" not in plugins.available()
    with pytest.raises(ValueError, match="line_tension"):
        plugins.load("line_tension")


def test_load_through_entry_point(LineTension):
    assert isinstance(LineTension, type) and issubclass(LineTension, plugins.Force)
    assert LineTension.__module__ == "spherevm_line_tension"
    assert LineTension.__name__ == "LineTension"
    avail = plugins.available()
    assert "line_tension" in avail
    assert avail["vertex_model"] == "force"  # the built-ins are still listed


def test_energy_is_tension_times_total_edge_length(LineTension):
    state = _state()
    res = LineTension(TENSION).compute(state)
    e = svm.topology.edges(state.vertex_neighbors)
    lengths = state.constraint.edge_lengths(state, e[:, 0], e[:, 1])
    expected = TENSION * np.bincount(state.vertex_replica_np()[e[:, 0]], weights=lengths,
                                     minlength=state.n_replicas)
    np.testing.assert_allclose(res.energy, expected, rtol=1e-13)
    # each cell gets half of its perimeter's worth; the cells add up to the total
    _, perimeter = svm.analysis.cell_shapes(state)
    np.testing.assert_allclose(res.cell_energy, 0.5 * TENSION * perimeter, rtol=1e-13)
    np.testing.assert_allclose(np.bincount(state.cell_replica_np(), weights=res.cell_energy), expected, rtol=1e-13)


def test_forces_match_finite_differences_and_are_tangent(LineTension):
    state = _state()
    force = LineTension(TENSION)
    F = force.forces(state)
    x0 = state.positions.copy()
    rep = state.vertex_replica_np()
    h = 1e-5  # balances truncation (h^2) against rounding (eps E / h): errors ~2e-8 here
    rng = np.random.default_rng(0)
    vertices = rng.choice(state.n_vertices, size=12, replace=False)
    fd = np.zeros((len(vertices), 3))
    for i, v in enumerate(vertices):  # a test, not a hot path
        for d in range(3):
            for sign in (+1, -1):
                x = x0.copy()
                x[v, d] += sign * h
                state.positions = x
                fd[i, d] -= sign * force.energy(state)[rep[v]] / (2 * h)
    state.positions = x0
    # the energy depends on directions only, so the full 3-D gradient is the surface gradient
    err = np.linalg.norm(fd - F[vertices], axis=1)
    assert np.all(err <= 1e-6 * np.linalg.norm(F[vertices], axis=1)), err
    radial = np.abs((F * x0).sum(axis=1)) / np.linalg.norm(x0, axis=1)
    assert np.all(radial <= 1e-12 * np.linalg.norm(F, axis=1))


def test_runs_in_a_simulation_with_fire(LineTension):
    sim = svm.Simulation(device="cpu", seed=1)
    sim.state = _state()
    lt = LineTension(TENSION)
    sim.operations.forces.append(svm.plugins.forces.VertexModel.dimensionless(kr=1.0, p0=4.5))
    sim.operations.forces.append(lt)
    sim.operations.integrator = svm.plugins.integrators.FIRE(dt=0.02)
    e0 = sim.log("energy").copy()
    sim.run(200)
    e1 = sim.log("energy")
    assert sim.timestep == 200
    assert np.all(np.isfinite(sim.state.positions))
    assert np.all(e1 < e0)
    assert "line_tension_energy" in sim.loggables
    np.testing.assert_allclose(sim.log("line_tension_energy"), lt.energy(sim.state))


def test_summed_forces_are_the_sum_of_both(LineTension):
    sim = svm.Simulation(device="cpu")
    sim.state = _state(replicas=3)
    vm = svm.plugins.forces.VertexModel.dimensionless(kr=1.0, p0=3.9)
    lt = LineTension(TENSION)
    sim.operations.forces.extend([vm, lt])
    forces, energy = sim.compute_forces()
    state = sim.state
    np.testing.assert_allclose(forces, vm.forces(state) + lt.forces(state), rtol=1e-14, atol=1e-14)
    np.testing.assert_allclose(energy, vm.energy(state) + lt.energy(state), rtol=1e-14)
    assert not np.allclose(lt.forces(state), 0.0)


def test_minimum_matches_the_shifted_target_perimeter(LineTension):
    """kP (P - P0)^2 + Lambda P / 2 has its minimum at P0 - Lambda / (4 kP): a fluid tissue gets there."""
    sim = svm.Simulation(device="cpu")
    sim.state = _state(n_cells=32, replicas=1, seed=0)
    p0, tension = 4.6, 0.4
    sim.operations.forces.extend([svm.plugins.forces.VertexModel.dimensionless(kr=1.0, p0=p0),
                                  LineTension(tension)])
    sim.operations.integrator = svm.plugins.integrators.FIRE(dt=0.05)
    sim.minimize(force_tol=1e-9, max_steps=5000)
    _, perimeter = svm.analysis.cell_shapes(sim.state)  # <A> = 1 at the default radius
    np.testing.assert_allclose(perimeter, p0 - tension / 4, rtol=1e-6)


def test_unknown_name_names_the_available_plugins(line_tension_path):
    with pytest.raises(ValueError) as info:
        plugins.load("no_such_plugin")
    msg = str(info.value)
    assert "no_such_plugin" in msg
    for name in ("vertex_model", "fire", "line_tension"):
        assert name in msg


def test_entry_point_to_a_non_plugin_class_is_refused(monkeypatch):
    monkeypatch.syspath_prepend(str(EXAMPLE / "broken"))
    monkeypatch.delitem(sys.modules, "spherevm_broken_plugin", raising=False)
    assert "not_a_plugin" in plugins.available()
    with pytest.raises(TypeError, match="not_a_plugin"):
        plugins.load("not_a_plugin")


def test_example_script_has_the_same_plugin(LineTension):
    """examples/line_tension_plugin.py defines the class inline: it must compute what the package does."""
    import importlib.util
    path = pathlib.Path(__file__).parent.parent / "examples" / "line_tension_plugin.py"
    spec = importlib.util.spec_from_file_location("_line_tension_example", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)   # defines things only; main() runs under __main__
    state = _state(replicas=2)
    a, b = module.LineTension(TENSION).compute(state), LineTension(TENSION).compute(state)
    for name in ("forces", "energy", "cell_energy"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name))


# ------------------------------------------------------------------ a misspelt keyword (issue 35.9)
def _first_parameter(cls):
    import inspect
    return next(p.name for p in inspect.signature(cls).parameters.values()
                if p.kind not in (p.VAR_POSITIONAL, p.VAR_KEYWORD))


@pytest.mark.parametrize("name", sorted(n for n, _, _ in plugins.describe()) + ["line_tension"])
def test_a_misspelt_keyword_names_the_nearest_parameter(name, line_tension_path):
    """Every registered plugin, the built-ins and a user's (line_tension): ``dtt=`` for ``dt=``."""
    cls = plugins.load(name)
    right = _first_parameter(cls)
    with pytest.raises(TypeError, match=rf"^{cls.__name__}\(\) got an unexpected keyword argument "
                                        rf"'{right + right[-1]}' \(did you mean '{right}'\?\); its parameters: "
                                        rf"{right}, "):
        cls(**{right + right[-1]: 1.0})


class _Tuned(svm.plugins.integrators.FIRE):
    """A user's subclass that keeps FIRE's constructor."""


class _Wrapping(svm.plugins.integrators.FIRE):
    """A user's integrator whose constructor passes a wrong keyword to its parent's."""

    def __init__(self, strength=1.0):
        super().__init__(dtt=0.1)


class _Open(svm.plugins.Updater):
    """A user's updater that takes any keyword: Python's own message stands."""

    def __init__(self, **options):
        super().__init__()
        self.options = dict(options)


def test_keyword_hints_name_the_class_at_fault():
    with pytest.raises(TypeError, match=r"^_Tuned\(\) got an unexpected keyword argument 'force_tolerance' "
                                        r"\(did you mean 'force_tol'\?\)"):
        _Tuned(force_tolerance=1e-8)
    with pytest.raises(TypeError, match=r"^FIRE\(\) got an unexpected keyword argument 'dtt' \(did you mean 'dt'\?\)"):
        _Wrapping(strength=2.0)              # the user's call was right: the parent's is named
    with pytest.raises(TypeError, match=r"^_Wrapping\(\) got an unexpected keyword argument 'strenght' "
                                        r"\(did you mean 'strength'\?\); its parameters: strength$"):
        _Wrapping(strenght=2.0)
    with pytest.raises(TypeError, match=r"^_Tuned\(\) got an unexpected keyword argument 'zzz'; its parameters"):
        _Tuned(zzz=1)                        # nothing near: no guess
    assert _Open(anything=1).options == {"anything": 1}
    with pytest.raises(TypeError, match=r"missing 1 required positional argument"):
        svm.plugins.forces.Bending.__init__()   # other TypeErrors pass through unchanged
