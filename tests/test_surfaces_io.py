"""Implicit surfaces beyond the step: checkpoints and exact restart (library and command line), GSD
files (the surface's parameters, a plugin surface found by its entry point), meshes and pictures
(``spherevm export`` and ``render``), and the trajectory analysis (MSD, Q_s, F_s, tau_alpha) on the
torus, the ellipsoid, the Gaussian bump and the user's sinusoid (tests/plugin_example)."""
import os
import pathlib
import subprocess
import sys

import numpy as np
import pytest
from conftest import to_numpy

import spherevm as svm
from spherevm import cli
from spherevm.analysis import Trajectory, msd, self_intermediate_scattering, self_overlap
from spherevm.constraints import Ellipsoid, GaussianBump, Torus
from spherevm.constraints.registry import surface as parse_surface
from spherevm.plugins.forces import VertexModel
from spherevm.plugins.integrators import FIRE, Active, Brownian
from spherevm.plugins.updaters import T1
from spherevm.plugins.writers import GSD

EXAMPLE = pathlib.Path(__file__).parent / "plugin_example"
SPECS = {"torus": "torus:R=3,r=1", "ellipsoid": "ellipsoid:a=1,b=1.5,c=2", "bump": "bump:height=1.5,width=1,box=12",
         "sinusoid": "sinusoid:amplitude=1.5,box=10"}
INTEGRATORS = {"brownian": lambda: Brownian(dt=0.01, T=0.05), "active": lambda: Active(dt=0.01, v0=0.3, Dr=0.5, T=0.01),
               "fire": lambda: FIRE(dt=0.05, check_every=7)}


@pytest.fixture(params=sorted(SPECS))
def spec(request, monkeypatch):
    """A surface's command-line spec (the sinusoid's entry point on the path)."""
    monkeypatch.syspath_prepend(str(EXAMPLE))
    return SPECS[request.param]


def make(kind, device="cpu"):
    sim = svm.Simulation(device=device, seed=4)
    sim.operations.forces.append(VertexModel.dimensionless(kr=1.0, p0=3.85))
    sim.operations.updaters.append(T1())
    sim.operations.integrator = INTEGRATORS[kind]()
    return sim


# ------------------------------------------------------------------ checkpoints and restart
@pytest.mark.parametrize("kind", sorted(INTEGRATORS))
def test_restart_is_bitwise_on_each_surface(spec, kind, device, tmp_path):
    """A run written to GSD at step 20 and continued in a fresh Simulation for 20 more steps ends
    bitwise where the uninterrupted 40 steps end (T1 flips included), on either device."""
    tiling = svm.init.random_tiling(40, seed=3, surface=parse_surface(spec))
    whole = make(kind, device)
    whole.state = tiling
    whole.run(40)
    first = make(kind, device)
    first.state = tiling
    first.operations.writers.append(GSD(20, tmp_path / "ck.gsd"))
    first.run(20)
    first.operations.writers[0].close()
    second = make(kind, device)
    second.create_state_from_gsd(tmp_path / "ck.gsd")
    assert second.timestep == 20 and repr(second.state.constraint) == repr(tiling.constraint)
    second.run(20)
    for name in ("positions", "cell_vertices"):
        assert to_numpy(getattr(second.state, name)).tobytes() == to_numpy(getattr(whole.state, name)).tobytes()
    assert whole.log("t1_total_flips").sum() > 0


