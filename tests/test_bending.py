"""Bending between neighbouring cells, E_b = B sum_pairs (1 - n_i.n_j) (issue 12).

Known answers on the regular dodecahedron and truncated icosahedron (derived below from an
icosahedron built here, not from spherevm.init), finite-difference forces, the small-cell limit,
symmetries (rotation, torque), per-replica B, the plane, bad input, and CPU/GPU parity.
"""
import pathlib
import tomllib

import numpy as np
import pytest

import spherevm as svm
from conftest import to_numpy
from spherevm.plugins.forces import Bending, VertexModel, cell_normals
from spherevm.plugins.forces.bending import cell_area_vectors, neighbor_pairs

PHI = (1 + 5 ** 0.5) / 2


def _icosahedron():
    """The 12 unit vertices and 20 faces of an icosahedron, from the golden-ratio rectangles."""
    v = []
    for s1 in (-1, 1):
        for s2 in (-1, 1):
            v += [(0, s1, s2 * PHI), (s1, s2 * PHI, 0), (s2 * PHI, 0, s1)]
    v = np.array(v, dtype=float)
    v /= np.linalg.norm(v, axis=1)[:, None]
    d = np.linalg.norm(v[:, None] - v[None], axis=2)
    edge = d[d > 1e-9].min()
    adj = np.abs(d - edge) < 1e-9
    faces = [(i, j, k) for i in range(12) for j in range(i + 1, 12) for k in range(j + 1, 12)
             if adj[i, j] and adj[j, k] and adj[i, k]]
    return v, adj, faces


def _expected_dodecahedron():
    # Dodecahedron face normals = icosahedron vertex directions; adjacent faces <-> icosahedron
    # edges (30). n_i.n_j = cos of the angle between adjacent icosahedron vertices = 1/sqrt(5).
    v, adj, _ = _icosahedron()
    dots = (v @ v.T)[np.triu(adj)]
    assert len(dots) == 30 and np.allclose(dots, 1 / 5 ** 0.5)
    return 30 * (1 - 1 / 5 ** 0.5)


def _expected_truncated_icosahedron():
    # Pentagon normals = icosahedron vertices u, hexagon normals = icosahedron face normals f
    # (normalised face centroids). Hexagon-hexagon edges (30) <-> faces sharing an edge:
    # f.f' = sqrt(5)/3 (the icosahedron's dihedral angle is arccos(-sqrt5/3)). Hexagon-pentagon
    # edges (60) <-> vertex in face: u.f = inradius / circumradius = sqrt((5 + 2 sqrt5) / 15).
    v, adj, faces = _icosahedron()
    f = np.array([v[list(t)].mean(axis=0) for t in faces])
    f /= np.linalg.norm(f, axis=1)[:, None]
    hh = [f[a] @ f[b] for a in range(20) for b in range(a + 1, 20) if len(set(faces[a]) & set(faces[b])) == 2]
    hp = [v[i] @ f[a] for a in range(20) for i in faces[a]]
    assert len(hh) == 30 and np.allclose(hh, 5 ** 0.5 / 3)
    assert len(hp) == 60 and np.allclose(hp, ((5 + 2 * 5 ** 0.5) / 15) ** 0.5)
    return 30 * (1 - 5 ** 0.5 / 3) + 60 * (1 - ((5 + 2 * 5 ** 0.5) / 15) ** 0.5)


def _rel(a, b):
    return np.abs(a - b).max() / max(np.abs(b).max(), 1e-300)


# ------------------------------------------------------------------ known answers
@pytest.mark.parametrize("name, expected, n_pairs", [("dodecahedron", _expected_dodecahedron(), 30),
                                                     ("truncated_icosahedron", _expected_truncated_icosahedron(), 90)])
@pytest.mark.parametrize("B", [1.0, 0.37])
def test_regular_polyhedra_known_energy(name, expected, n_pairs, B, device):
    s = svm.init.regular_tiling(name, radius=1.7, device=device)
    assert len(to_numpy(neighbor_pairs(s))) == n_pairs
    r = Bending(B).compute(s)
    assert abs(to_numpy(r.energy)[0] - B * expected) <= 1e-13 * B * expected
    assert abs(to_numpy(r.cell_energy).sum() - B * expected) <= 1e-13 * B * expected
    # regular faces: forces vanish by symmetry (the energy scale is B ~ 1)
    assert np.abs(to_numpy(r.forces)).max() <= 1e-13


