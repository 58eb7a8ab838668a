"""spherevm.testing.check_force on the built-in VertexModel, the example line-tension plugin, and
planted wrong forces that it must catch (naming the worst vertex)."""
import pathlib

import numpy as np
import pytest

import spherevm as svm
from spherevm.plugins import Force, ForceResult
from spherevm.plugins.forces import VertexModel
from spherevm.testing import ForceCheck, assert_force_ok, check_force

EXAMPLE = pathlib.Path(__file__).parent / "plugin_example"


def sphere(device="cpu"):
    return svm.init.random_tiling(40, replicas=3, seed=4, device=device)


def plane():
    return svm.init_plane.random_planar_tiling(30, replicas=2, seed=5)


@pytest.mark.parametrize("params", [dict(kr=0.0, p0=3.6), dict(kr=1.0, p0=3.8), dict(kr=10.0, p0=4.2, a0=0.8),
                                    dict(kr=0.5, p0=3.0, kP=2.0)])
def test_vertex_model_sphere(params, device):
    report = check_force(VertexModel.dimensionless(**params), sphere(device))
    report.assert_ok()
    assert report.cell_energy_error < 1e-12 and report.replica_leak == 0.0
    assert report.worst_derivative["relative"] < 1e-8          # far below the default rtol 1e-6


def test_vertex_model_raw_parameters_and_per_cell():
    state = sphere()
    kA = np.linspace(0.5, 2.0, state.n_cells)
    assert_force_ok(VertexModel(kA=kA, kP=1.3, A0=0.9, P0=3.5), state, samples=4)


@pytest.mark.parametrize("params", [dict(kr=1.0, p0=3.8), dict(kr=0.0, p0=3.4)])
def test_vertex_model_plane(params):
    report = assert_force_ok(VertexModel.dimensionless(**params), plane())
    assert report.worst_tangency["normal"] == 0.0


def test_line_tension_plugin(monkeypatch):
    monkeypatch.syspath_prepend(str(EXAMPLE))
    from spherevm_line_tension import LineTension
    assert_force_ok(LineTension(0.7), sphere())
    assert_force_ok(LineTension(0.7), svm.init.random_tiling(64, replicas=2, seed=9), samples=16)


class Planted(Force):
    """A VertexModel with a planted error: forces scaled, or one component of one vertex flipped."""

    def __init__(self, scale=1.0, flip=None, radial=0.0):
        super().__init__()
        self.inner, self.scale, self.flip, self.radial = VertexModel.dimensionless(kr=1.0, p0=3.7), scale, flip, radial

    def compute(self, state):
        r = self.inner.compute(state)
        f = r.forces * self.scale
        if self.flip is not None:
            f = f.copy()
            f[self.flip] = f[self.flip] - 2 * (f[self.flip] @ np.array([1.0, 0, 0])) * np.array([1.0, 0, 0])
        if self.radial:
            f = f + self.radial * state.positions
        return ForceResult(f, r.energy, r.cell_energy)

    def __repr__(self):
        return f"Planted(scale={self.scale}, flip={self.flip})"


def test_catches_scaled_forces():
    report = check_force(Planted(scale=1.01), sphere())
    assert not report.ok and isinstance(report, ForceCheck)
    assert 0.005 < report.worst_derivative["relative"] < 0.02
    with pytest.raises(AssertionError, match="worst derivative: vertex"):
        report.assert_ok()


def test_catches_a_sign_flip_and_names_the_vertex():
    state = sphere()
    vrep = state.vertex_replica_np()
    bad = int(np.flatnonzero(vrep == 1)[7])
    # sample every vertex of replica 1 with enough draws that the flipped one is hit
    report = check_force(Planted(flip=bad), state, samples=200)
    assert not report.ok
    assert report.worst_derivative["vertex"] == bad and report.worst_derivative["replica"] == 1
    with pytest.raises(AssertionError, match=f"vertex {bad} \\(replica 1"):
        report.assert_ok()


def test_catches_a_normal_part():
    report = check_force(Planted(radial=1e-6), sphere())
    assert not report.ok and any("normal part" in f for f in report.failures)


def test_catches_wrong_cell_energies_and_leaks():
    class Bad(Planted):
        def compute(self, state):
            r = self.inner.compute(state)
            e = r.energy + 1e-3 * state.positions[0, 0]             # replica 0's vertex 0 leaks into all
            return ForceResult(r.forces, e, r.cell_energy)
    report = check_force(Bad(), sphere(), samples=2)
    text = str(report)
    assert "per-cell energies of replica" in text and "replicas must be independent" in text


def test_restores_positions():
    state = sphere()
    before = state.positions.copy()
    check_force(Planted(scale=2.0), state, samples=2)
    assert np.array_equal(state.positions, before)