def test_cli_minimize_restart_on_each_surface(spec, tmp_path, capsys):
    """``minimize --restart`` continues bitwise, with ``--surface`` left out or given as the file's;
    another surface is refused naming both."""
    common = ["--device", "cpu", "-q"]
    runs = {"whole": ["--cells", "30", "--replicas", "2", "--surface", spec, "--max-steps", "120"],
            "first": ["--cells", "30", "--replicas", "2", "--surface", spec, "--max-steps", "60"]}
    for name, argv in runs.items():
        assert cli.main(["minimize", *argv, *common, "--out", str(tmp_path / f"{name}.gsd")]) == 0
    whole = capsys.readouterr().out.split(runs["first"][-1])[0]
    final = svm.init.from_gsd(tmp_path / "whole.gsd").positions.tobytes()
    for name, extra in (("again", []), ("named", ["--surface", spec])):
        argv = ["minimize", "--restart", str(tmp_path / "first.gsd"), "--max-steps", "60", *extra, *common]
        assert cli.main([*argv, "--out", str(tmp_path / f"{name}.gsd")]) == 0
        assert svm.init.from_gsd(tmp_path / f"{name}.gsd").positions.tobytes() == final
    assert whole
    capsys.readouterr()
    other = "torus:R=4,r=1" if not spec.startswith("torus") else "torus:R=3,r=2"
    assert cli.main(["minimize", "--restart", str(tmp_path / "first.gsd"), "--surface", other, *common]) == 2
    assert "argument --surface: " + other + ", but --restart" in capsys.readouterr().err


def test_cli_dynamics_restart_on_a_torus(tmp_path):
    """``dynamics --restart`` of a torus file (the file names the surface; no spec needed)."""
    out, again = tmp_path / "d.gsd", tmp_path / "e.gsd"
    base = ["--device", "cpu", "-q", "--kr", "1", "--dt", "0.02", "--T", "0.05"]
    assert cli.main(["dynamics", "--cells", "40", "--replicas", "1", "--surface", SPECS["torus"], "--steps", "20",
                     "--relax", "20", "--equilibrate", "0", "--out", str(out), *base]) == 0
    assert cli.main(["dynamics", "--restart", str(out), "--steps", "20", "--out", str(again), *base]) == 0
    with svm.gsdio.Reader(out) as r, svm.gsdio.Reader(again) as s:
        assert s.step(-1) == r.step(-1) + 20
        assert type(s.state(-1).constraint) is Torus


# ------------------------------------------------------------------ GSD files
def test_gsd_keeps_every_parameter_and_finds_plugin_surfaces(tmp_path):
    """A bump's box (not its default) survives a GSD round trip; a file on the user's sinusoid is read
    in a fresh process that never imported it (found through its entry point)."""
    bump = GaussianBump(1.5, 1.0, (12.0, 10.0))
    sim = svm.Simulation(device="cpu")
    sim.state = svm.init.random_tiling(40, seed=1, surface=bump)
    svm.write_gsd(sim, tmp_path / "b.gsd")
    assert repr(svm.init.from_gsd(tmp_path / "b.gsd").constraint) == repr(bump) == \
        "GaussianBump(Lx=12, Ly=10, height=1.5, width=1)"
    sys.path.insert(0, str(EXAMPLE))
    try:
        sim.state = svm.init.random_tiling(40, seed=1, surface=parse_surface(SPECS["sinusoid"]))
    finally:
        sys.path.remove(str(EXAMPLE))
    svm.write_gsd(sim, tmp_path / "s.gsd")
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([os.getcwd(), str(EXAMPLE)]))
    script = (f"import spherevm as svm; s = svm.init.from_gsd({str(tmp_path / 's.gsd')!r}); "
              "print(repr(s.constraint), s.n_cells)")
    out = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, env=env, cwd=os.getcwd())
    assert out.stdout.strip() == "Sinusoid(Lx=10, Ly=10, amplitude=1.5) 40", out.stderr