def test_regular_faces_normal_is_the_radial_direction_at_their_centre():
    s = svm.init.regular_tiling("truncated_icosahedron", radius=3.0)
    n = cell_normals(s)
    centre = s.constraint.cell_centers(s)          # normalised vertex centroid: exact for regular faces
    assert np.abs(n - centre).max() <= 1e-14
    # the area vector's length is the flat face's area: pentagons and hexagons of edge a
    a = np.linalg.norm(cell_area_vectors(s), axis=1)
    edge = np.linalg.norm(s.positions[s.cell_vertices[:, 0]] - s.positions[s.cell_vertices[:, 1]], axis=1)
    flat = np.where(s.cell_sides == 5, np.sqrt(25 + 10 * 5 ** 0.5) / 4, 3 * 3 ** 0.5 / 2) * edge ** 2
    assert _rel(a, flat) <= 1e-13


# ------------------------------------------------------------------ forces
@pytest.mark.parametrize("B", [0.01, 0.3, 2.0])
def test_forces_match_finite_differences(B, device):
    s = svm.init.random_tiling(150, replicas=2, seed=4, radius=3.2)
    force = Bending(B)
    F = to_numpy(force.forces(s.to(device)))
    rng = np.random.default_rng(1)
    verts = rng.choice(s.n_vertices, 10, replace=False)
    h = 1e-6
    for v in verts:
        x = s.positions[v].copy()
        n = x / np.linalg.norm(x)
        t1 = np.cross(n, [0.3, -0.5, 0.8])
        t1 /= np.linalg.norm(t1)
        for t in (t1, np.cross(n, t1)):        # two tangent directions
            s.positions[v] = x + h * t
            ep = force.energy(s).sum()
            s.positions[v] = x - h * t
            em = force.energy(s).sum()
            s.positions[v] = x
            assert abs(-(ep - em) / (2 * h) - F[v] @ t) <= 1e-6 * np.abs(F).max()


def test_forces_are_tangent_and_torque_free(device):
    s = svm.State.concatenate([svm.init.random_tiling(300, seed=9 + i, radius=R) for i, R in enumerate((2.0, 4.0, 5.0))],
                              device=device)
    r = Bending([0.2, 1.0, 3.0]).compute(s)
    F, x = to_numpy(r.forces), to_numpy(s.positions)
    radial = np.abs((F * x).sum(axis=1)) / np.linalg.norm(x, axis=1)
    assert np.all(radial <= 1e-12 * np.abs(F).max())
    rep = to_numpy(s.vertex_replica)
    torque = np.stack([np.bincount(rep, weights=c) for c in np.cross(x, F).T], axis=1)
    scale = np.bincount(rep, weights=np.linalg.norm(x, axis=1) * np.linalg.norm(F, axis=1))
    assert np.all(np.abs(torque).max(axis=1) <= 1e-12 * scale)
    assert np.abs(F).max() > 1e-3                  # not trivially zero


def test_rotation_invariance():
    s = svm.init.random_tiling(400, seed=2, radius=5.0)
    q, _ = np.linalg.qr(np.random.default_rng(3).normal(size=(3, 3)))
    if np.linalg.det(q) < 0:
        q[:, 0] *= -1
    r0 = Bending(0.7).compute(s)
    s2 = s.copy()
    s2.positions = s.positions @ q.T
    r1 = Bending(0.7).compute(s2)
    assert _rel(r1.energy, r0.energy) <= 1e-12
    assert _rel(r1.cell_energy, r0.cell_energy) <= 1e-11
    assert _rel(r1.forces, r0.forces @ q.T) <= 1e-10


def test_cell_energies_sum_to_total_and_per_replica_B(device):
    s = svm.init.random_tiling(120, replicas=3, seed=5, device=device)
    one = Bending(1.0).compute(s)
    B = np.array([0.0, 0.5, 2.0])
    r = Bending(B).compute(s)
    e1, e = to_numpy(one.energy), to_numpy(r.energy)
    assert _rel(e, B * e1) <= 1e-14
    per_cell = np.bincount(to_numpy(s.cell_replica), weights=to_numpy(r.cell_energy), minlength=3)
    assert _rel(per_cell, e) <= 1e-13
    F, F1, rep = to_numpy(r.forces), to_numpy(one.forces), to_numpy(s.vertex_replica)
    assert np.all(F[rep == 0] == 0)
    assert _rel(F, B[rep][:, None] * F1) <= 1e-14
    assert e1.min() > 0


