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


@pytest.mark.filterwarnings("ignore:overflow encountered:RuntimeWarning")   # projecting the planted padding
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


def _pixels(fig):
    """The figure's RGB pixels (rows from the top) after drawing on the Agg canvas."""
    fig.canvas.draw()
    return np.asarray(fig.canvas.buffer_rgba())[..., :3]


def _white(rgb):
    return (rgb == 255).all(axis=-1)


def test_sphere_drawn_as_a_round_ball():
    """The cells facing the camera, clipped at the rim, fill the disc it sees and nothing else: no
    gaps inside (cells half behind the rim were left out before) and nothing poking out."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from mpl_toolkits.mplot3d import proj3d

    from spherevm.render import draw, view_direction
    state = svm.init.random_tiling(64, seed=3)
    fig = plt.figure(figsize=(4, 4), dpi=100)
    ax = fig.add_subplot(projection="3d")
    draw(ax, state, elev=25, azim=-60)
    rgb = _pixels(fig)
    r = state.radius_np()[0]
    v = view_direction(25, -60)
    rim = r * np.cross(v, [0.0, 0.0, 1.0]) / np.linalg.norm(np.cross(v, [0.0, 0.0, 1.0]))
    x, y, _ = proj3d.proj_transform(*np.array([[0.0, 0.0, 0.0], rim]).T, ax.get_proj())
    (cx, cy), edge = ax.transData.transform(np.c_[x, y])
    radius = np.hypot(edge[0] - cx, edge[1] - cy)
    rows, cols = np.indices(rgb.shape[:2])
    d = np.hypot(cols + 0.5 - cx, (rgb.shape[0] - rows - 0.5) - cy)
    assert radius > 100
    assert not _white(rgb[d < radius - 2]).any()                   # a solid ball
    assert _white(rgb[(d > radius + 2) & (d < radius + 15)]).all()  # a round rim
    plt.close(fig)


def test_clipped_cells_tile_the_visible_disc():
    from spherevm.render import cell_polygons, clip_to_front, refine, view_direction
    state = svm.init.random_tiling(30, seed=3)
    r = state.radius_np()[0]
    v = view_direction(-40, 100)
    u = np.cross(v, [0.0, 0.0, 1.0])
    u /= np.linalg.norm(u)
    w = np.cross(v, u)
    area = 0.0
    for poly in cell_polygons(state, np.arange(state.n_cells)):
        part = clip_to_front(refine(poly, r), v, r)
        if part is None:
            assert (poly @ v < 0).all()
            continue
        assert (part @ v > -1e-12).all() and np.allclose(np.linalg.norm(part, axis=1), r)
        x, y = part @ u, part @ w
        area += 0.5 * abs(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1)))
    assert area / (np.pi * r ** 2) == pytest.approx(1, abs=1e-3)  # the rim in 3-degree steps: 5e-4 short


def test_plane_drawn_with_its_box_and_periodic_images():
    """The box is outlined and filled: cells that cross its edge show on both sides (with one side
    only, the tissue looked non-confluent at the edges), the images around it faded."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.patches import Rectangle

    from spherevm.render import draw
    state = svm.init_plane.random_planar_tiling(30, seed=2)
    lx, ly = state.box_np()[0]
    fig = plt.figure(figsize=(4, 4), dpi=100)
    ax = fig.add_subplot()
    draw(ax, state)
    boxes = [p for p in ax.patches if isinstance(p, Rectangle) and not p.get_fill()]
    assert len(boxes) == 1 and (boxes[0].get_width(), boxes[0].get_height()) == (lx, ly)
    faded, inside = ax.collections
    assert len(inside.get_paths()) == len(faded.get_paths()) == 9 * state.n_cells and faded.get_alpha() < 1
    rgb = _pixels(fig)
    (x0, y0), (x1, y1) = ax.transData.transform([(0, 0), (lx, ly)])
    h = rgb.shape[0]
    box = rgb[int(h - y1) + 3:int(h - y0) - 3, int(x0) + 3:int(x1) - 3]
    assert box.size and not _white(box).any()
    margin = rgb[int(h - y1) + 3:int(h - y0) - 3, int(x1) + 3:int(x1) + 10]       # right of the box
    assert not _white(margin).any() and margin.mean() > box.mean()                  # images, faded
    plt.close(fig)


def test_render_title_names_the_frame(gsd_file, tmp_path, monkeypatch):
    import spherevm.render as render
    seen = {}
    monkeypatch.setattr(render, "render_state", lambda state, out, **kw: seen.update(kw))
    render.render_gsd(gsd_file, tmp_path / "x.png", frame=-1, replica=1)
    assert seen["title"] == f"{gsd_file}  frame 2  (step 100)  replica 1"
