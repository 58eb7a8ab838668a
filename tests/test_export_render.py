"""Meshes through trimesh (spherevm export) and pictures through matplotlib (spherevm render)."""
import numpy as np
import pytest

import spherevm as svm
from spherevm.cli import main
from spherevm.export import cell_mesh, export_gsd

trimesh = pytest.importorskip("trimesh")


@pytest.fixture(scope="module")
def gsd_file(tmp_path_factory):
    path = tmp_path_factory.mktemp("export") / "run.gsd"
    sim = svm.Simulation(device="cpu")
    sim.state = svm.init.random_tiling(30, replicas=2, seed=3)
    sim.operations.forces.append(svm.plugins.forces.VertexModel.dimensionless(kr=1.0, p0=3.8))
    sim.operations.integrator = svm.plugins.integrators.FIRE(dt=0.02)
    sim.operations.writers.append(svm.plugins.writers.GSD(50, str(path)))
    sim.run(100)
    sim.operations.writers[0].close()
    return path


@pytest.mark.parametrize("n", [1, 2, 4, 8])
def test_mesh_faces_and_area(n):
    state = svm.init.random_tiling(30, replicas=2, seed=3)
    mesh = cell_mesh(state, subdivisions=n, replica=1)
    sides = state.cell_sides[state.cell_replica_np() == 1]
    assert len(mesh.faces) == sides.sum() * n * n
    R = state.radius_np()[1]
    # flat triangles of size ~ sqrt(<A>)/n on a sphere of radius R miss ~ (size/R)^2 / 12 of the area
    rel = 1 - mesh.area / (4 * np.pi * R ** 2)
    assert 0 < rel < 0.25 * (1 / np.sqrt(30 / (4 * np.pi)) / n) ** 2 * 4
    assert np.allclose(np.linalg.norm(mesh.vertices, axis=1), R)
    assert mesh.is_winding_consistent is not False and mesh.volume > 0     # outward normals


def test_area_converges():
    state = svm.init.random_tiling(30, seed=3)
    errs = [abs(1 - cell_mesh(state, subdivisions=n).area / (4 * np.pi * state.radius_np()[0] ** 2)) for n in (2, 4, 8)]
    assert errs[1] < errs[0] / 3.5 and errs[2] < errs[1] / 3.5                # second order


@pytest.mark.parametrize("ext", ["ply", "obj", "glb"])
def test_files_load_back(gsd_file, tmp_path, ext):
    out = tmp_path / f"cells.{ext}"
    assert main(["export", str(gsd_file), "--to", str(out), "--replica", "0", "--subdivisions", "2"]) == 0
    mesh = trimesh.load(out, force="mesh")
    state = svm.init.from_gsd(gsd_file)
    sides = state.cell_sides[state.cell_replica_np() == 0]
    assert len(mesh.faces) == 4 * sides.sum()
    assert abs(mesh.area / (4 * np.pi * state.radius_np()[0] ** 2) - 1) < 0.02
    vc = np.asarray(mesh.visual.vertex_colors)
    assert vc.shape == (len(mesh.vertices), 4) and len(np.unique(vc[:, :3], axis=0)) > 5


def test_side_by_side_and_quantities(gsd_file, tmp_path):
    mesh = export_gsd(gsd_file, tmp_path / "all.ply", quantity="energy", cmap="magma")
    state = svm.init.from_gsd(gsd_file)
    assert len(mesh.faces) == state.cell_sides.sum() * 9
    assert mesh.bounds[1, 0] - mesh.bounds[0, 0] > 4 * state.radius_np().max()   # two spheres apart
    with pytest.raises(ValueError, match="quantity must be one of"):
        cell_mesh(state, quantity="volume")


def test_plane_mesh_area():
    state = svm.init_plane.random_planar_tiling(20, seed=1)
    mesh = cell_mesh(state, subdivisions=1)
    assert np.isclose(mesh.area, state.constraint.total_area_np(state.box_np())[0])


def test_cli_export_errors(gsd_file, tmp_path, capsys):
    assert main(["export", str(gsd_file), "--to", str(tmp_path / "x.stl")]) == 2
    assert "output must end in one of" in capsys.readouterr().err


@pytest.mark.parametrize("plane", [False, True])
def test_render_png(tmp_path, gsd_file, plane):
    import matplotlib.image
    if plane:
        path = tmp_path / "plane.gsd"
        sim = svm.Simulation(device="cpu")
        sim.state = svm.init_plane.random_planar_tiling(30, seed=2)
        sim.operations.integrator = svm.plugins.integrators.FIRE(dt=0.02)
        sim.operations.writers.append(svm.plugins.writers.GSD(filename=str(path)))
        sim.run(0)
        sim.operations.writers[0].close()
    else:
        path = gsd_file
    out = tmp_path / "snap.png"
    assert main(["render", str(path), "--out", str(out), "--size", "4", "3", "--dpi", "50"]) == 0
    img = matplotlib.image.imread(out)
    assert img.shape[:2] == (150, 200)
    assert img[..., :3].std() > 0.05                       # not blank


def test_render_ignores_matplotlib_padding(monkeypatch):
    """matplotlib pads cells of different sides with np.empty; were the view scaled on that padding,
    a run whose padding held huge numbers failed with 'Axis limits cannot be NaN or Inf' (CI did)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from spherevm.render import draw
    state = svm.init.random_tiling(30, seed=3)
    assert len(np.unique(state.cell_sides)) > 1                     # ragged polygons
    empty = np.empty
    monkeypatch.setattr(np, "empty", lambda shape, dtype=float, **kw: np.full(shape, np.finfo(dtype).max, dtype)
                        if np.dtype(dtype).kind == "f" else empty(shape, dtype, **kw))
    fig = plt.figure()
    ax = fig.add_subplot(projection="3d")
    draw(ax, state)
    monkeypatch.undo()
    r = state.radius_np()[0]
    assert np.allclose([ax.get_xlim(), ax.get_ylim(), ax.get_zlim()], [-r, r])
    fig.savefig(__import__("io").BytesIO(), format="png")
    plt.close(fig)