def test_small_cell_limit():
    """E_b = B sum (1 - cos theta_ij) against (B / 2R^2) sum r_ij^2, r_ij = R theta_ij the geodesic
    distance between the cells' centres R n_i. 1 - cos t = t^2/2 (1 - t^2/12 + ...), so the ratio
    lies in [1 - max t^2/12, 1]: with N = 2000 cells, t ~ sqrt(4 pi / N) ~ 0.08, about 1e-3.
    With the normalised vertex centroids as centres the ratio is only O(1) close (the two centres
    differ by a fraction of a cell), which the second check bounds loosely."""
    R = 4.0
    s = svm.init.random_tiling(2000, seed=7, radius=R)
    B = 0.3
    E = Bending(B).energy(s)[0]
    n = cell_normals(s)
    p = neighbor_pairs(s)
    r = R * np.arccos(np.clip((n[p[:, 0]] * n[p[:, 1]]).sum(axis=1), -1, 1))
    approx = B / (2 * R ** 2) * (r ** 2).sum()
    tmax = (r / R).max()
    assert 1 - tmax ** 2 / 12 <= E / approx <= 1 + 1e-10
    assert E / approx < 1 - 1e-5                   # and the quartic correction is seen
    c = s.constraint.cell_centers(s)
    rc = R * np.arccos(np.clip((c[p[:, 0]] * c[p[:, 1]]).sum(axis=1), -1, 1))
    assert 0.7 <= E / (B / (2 * R ** 2) * (rc ** 2).sum()) <= 1.3


def test_topology_cache_follows_t1_flips():
    s = svm.init.random_tiling(100, seed=6)
    force = Bending(0.5)
    force.compute(s)                                # fills the cache
    lengths = s.constraint.edge_lengths(s, np.arange(s.n_vertices), s.vertex_neighbors[:, 0])
    u = int(np.argmin(lengths))
    svm.topology.t1_flip(s, np.array([u]), np.array([0]), 0.05)
    s.topology_changed()
    fresh = s.copy()
    a, b = force.compute(s), Bending(0.5).compute(fresh)
    assert np.array_equal(neighbor_pairs(s), neighbor_pairs(fresh))
    assert _rel(a.forces, b.forces) <= 1e-15 and _rel(a.energy, b.energy) <= 1e-15


def test_blocks_of_cells_on_all_cores_match_one_block_and_per_corner_sums(monkeypatch):
    """A tiling large enough for the NumPy path's blocks (of vertices and of cells, on a thread
    pool) against the same State in one block; the area vectors against a plain per-corner sum."""
    s = svm.init.random_tiling(17000, seed=3, radius=3.0)
    from spherevm.constraints import cell_rows, corners
    assert len(cell_rows.cell_blocks(s)) > 1 and len(corners.corner_index(s)) > 1
    vm, bend = VertexModel.dimensionless(kr=1.0, p0=3.8), Bending(0.7)
    blocked, alone = bend.combined(vm, s), bend.compute(s)
    a = cell_area_vectors(s)
    x, vc, vn, first = s.positions, s.vertex_cells, s.vertex_neighbors, s.cell_vertices[:, 0]
    corner = 0.5 * np.cross(x[:, None] - x[first[vc]], x[vn] - x[:, None])
    ref = np.zeros((s.n_cells, 3))
    np.add.at(ref, vc.reshape(-1), corner.reshape(-1, 3))
    assert _rel(a, ref) <= 1e-13
    monkeypatch.setattr(corners, "PARALLEL_MIN_VERTICES", 10 ** 9)
    one = s.copy()
    assert len(cell_rows.cell_blocks(one)) == 1 and len(corners.corner_index(one)) == 1
    for r, ref in ((blocked, bend.combined(vm, one)), (alone, bend.compute(one))):
        assert _rel(r.forces, ref.forces) <= 1e-13 and _rel(r.cell_energy, ref.cell_energy) <= 1e-13
        assert _rel(r.energy, ref.energy) <= 1e-14