def test_gsd_frames_for_ovito(spec, tmp_path):
    """The frame's box: on a closed surface a cube about the origin holding every vertex; on a
    periodic one the box (Lx, Ly) in x and y (bonds across its edges are minimum images in OVITO),
    particles shifted to its centre. With OVITO installed, one face of the cell mesh per cell."""
    gsd_hoomd = pytest.importorskip("gsd.hoomd")
    sim = svm.Simulation(device="cpu")
    sim.state = s = svm.init.random_tiling(40, replicas=2, seed=1, surface=parse_surface(spec))
    svm.write_gsd(sim, tmp_path / "o.gsd")
    with gsd_hoomd.open(tmp_path / "o.gsd") as f:
        box, x = f[0].configuration.box, f[0].particles.position
    if s.constraint.periodic:
        L = s.size_np()[0, :2]
        assert np.allclose(box[:2], L, rtol=1e-6) and box[2] >= 2 * np.abs(s.positions[:, 2]).max()
        assert np.all(np.abs(x[:, :2]) <= L / 2 * (1 + 1e-6))
        assert np.allclose(x, s.positions - [L[0] / 2, L[1] / 2, 0], atol=1e-5)
    else:
        assert box[0] == box[1] == box[2] and np.all(np.abs(x) < box[0] / 2) and np.allclose(x, s.positions, atol=1e-5)
    assert np.array_equal(svm.init.from_gsd(tmp_path / "o.gsd").positions, s.positions)
    pytest.importorskip("ovito")
    import spherevm.ovito as so
    mesh = so.pipeline(tmp_path / "o.gsd", side_by_side=False).compute(0).surfaces["cells"]
    assert mesh.faces.count == s.n_cells and mesh.vertices.count == so.SEGMENTS * s.cell_sides.sum()


# ------------------------------------------------------------------ meshes and pictures
def test_export_and_render_on_each_surface(spec, tmp_path):
    """``spherevm export``: each cell's fan of triangles cut into subdivisions^2, the vertices on the
    surface, the mesh's area that of the fans; ``spherevm render``: a PNG with the cells coloured."""
    trimesh = pytest.importorskip("trimesh")
    plt = pytest.importorskip("matplotlib.pyplot")
    sim = svm.Simulation(device="cpu")
    sim.state = svm.init.random_tiling(40, replicas=2, seed=2, surface=parse_surface(spec))
    svm.write_gsd(sim, tmp_path / "s.gsd")
    s = sim.state
    assert cli.main(["export", str(tmp_path / "s.gsd"), "--to", str(tmp_path / "m.ply"), "--replica", "1",
                     "--subdivisions", "2"]) == 0
    mesh = trimesh.load(tmp_path / "m.ply", force="mesh")
    mine = s.cell_replica_np() == 1
    assert len(mesh.faces) == 4 * s.cell_sides[mine].sum()
    con = s.constraint
    size = np.broadcast_to(s.size_np()[1], (len(mesh.vertices),) + s.size_np().shape[1:])
    extent = np.abs(mesh.vertices).max()                  # the file holds float32 coordinates
    assert np.abs(con.distance_to_surface(np.asarray(mesh.vertices, dtype=np.float64), size)).max() < 1e-6 * extent
    # the cells' flat facets bulged onto the surface: more area than the facets, about the surface's
    # (a little more where projected pieces of a coarse cell tilt on a saddle: the torus's inner side)
    assert con.cell_areas_np(s)[mine].sum() < mesh.area < 1.01 * con.total_area_np(s.size_np()[1])
    assert cli.main(["render", str(tmp_path / "s.gsd"), "--out", str(tmp_path / "p.png")]) == 0
    image = plt.imread(tmp_path / "p.png")
    assert len(np.unique((image[..., :3] * 255).astype(int).reshape(-1, 3), axis=0)) > 20


# ------------------------------------------------------------------ analysis
def test_rigid_motions_of_each_surface():
    """The torus and a spheroid (a = b) turn about z; a general ellipsoid and the bump have none."""
    assert Torus(3, 1).rigid_motions == ("z-rotations",)
    assert Ellipsoid(1, 1, 2).rigid_motions == ("z-rotations",)
    assert Ellipsoid(2, 2, 2).rigid_motions == ("rotations",)
    assert Ellipsoid(1, 1.5, 2).rigid_motions == () and GaussianBump().rigid_motions == ()


