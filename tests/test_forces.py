"""VertexModel energies and forces against finite differences and analytic values."""
import numpy as np
import pytest
from conftest import finite_difference_forces, to_numpy

import spherevm as svm
from spherevm.plugins.forces import VertexModel


@pytest.mark.parametrize("model", [
    VertexModel.dimensionless(kr=1.0, p0=3.7),
    VertexModel.dimensionless(kr=0.0, p0=3.9),
    VertexModel(kA=0.7, kP=1.3, A0=1.2, P0=3.1),
])
def test_forces_match_finite_differences(tiling200, model, device):
    # finite differences on the CPU copy (NumPy in-place edits), forces on the device
    s = tiling200
    forces = to_numpy(model.forces(s.to(device)))
    rng = np.random.default_rng(0)
    verts = rng.choice(s.n_vertices, 25, replace=False)
    fd = finite_difference_forces(model, s, verts)
    scale = np.abs(forces).max()
    assert np.abs(fd - forces[verts]).max() <= 1e-6 * scale


def test_forces_are_tangent(tiling200, device):
    f = to_numpy(VertexModel.dimensionless(kr=1.0, p0=3.8).forces(tiling200.to(device)))
    radial = np.abs((f * tiling200.positions).sum(1)) / np.linalg.norm(tiling200.positions, axis=1)
    assert radial.max() <= 1e-12 * np.linalg.norm(f, axis=1).max()


def test_per_cell_parameters_match_scalar_ones(tiling200, device):
    s = tiling200.to(device)
    a = VertexModel(kA=0.5, kP=1.0, A0=1.0, P0=3.8)
    b = VertexModel(kA=np.full(s.n_cells, 0.5), kP=1.0, A0=np.ones(s.n_cells), P0=np.full(s.n_cells, 3.8))
    assert np.array_equal(to_numpy(a.forces(s)), to_numpy(b.forces(s)))
    with pytest.raises(ValueError, match="per-cell P0 has length 3"):
        VertexModel(P0=[1.0, 2.0, 3.0]).forces(s)


def test_energy_matches_definition_and_dimensionless_form(device):
    s = svm.init.random_tiling(100, replicas=2, seed=3, radius=2.5, device=device)
    area, perim = svm.analysis.cell_shapes(s)
    mean_a = 4 * np.pi * 2.5 ** 2 / 100
    kr, p0 = 0.8, 3.75
    model = VertexModel.dimensionless(kr=kr, p0=p0)
    e = to_numpy(model.energy(s))
    a, p = area / mean_a, perim / np.sqrt(mean_a)
    per_cell = mean_a * (kr * (a - 1) ** 2 + (p - p0) ** 2)
    assert np.allclose(e, [per_cell[:100].sum(), per_cell[100:].sum()], rtol=1e-12)
    direct = VertexModel(kA=kr / mean_a, kP=1.0, A0=mean_a, P0=p0 * np.sqrt(mean_a))
    assert np.allclose(to_numpy(direct.energy(s)), e, rtol=1e-12)


def test_regular_tiling_at_its_own_shape_has_zero_energy_and_force(device):
    s = svm.init.regular_tiling("dodecahedron", device=device)
    area, perim = svm.analysis.cell_shapes(s)
    model = VertexModel(kA=1.0, kP=1.0, A0=area[0], P0=perim[0])
    assert to_numpy(model.energy(s))[0] < 1e-28
    assert np.abs(to_numpy(model.forces(s))).max() < 1e-13


def test_symmetric_tiling_forces_vanish_by_symmetry(device):
    # each dodecahedron vertex has a three-fold axis through it: no tangent force for any parameters
    s = svm.init.regular_tiling("dodecahedron", device=device)
    f = to_numpy(VertexModel.dimensionless(kr=1.0, p0=3.0).forces(s))
    assert np.abs(f).max() < 1e-13
    # truncated icosahedron vertices only have a mirror plane: forces lie in it, with equal size
    s = svm.init.regular_tiling("truncated_icosahedron", device=device)
    f = to_numpy(VertexModel.dimensionless(kr=1.0, p0=3.0).forces(s))
    mag = np.linalg.norm(f, axis=1)
    assert mag.min() > 1e-3                       # not zero by accident: the check below has content
    assert np.ptp(mag) < 1e-12 * mag.max()
    # the mirror plane of a vertex holds the centre, the vertex and the centre of its pentagon
    x = to_numpy(s.positions)
    cells, sides = to_numpy(s.vertex_cells), to_numpy(s.cell_sides)
    cv = to_numpy(s.cell_vertices)
    pent = np.array([[c for c in row if c >= 0 and sides[c] == 5][0] for row in cells])
    centre = np.array([x[cv[c, :5]].mean(axis=0) for c in pent])
    normal = np.cross(x, centre)
    normal /= np.linalg.norm(normal, axis=1)[:, None]
    assert np.abs((f * normal).sum(axis=1)).max() < 1e-12 * mag.max()
    # and in the tangent plane
    assert np.abs((f * x).sum(axis=1)).max() < 1e-12 * mag.max() * np.linalg.norm(x, axis=1).max()


def test_replicas_are_independent(device):
    ens = svm.init.random_tiling(60, replicas=3, seed=8, device=device)
    model = VertexModel.dimensionless(kr=1.0, p0=3.8)
    f_all, e_all = to_numpy(model.forces(ens)), to_numpy(model.energy(ens))
    for r in range(3):
        one = ens.replica(r)
        v0, v1 = ens.vertex_start[r], ens.vertex_start[r + 1]
        assert np.array_equal(to_numpy(model.forces(one)), f_all[v0:v1])
        assert np.isclose(to_numpy(model.energy(one))[0], e_all[r], rtol=1e-14)


@pytest.mark.parametrize("kw", [dict(kA=-1), dict(kP=float("nan")), dict(P0=-3.0), dict(A0=[[1.0]])])
def test_bad_parameters(kw):
    with pytest.raises(ValueError, match=list(kw)[0]):
        VertexModel(**kw)


def test_threaded_blocks_give_the_same_forces(monkeypatch):
    # CPU only: large NumPy states are split into per-core vertex blocks: the result must not change
    import spherevm.constraints.corners as corners
    s = svm.init.random_tiling(500, replicas=2, seed=21)
    model = VertexModel.dimensionless(kr=0.7, p0=3.7)
    one = model.compute(s)
    monkeypatch.setattr(corners, "PARALLEL_MIN_VERTICES", 10)
    monkeypatch.setattr(corners.os, "cpu_count", lambda: 3)
    s.topology_changed()
    many = model.compute(s)
    assert len(corners.blocks(s, s.n_vertices)) == 3
    assert np.allclose(many.forces, one.forces, rtol=0, atol=1e-13 * np.abs(one.forces).max())
    assert np.allclose(many.energy, one.energy, rtol=1e-14)


def test_allocator_thresholds_are_fixed_unless_asked_not_to():
    # spherevm.device.tune_allocator: on glibc the NumPy path keeps freed memory for reuse
    import ctypes
    import os
    import subprocess
    import sys
    try:
        ctypes.CDLL("libc.so.6").mallopt
    except (OSError, AttributeError):
        pytest.skip("not glibc")
    assert svm.device.ALLOCATOR_TUNED
    code = "import spherevm; print(spherevm.device.ALLOCATOR_TUNED)"
    package_root = os.path.dirname(os.path.dirname(svm.__file__))      # this spherevm, not an installed one
    env = dict(os.environ, SPHEREVM_MALLOC="system", PYTHONPATH=package_root)
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True).stdout
    assert out.strip() == "False"