def test_in_a_simulation_with_the_vertex_model():
    sim = svm.Simulation(device="cpu")
    sim.state = svm.init.random_tiling(64, replicas=2, seed=5)
    vm, bend = VertexModel.dimensionless(kr=1.0, p0=3.7), Bending([0.1, 1.0])
    sim.operations.forces.extend([vm, bend])
    total = to_numpy(vm.forces(sim.state)) + to_numpy(bend.forces(sim.state))
    forces, energy = sim.compute_forces()
    assert _rel(to_numpy(forces), total) <= 1e-14
    assert _rel(to_numpy(energy), vm.energy(sim.state) + bend.energy(sim.state)) <= 1e-14
    e0 = to_numpy(energy)
    sim.minimize(force_tol=1e-8, max_steps=500)
    forces, energy = sim.compute_forces()
    assert np.all(to_numpy(energy) < e0)
    assert "bending_energy" in sim.loggables


def test_vertex_model_and_bending_together_in_one_pass():
    """Bending.combined (one cell_geometry, one shape_gradient) against the two forces apart; the
    Simulation pairs them whatever their order and leaves other forces alone."""
    s = svm.init.random_tiling(300, replicas=2, seed=8, radius=2.5)
    vm, bend = VertexModel.dimensionless(kr=0.9, p0=3.75), Bending([0.3, 2.0])
    a, b = vm.compute(s), bend.compute(s)
    both = bend.combined(vm, s)
    assert _rel(both.forces, a.forces + b.forces) <= 1e-14
    assert _rel(both.energy, a.energy + b.energy) <= 1e-14
    assert _rel(both.cell_energy, a.cell_energy + b.cell_energy) <= 1e-14
    assert vm.combined(bend, s) is None and bend.combined(Bending(1.0), s) is None
    assert bend.combined(type("MyModel", (VertexModel,), {})(), s) is None      # a subclass may differ
    from spherevm.plugins.base import compute_all
    other = VertexModel(kA=0.0, kP=0.2, A0=0.0, P0=1.0)
    results = compute_all([vm, other, bend], s)
    assert len(results) == 2
    assert np.array_equal(results[0].forces, both.forces) and np.array_equal(results[1].forces, other.compute(s).forces)
    sim = svm.Simulation(device="cpu")
    sim.state = s
    sim.operations.forces.extend([bend, vm])
    forces, energy = sim.compute_forces()
    assert np.array_equal(forces, both.forces) and np.array_equal(energy, both.energy)


# ------------------------------------------------------------------ the plane
def test_plane_gives_zero_energy_and_force():
    s = svm.init.random_planar_tiling(64, replicas=2, seed=3)
    r = Bending(1.0).compute(s)
    assert np.all(r.energy == 0) and np.all(r.cell_energy == 0) and np.all(r.forces == 0)
    n = cell_normals(s)
    assert np.array_equal(n, np.tile([0.0, 0.0, 1.0], (s.n_cells, 1)))
    # with the vertex model, in one pass: exactly the vertex model's forces and energies
    vm = VertexModel.dimensionless(kr=1.0, p0=3.7)
    both, alone = Bending(1.0).combined(vm, s), vm.compute(s)
    assert np.array_equal(both.forces, alone.forces) and np.array_equal(both.energy, alone.energy)
    # area vectors through minimum images: their lengths are the cell areas
    assert _rel(cell_area_vectors(s)[:, 2], s.constraint.cell_geometry(s).area) <= 1e-12


# ------------------------------------------------------------------ bad input
@pytest.mark.parametrize("B", [-0.1, np.nan, np.inf, [0.1, -1.0], [[0.1]], "x", []])
def test_bad_B_is_refused(B):
    with pytest.raises(ValueError, match="B"):
        Bending(B)


def test_wrong_length_per_replica_B_is_refused_before_anything_runs():
    sim = svm.Simulation(device="cpu")
    sim.state = svm.init.random_tiling(40, replicas=2, seed=1)
    force = Bending([0.1, 0.2, 0.3])
    with pytest.raises(ValueError, match="per-replica B has length 3.*2 replicas"):
        sim.operations.forces.append(force)
    with pytest.raises(ValueError, match="B"):
        force.compute(sim.state)


def test_registered_as_a_built_in_entry_point():
    data = tomllib.loads((pathlib.Path(__file__).parent.parent / "pyproject.toml").read_text())
    assert data["project"]["entry-points"]["spherevm.plugins"]["bending"] == "spherevm.plugins.forces:Bending"