def test_a_torus_turned_rigidly_about_its_axis_has_no_msd():
    """Frames of a torus tissue turned about z: MSD and 1 - Q_s are zero (to rounding) with the
    rotation removed (the default), not without; a tilt (no symmetry of the torus) is not removed."""
    s = svm.init.random_tiling(40, replicas=2, seed=1, surface=Torus(3.0, 1.0))
    c = s.constraint.cell_centers(s)
    frames = []
    for angle in np.linspace(0, 1.5, 6):
        rot = np.array([[np.cos(angle), -np.sin(angle), 0], [np.sin(angle), np.cos(angle), 0], [0, 0, 1]])
        frames.append(c @ rot.T)
    traj = Trajectory(np.arange(6.0), np.array(frames), s.cell_replica_np(), constraint=s.constraint, size=s.size_np())
    assert np.abs(msd(traj).value).max() < 1e-24
    assert np.all(self_overlap(traj).value == 1.0)
    moved = msd(traj, remove_rotation=False).value
    assert moved[-1] > 1.0
    assert np.abs(traj.without_rotation().centroids - c).max() < 1e-12
    tilted = c @ np.array([[1, 0, 0], [0, np.cos(0.5), -np.sin(0.5)], [0, np.sin(0.5), np.cos(0.5)]]).T
    tilt = Trajectory(np.arange(2.0), np.array([c, tilted]), s.cell_replica_np(), constraint=s.constraint,
                      size=s.size_np())
    assert msd(tilt).value[1] > 0.1


def test_surfaces_without_rigid_motions_refuse_their_removal():
    s = svm.init.random_tiling(40, seed=1, surface=Ellipsoid(1.0, 1.5, 2.0))
    c = s.constraint.cell_centers(s)
    traj = Trajectory(np.arange(2.0), np.array([c, c]), s.cell_replica_np(), constraint=s.constraint, size=s.size_np())
    with pytest.raises(ValueError, match=r"remove_rotation=True: a trajectory on Ellipsoid\(a=1, b=1.5, c=2\) has "
                                         r"no rigid rotation to remove \(its rigid motions: none\)"):
        msd(traj, remove_rotation=True)
    assert msd(traj).value[1] == 0.0


def test_analysis_end_to_end_on_each_surface(spec, tmp_path):
    """Brownian + T1 of a fluid tissue (p0 = 4.1) written to GSD, read as a Trajectory: MSD grows from
    0, Q_s and F_s fall from 1 and stay in [0, 1], Q_s reaches 1/e (tau_alpha); displacements are
    chords in the embedding space, unwrapped across a periodic box."""
    sim = svm.Simulation(device="cpu", seed=4)
    sim.operations.forces.append(VertexModel.dimensionless(kr=1.0, p0=4.1))
    sim.operations.updaters.append(T1())
    sim.operations.integrator = Brownian(dt=0.01, T=0.2)
    sim.state = svm.init.random_tiling(60, seed=5, surface=parse_surface(spec))
    sim.operations.writers.append(GSD(20, tmp_path / "t.gsd"))
    sim.run(600)
    sim.operations.writers[0].close()
    traj = Trajectory.from_gsd(tmp_path / "t.gsd")
    m, q, f = msd(traj), self_overlap(traj), self_intermediate_scattering(traj)
    assert m.value[0] == 0 and m.value[-1] > 0.5
    assert q.value[0] == 1 and f.value[0] == pytest.approx(1.0)
    assert np.all((q.value >= 0) & (q.value <= 1)) and np.all(np.abs(f.value) <= 1)
    assert 0 < q.tau_alpha() < 600
    chords = traj.positions - traj.positions[0]                   # unwrapped, in the embedding space
    plain = msd(traj, remove_rotation=False, remove_drift=False).value
    expected = ((chords / traj.length_unit[traj.cell_replica][:, None]) ** 2).sum(axis=-1).mean(axis=1)
    assert plain == pytest.approx(expected, rel=1e-12)


def test_the_gallery_script_draws_every_surface(tmp_path, monkeypatch, capsys):
    """examples/surfaces_gallery.py, tiny: one picture per surface."""
    import runpy
    script = pathlib.Path(__file__).resolve().parent.parent / "examples" / "surfaces_gallery.py"
    monkeypatch.setattr(sys, "argv", [str(script), str(tmp_path), "60", "30"])
    monkeypatch.syspath_prepend(str(EXAMPLE))
    runpy.run_path(str(script), run_name="__main__")
    names = ("sphere", "plane", "torus", "ellipsoid", "bump", "sinusoid")
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(f"surface_{n}.png" for n in names)
    assert capsys.readouterr().out.count("FIRE steps") == 6