# ------------------------------------------------------------------ GPU parity
@pytest.mark.gpu
@pytest.mark.parametrize("n_cells, replicas", [(200, 1), (64, 16), (1000, 3)])
@pytest.mark.parametrize("per_replica", [False, True])
def test_gpu_matches_numpy(n_cells, replicas, per_replica):
    cpu = svm.init.random_tiling(n_cells, replicas=replicas, seed=n_cells)
    B = np.linspace(0.05, 2.0, replicas) if per_replica else 0.4
    force = Bending(B)
    rc, rg = force.compute(cpu), force.compute(cpu.to("gpu"))
    assert _rel(rg.forces.get(), rc.forces) <= 1e-12
    assert _rel(rg.energy.get(), rc.energy) <= 1e-12
    assert _rel(rg.cell_energy.get(), rc.cell_energy) <= 1e-12


@pytest.mark.gpu
@pytest.mark.parametrize("n_cells, replicas", [(200, 1), (64, 16), (1000, 3)])
def test_gpu_vertex_model_with_bending_fused_matches_numpy(n_cells, replicas):
    """The fused kernels (vertex_model.cuh with bending's terms) against the NumPy path, and the
    GPU Simulation taking them."""
    cpu = svm.init.random_tiling(n_cells, replicas=replicas, seed=n_cells + 1)
    vm, force = VertexModel.dimensionless(kr=0.8, p0=3.7), Bending(np.linspace(0.5, 2.0, replicas))
    rc = force.combined(vm, cpu)
    gpu = cpu.to("gpu")
    rg = force.combined(vm, gpu)
    assert _rel(rg.forces.get(), rc.forces) <= 1e-12
    assert _rel(rg.energy.get(), rc.energy) <= 1e-12
    assert _rel(rg.cell_energy.get(), rc.cell_energy) <= 1e-12
    sim = svm.Simulation(device="gpu")
    sim.state = gpu
    sim.operations.forces.extend([vm, force])
    forces, energy = sim.compute_forces()
    assert _rel(forces.get(), rc.forces) <= 1e-12 and _rel(energy.get(), rc.energy) <= 1e-12


@pytest.mark.gpu
@pytest.mark.parametrize("surface", ["plane", "flat sphere"])
def test_gpu_refuses_surfaces_without_bending_kernels(surface):
    """The plane, and the sphere measured with the flat metric: the kernels compute the geodesic sphere's."""
    sim = svm.Simulation(device="gpu")
    if surface == "plane":
        sim.state = svm.init.random_planar_tiling(64, seed=3, device="gpu")
    else:
        state = svm.init.random_tiling(64, seed=3, device="gpu")
        state.constraint = svm.constraints.Sphere(metric="flat")
        sim.state = state
    with pytest.raises(ValueError, match="Bending on the GPU supports GeodesicSphere, ImplicitSurface surfaces only"):
        sim.operations.forces.append(Bending(1.0))


# ------------------------------------------------------------------ the command line
from spherevm import cli, sweeps  # noqa: E402
from spherevm.cli import rigidity as rigidity_cli  # noqa: E402


def _energy_rows(text):
    lines = [ln.split() for ln in text.splitlines() if ln.strip()]
    assert lines[0][0] == "replica"
    return np.array([float(r[1]) for r in lines[1:]])


def test_cli_bending_shorthand_and_force_option_agree_and_change_the_result(capsys):
    base = ["minimize", "-N", "32", "-R", "2", "--max-steps", "200", "--device", "cpu", "-q", "--seed", "3"]
    outs = []
    for extra in ([], ["--bending", "0.5"], ["--force", "bending:B=0.5"]):
        assert cli.main(base + extra) == 0
        outs.append(_energy_rows(capsys.readouterr().out))
    assert np.array_equal(outs[1], outs[2])
    assert not np.allclose(outs[0], outs[1])


@pytest.mark.parametrize("argv, words", [
    (["--force", "bending:B=-1"], ["bending", "B", ">= 0"]),
    (["--force", "bending:C=1"], ["bending", "'C'", "B"]),
    (["--force", "bending:B"], ["bending", "key=value"]),
    (["--force", "no_such_force:x=1"], ["no_such_force"]),
    (["--force", "fire:dt=0.1"], ["fire", "not a force"]),
    (["--bending", "-0.5"], ["--bending"]),
])
@pytest.mark.parametrize("command", ["minimize", "dynamics"])
def test_cli_bad_forces_give_one_line_naming_plugin_and_parameter(command, argv, words, capsys):
    rc = cli.main([command, "-N", "16", "-R", "1", "--device", "cpu", "-q"] + argv)
    captured = capsys.readouterr()
    assert rc == 2 and captured.out == ""
    lines = captured.err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("spherevm: error: ") and "Traceback" not in captured.err
    for w in words:
        assert w in lines[0], lines[0]


def test_cli_plugins_lists_force_parameters(capsys):
    assert cli.main(["plugins"]) == 0
    out = capsys.readouterr().out
    assert "parameters: kA=1.0, kP=1.0, A0=1.0, P0=3.8" in out


def test_rigidity_sweep_carries_forces_in_its_manifest(tmp_path, capsys):
    plain = sweeps.RigiditySweep(cells=[16], p0=[3.8], replicas=1, max_steps=300)
    assert "forces" not in plain.parameters()                   # old manifests still match
    with_b = sweeps.RigiditySweep(cells=[16], p0=[3.8], replicas=1, max_steps=300, forces=[("bending", {"B": 0.2})])
    assert with_b.parameters()["forces"] == [["bending", {"B": 0.2}]]
    assert sweeps.RigiditySweep.from_parameters(with_b.parameters()) == with_b
    with pytest.raises(ValueError, match="bending.*B"):
        sweeps.RigiditySweep(cells=[16], p0=[3.8], replicas=1, max_steps=300, forces=[("bending", {"B": -1})])
    # the chunk adds the force: energies differ from the plain sweep's, same tilings
    from spherevm.sweeps.execution import run_chunk
    a = run_chunk(plain.parameters(), 16, 0, 1)
    b = run_chunk(with_b.parameters(), 16, 0, 1)
    assert a["tiling_seed"] == b["tiling_seed"]
    assert a["energy_per_cell"] != b["energy_per_cell"]
    # and from the command line, into the folder's manifest
    out = tmp_path / "sweep"
    args = cli.build_parser().parse_args(["rigidity", "--cells", "16", "--p0", "3.8", "3.9", "--replicas", "1",
                                          "--device", "cpu", "--workers", "1", "--bending", "0.2", "--no-plots", "--max-steps", "300",
                                          "-q", "--out", str(out)])
    assert rigidity_cli.sweep_from_args(args).forces == (("bending", (("B", 0.2),)),)
    assert args.func(args) == 0
    import json
    assert json.loads((out / "manifest.json").read_text())["parameters"]["forces"] == [["bending", {"B": 0.2}]]


# ------------------------------------------------------------------ the study (examples/bending_glassy.py)
def _example():
    import importlib.util
    path = pathlib.Path(__file__).parent.parent / "examples" / "bending_glassy.py"
    spec = importlib.util.spec_from_file_location("bending_glassy", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_study_fit_tells_arrhenius_from_sub_and_super_arrhenius():
    ex = _example()
    T = np.array([0.008, 0.01, 0.0125, 0.015, 0.02, 0.025, 0.03, 0.04])
    rng = np.random.default_rng(0)
    noise = 0.02 * rng.normal(size=len(T))
    for c, word in ((0.0, "consistent with Arrhenius"), (-2e-4, "sub-Arrhenius"), (2e-4, "super-Arrhenius")):
        fit = ex.fit_log_tau(T, 1.0 + 0.05 / T + c / T ** 2 + noise)
        assert ex.verdict(fit).startswith(word)
        assert abs(fit["quadratic"]["coef"][2] - c) < 5 * fit["quadratic"]["err"][2] + 1e-12


def test_study_runs_one_ensemble_per_size_and_writes_its_results(tmp_path, capsys):
    ex = _example()
    out = tmp_path / "bg"
    ex.main(["--cells", "32", "--B", "0", "0.1", "--T", "0.02", "0.01", "--replicas", "2", "--steps", "100",
             "--relax", "200", "--device", "cpu", "--out", str(out)])
    import json
    rows = json.loads(out.with_suffix(".json").read_text())
    assert [(r["N"], r["B"]) for r in rows] == [(32, 0.0), (32, 0.1)]
    for r in rows:
        assert r["T"] == [0.01, 0.02] and np.array(r["tau"]).shape == (2, 2)
        assert len(r["msd_lowest_T"]["msd"]) == len(r["msd_lowest_T"]["lag"]) and r["msd_lowest_T"]["T"] == 0.01
    text = capsys.readouterr().out
    assert "N=32 production: 100/100 steps" in text and "N=32 B=0.1:" in text
