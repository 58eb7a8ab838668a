"""GSD writer and reader: exact restore from any frame, HOOMD/OVITO layout, bad input."""
import subprocess
import sys

import gsd.hoomd
import numpy as np
import pytest
from conftest import Snapshots, assert_same_state, snapshot, to_numpy

import spherevm as svm
from spherevm import topology
from spherevm.plugins.forces import VertexModel
from spherevm.plugins.integrators import FIRE
from spherevm.plugins.writers import GSD
from spherevm.gsdio import FrameIndexError, read_cell_values, read_state



def make_sim(state=None, device="cpu"):
    sim = svm.Simulation(device=device, seed=1)
    sim.state = state if state is not None else svm.init.random_tiling(64, replicas=3, seed=1)
    sim.operations.forces.append(VertexModel.dimensionless(kr=1.0, p0=3.8))
    sim.operations.integrator = FIRE(dt=0.02)
    return sim


def manual_t1(state):
    """A State after one T1 on the first edge of replica 0 whose two cells have > 4 sides."""
    cv, sides = state.cell_vertices, state.cell_sides
    cells = [list(cv[c, :sides[c]]) for c in range(state.n_cells)]
    vn, vc = state.vertex_neighbors, state.vertex_cells
    for a, b in topology.edges(vn):
        k = list(vn[a]).index(b)
        c1, c2 = vc[a, k], vc[a, k - 1]   # a -> b in c1, b -> a in c2
        if sides[c1] > 4 and sides[c2] > 4 and b < state.vertex_start[1]:
            break
    c3 = vc[a, (k + 1) % 3]
    c4 = next(c for c in vc[b] if c not in (c1, c2))

    def insert_after(cell, prev, v):
        cell.insert(cell.index(prev) + 1, v)

    cells[c1].remove(b)                   # c1 keeps a
    cells[c2].remove(a)                   # c2 keeps b
    insert_after(cells[c3], cells[c3][cells[c3].index(a) - 1], b)   # c3: p2, b, a, p1
    insert_after(cells[c4], cells[c4][cells[c4].index(b) - 1], a)   # c4: s1, a, b, s2
    table, new_sides = topology.pad_cells(cells)
    new_vn, new_vc = topology.build_vertex_tables(table, new_sides, state.n_vertices)
    pos = state.positions.copy()
    m = pos[a] + pos[b]
    axis = m / np.linalg.norm(m)
    for angle in (np.pi / 2, -np.pi / 2):  # turn the edge a quarter about its midpoint
        c, s = np.cos(angle), np.sin(angle)
        rot = c * np.eye(3) + s * np.cross(np.eye(3), axis) + (1 - c) * np.outer(axis, axis)
        pos[[a, b]] = state.positions[[a, b]] @ rot.T
        new = svm.State(pos, table, new_sides, new_vn, new_vc, state.vertex_start, state.cell_start,
                        state.radius, constraint=state.constraint, validate=False)
        try:
            return new.validate()
        except ValueError:
            continue
    raise AssertionError("could not build a valid T1 state")


@pytest.fixture
def written(tmp_path, device):
    """A run on the device writing 4 frames, then frames with a hand-made T1, the original topology
    again, and a different ensemble (other sizes, replica count and max_sides)."""
    path = tmp_path / "run.gsd"
    sim = make_sim(device=device)
    snaps = Snapshots(trigger=3)
    writer = GSD(3, path)
    sim.operations.writers.extend([snaps, writer])
    sim.run(9)                            # frames at timesteps 0, 3, 6, 9
    assert snaps.steps == [0, 3, 6, 9]
    original = sim.state
    for state in (manual_t1(original.to("cpu")), original,
                  svm.State.concatenate([svm.init.random_tiling(20, seed=4), svm.init.random_tiling(31, seed=5)])):
        sim.state = state
        snaps.write(sim, sim.timestep)
        writer.write(sim, sim.timestep)
    return path, sim, writer, snaps.refs


def test_restore_every_frame_exactly(written, device):
    path, sim, writer, refs = written
    assert svm.gsdio.n_frames(path) == len(refs)
    for i, ref in enumerate(refs):
        assert_same_state(read_state(path, frame=i), ref)
        restored = svm.init.from_gsd(path, frame=i - len(refs), device=device)
        assert restored.device.name == device
        assert_same_state(restored, ref)
    # a Simulation on the device restores a frame onto its device
    sim.create_state_from_gsd(path, frame=4)
    assert sim.state.device.name == device
    assert_same_state(sim.state, refs[4])
    # the T1 frame really changed the topology, the next one restored it from frame 0's chunks
    assert not np.array_equal(refs[4]["vertex_neighbors"], refs[0]["vertex_neighbors"])
    with gsd.hoomd.open(path) as t:
        assert t.file.chunk_exists(frame=4, name="spherevm/vertex_neighbors")
        assert not t.file.chunk_exists(frame=5, name="spherevm/vertex_neighbors")
    restored = read_state(path, frame=4, validate=True)
    assert restored.n_vertices == refs[0]["positions"].shape[0]
    last = read_state(path)
    assert last.n_replicas == 2 and last.max_sides != refs[0]["cell_vertices"].shape[1]
    assert isinstance(last.constraint, svm.constraints.Sphere)


def test_hoomd_layout_lengths_box_and_log(written, device):
    path, sim, writer, refs = written
    with gsd.hoomd.open(path) as t:
        assert len(t) == len(refs)
        for i, frame in enumerate(t):
            ref = refs[i]
            nv = ref["positions"].shape[0]
            bonds = topology.edges(ref["vertex_neighbors"])
            n_rep = len(ref["radius"])
            assert frame.particles.N == nv and frame.bonds.N == len(bonds)
            assert np.array_equal(frame.bonds.group, bonds)
            assert np.allclose(frame.particles.position, ref["positions"], atol=1e-6)
            for key, value in frame.log.items():
                if key.startswith("particles/"):
                    assert len(value) == nv, key
                elif key.startswith("bonds/"):
                    assert len(value) == len(bonds), key
                else:
                    assert value.shape == (n_rep,), key
            for key in ("particles/replica", "particles/cell_shape_index", "particles/cell_area",
                        "particles/cell_energy", "particles/force", "bonds/length", "energy", "max_force"):
                assert key in frame.log
            box = frame.configuration.box
            assert box[0] == box[1] == box[2] and np.all(box[3:] == 0)
            half = box[0] / 2
            assert box[0] >= 2.2 * ref["radius"].max() * (1 - 1e-6)
            assert np.all(np.abs(frame.particles.position) < half)
            d = frame.particles.position[bonds[:, 0]] - frame.particles.position[bonds[:, 1]]
            assert np.all(np.linalg.norm(d, axis=1) < half)
    # log values are the simulation's, per replica; cell values exact and consistent (recomputed
    # on the device that wrote them; the GPU sums a cell's corners with atomics, in cupy.bincount,
    # so there the same positions give the same areas to rounding, not bitwise)
    state0 = svm.init.from_gsd(path, frame=0, device=device)
    area, perimeter = svm.analysis.cell_shapes(state0)
    cells = read_cell_values(path, frame=0)
    if device == "cpu":
        assert np.array_equal(cells["area"], area) and np.array_equal(cells["perimeter"], perimeter)
    else:
        assert np.allclose(cells["area"], area, rtol=1e-14, atol=0)
        assert np.allclose(cells["perimeter"], perimeter, rtol=1e-14, atol=0)
    with gsd.hoomd.open(path) as t:
        f0 = t[0]
        model = VertexModel.dimensionless(kr=1.0, p0=3.8)
        res = model.compute(state0)
        assert np.allclose(f0.log["energy"], to_numpy(res.energy), rtol=1e-12)
        assert np.allclose(cells["energy"], to_numpy(res.cell_energy), rtol=1e-12)
        assert np.allclose(f0.log["particles/cell_area"], area[to_numpy(state0.vertex_cells)].mean(axis=1))
        assert np.allclose(f0.log["bonds/length"].sum(), perimeter.sum() / 2)


def test_readable_after_flush_without_close_and_append(tmp_path, device):
    path = tmp_path / "open.gsd"
    sim = make_sim(svm.init.random_tiling(16, replicas=2, seed=3), device)
    writer = GSD(2, str(path), log=("energy_per_cell", "timestep"))
    sim.operations.writers.append(writer)
    assert not path.exists()            # opened lazily
    sim.run(4)                          # frames at 0, 2, 4; not closed
    assert read_state(path).positions.tobytes() == to_numpy(sim.state.positions).tobytes()
    with gsd.hoomd.open(path) as t:
        assert len(t) == 3 and [int(f.configuration.step) for f in t] == [0, 2, 4]
        assert np.array_equal(t[2].log["timestep"], [4])
    writer.close()
    sim.run(2)                          # a write after close appends
    assert svm.gsdio.n_frames(path) == 4
    appender = GSD(1, path, mode="ab")
    appender.write(sim, sim.timestep)
    appender.close()
    assert svm.gsdio.n_frames(path) == 5
    overwriter = GSD(filename=path, mode="wb")
    overwriter.write(sim, sim.timestep)
    overwriter.close()
    assert svm.gsdio.n_frames(path) == 1
    with pytest.raises(FileExistsError, match="xb"):
        GSD(filename=path, mode="xb").write(sim, 0)


def test_crash_leaves_readable_file(tmp_path):
    # CPU only: a child process killed mid-run; what is on disk does not depend on the device
    path = tmp_path / "crash.gsd"
    code = (
        "import os, spherevm as svm\n"
        "sim = svm.Simulation(device='cpu')\n"
        "sim.state = svm.init.random_tiling(16, seed=2)\n"
        "sim.operations.forces.append(svm.plugins.forces.VertexModel.dimensionless(kr=1, p0=3.8))\n"
        "sim.operations.integrator = svm.plugins.integrators.FIRE(dt=0.02)\n"
        f"sim.operations.writers.append(svm.plugins.writers.GSD(1, {str(path)!r}))\n"
        "class Crash(svm.plugins.Writer):\n"
        "    def write(self, simulation, timestep):\n"
        "        os._exit(3)\n"
        "sim.operations.writers.append(Crash(trigger=svm.trigger.On(2)))\n"
        "sim.run(10)\n"
    )
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert proc.returncode == 3, proc.stderr
    assert svm.gsdio.n_frames(path) == 3
    assert read_state(path).n_cells == 16


def test_bad_input(tmp_path, written):
    path = written[0]
    with pytest.raises(FileNotFoundError, match="missing.gsd"):
        read_state(tmp_path / "missing.gsd")
    text = tmp_path / "notes.gsd"
    text.write_text("not a gsd file\n")
    with pytest.raises(ValueError, match="not a readable GSD file"):
        read_state(text)
    with pytest.raises(ValueError, match="is a directory"):
        read_state(tmp_path)
    plain = tmp_path / "plain.gsd"
    with gsd.hoomd.open(plain, "w") as t:
        f = gsd.hoomd.Frame()
        f.particles.N = 2
        f.particles.position = [[0, 0, 0], [1, 0, 0]]
        t.append(f)
    with pytest.raises(ValueError, match="not written by spherevm"):
        svm.init.from_gsd(plain)
    empty = tmp_path / "empty.gsd"
    gsd.hoomd.open(empty, "w").close()
    with pytest.raises(ValueError, match="no complete frame"):
        read_state(empty)
    n = svm.gsdio.n_frames(path)
    for bad in (n, -n - 1, 100):
        with pytest.raises(ValueError, match=f"out of range.*{n} frame"):
            read_state(path, frame=bad)
    with pytest.raises(IndexError):
        read_state(path, frame=n)
    assert issubclass(FrameIndexError, IndexError)
    with pytest.raises(TypeError, match="frame must be an integer"):
        read_state(path, frame=1.5)
    # writer arguments
    with pytest.raises(ValueError, match="mode must be"):
        GSD(filename=tmp_path / "x.gsd", mode="r")
    with pytest.raises(ValueError, match="unknown loggable"):
        GSD(filename=tmp_path / "x.gsd", log=("energy", "nope")).write(make_sim(), 0)
    with pytest.raises(ValueError, match="cannot append"):
        GSD(filename=text, mode="ab").write(make_sim(), 0)
    sim = make_sim(svm.init.random_tiling(16, seed=2))
    sim.state.positions[3, 1] = np.nan
    target = tmp_path / "nan.gsd"
    with pytest.raises(FloatingPointError, match="vertex 3 of replica 0.*timestep 7"):
        GSD(filename=target).write(sim, 7)
    assert not target.exists()


def test_writer_without_forces(tmp_path, device):
    sim = svm.Simulation(device=device)
    sim.state = svm.init.random_tiling(12, seed=1)
    w = GSD(filename=tmp_path / "init.gsd")
    w.write(sim, 0)
    w.close()
    with gsd.hoomd.open(tmp_path / "init.gsd") as t:
        assert "mean_shape_index" in t[0].log and "energy" not in t[0].log
        assert "particles/cell_shape_index" in t[0].log and "particles/cell_energy" not in t[0].log
    assert read_state(tmp_path / "init.gsd").n_cells == 12


def test_box_grows_for_long_edges(tmp_path, device):
    """In a 4-cell tiling edges are longer than 1.1 R: the box grows so that none reaches half of it."""
    sim = make_sim(svm.init.random_tiling(4, seed=0), device)
    with GSD(filename=tmp_path / "tiny.gsd") as w:
        w.write(sim, 0)
    with gsd.hoomd.open(tmp_path / "tiny.gsd") as t:
        f = t[0]
        d = f.particles.position[f.bonds.group[:, 0]] - f.particles.position[f.bonds.group[:, 1]]
        assert np.linalg.norm(d, axis=1).max() > 1.1 * sim.state.radius_np()[0]
        assert np.all(np.abs(d) < f.configuration.box[0] / 2)
    assert_same_state(read_state(tmp_path / "tiny.gsd"), snapshot(sim.state))


def test_per_item_keys_persist_with_right_lengths(tmp_path, device):
    """A per-vertex key missing from a frame would take frame 0's array (wrong length after a
    topology change): the writer keeps writing every key it has written, NaN when unknown."""
    path = tmp_path / "keys.gsd"
    sim = make_sim(svm.init.random_tiling(16, seed=1), device)
    w = GSD(filename=path, log=("mean_shape_index",))
    w.write(sim, 0)
    sim.operations.forces.remove(sim.operations.forces[0])
    sim.state = svm.init.random_tiling(24, replicas=2, seed=2)
    w.write(sim, 1)
    w.close()
    with gsd.hoomd.open(path) as t:
        f = t[1]
        assert f.log["particles/force"].shape == (f.particles.N, 3)
        assert np.all(np.isnan(f.log["particles/force"]))
        assert np.all(np.isnan(f.log["particles/cell_energy"]))
        assert f.log["particles/cell_area"].shape == (f.particles.N,)


def test_ovito_opens_file(written):
    ovito_io = pytest.importorskip("ovito.io")
    path, sim, writer, refs = written
    pipeline = ovito_io.import_file(str(path))
    assert pipeline.source.num_frames == len(refs)
    for i in (0, 4, len(refs) - 1):
        data = pipeline.compute(i)
        nv = refs[i]["positions"].shape[0]
        assert data.particles.count == nv
        assert data.particles.bonds.count == len(topology.edges(refs[i]["vertex_neighbors"]))
        shape = np.asarray(data.particles["cell_shape_index"])
        assert shape.shape == (nv,) and np.all(np.isfinite(shape))
        assert np.array_equal(np.asarray(data.particles["replica"]),
                              np.repeat(np.arange(len(refs[i]["radius"])), np.diff(refs[i]["vertex_start"])))
        assert "length" in data.particles.bonds.keys()
        # no bond crosses the periodic box
        assert not np.any(np.asarray(data.particles.bonds["Periodic Image"]))
        assert data.attributes["Timestep"] == min(3 * i, 9)
        assert len(data.attributes["energy"]) == len(refs[i]["radius"])


def test_reader_reads_many_frames_from_one_open_file(written, monkeypatch):
    import gsd.fl
    path, sim, writer, refs = written
    opened, real_open = [], gsd.fl.open
    monkeypatch.setattr(gsd.fl, "open", lambda *a, **k: opened.append(a or k) or real_open(*a, **k))
    with svm.gsdio.Reader(path) as f:
        assert len(f) == len(refs)
        for i, ref in enumerate(refs):
            assert_same_state(f.state(i), ref)
        steps = [f.step(i) for i in range(len(f))]
        with pytest.raises(FrameIndexError):
            f.step(len(f))
    assert len(opened) == 1
    with gsd.hoomd.open(path) as t:
        assert steps == [int(frame.configuration.step) for frame in t]


def _spherevm_imports(path):
    """Every spherevm module a source file imports, at the top or inside functions."""
    import ast
    import pathlib
    rel = pathlib.Path(path).relative_to(pathlib.Path(svm.__file__).parent.parent).with_suffix("")
    package = list(rel.parts[:-1])          # what a level-1 relative import starts from
    found = set()
    for node in ast.walk(ast.parse(pathlib.Path(path).read_text())):
        if isinstance(node, ast.Import):
            found.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = package[:len(package) - node.level + 1] if node.level else []
            module = ".".join(base + ([node.module] if node.module else []))
            found.update([module] if node.module else [f"{module}.{a.name}" for a in node.names])
    return {m for m in found if m.split(".")[0] == "spherevm"}


def test_io_and_shapes_modules_import_only_downwards():
    import pathlib
    root = pathlib.Path(svm.__file__).parent
    above_state = ("spherevm.plugins", "spherevm.simulation", "spherevm.analysis", "spherevm.protocols",
                   "spherevm.sweeps", "spherevm.cli")
    above_plugins = above_state[1:]
    rules = {root / "gsdio.py": above_state, root / "shapes.py": above_state, root / "init.py": above_state,
             root / "state.py": above_state + ("spherevm.gsdio", "spherevm.shapes", "spherevm.init")}
    rules.update((p, above_plugins) for p in (root / "plugins" / "writers").glob("*.py"))
    for path, forbidden in rules.items():
        bad = sorted(m for m in _spherevm_imports(path) if m.startswith(forbidden))
        assert not bad, f"{path.name} imports {bad} from a higher layer"
    assert not hasattr(svm.State, "from_gsd")   # reading a file is spherevm.init.from_gsd


# ------------------------------------------------------------------ issue 36, item 4: files cut short
@pytest.fixture(scope="module")
def growing_file(tmp_path_factory):
    """24 frames written one by one, with the file's bytes after each (gsd flushes every frame): the
    index and the name list were moved to the end of the file several times on the way."""
    path = tmp_path_factory.mktemp("cut") / "whole.gsd"
    sim = make_sim(svm.init.random_tiling(16, replicas=2, seed=5))
    sim.operations.updaters.append(svm.plugins.updaters.T1())
    writer = GSD(1, path)
    snapshots = []
    for _ in range(24):
        writer.write(sim, sim.timestep)
        snapshots.append(path.read_bytes())
        sim.run(3)
    writer.close()
    return path, snapshots


def _chunks(file, frame):
    return {name: file.read_chunk(frame=frame, name=name) for name in file.find_matching_chunk_names("")
            if file.chunk_exists(frame=frame, name=name)}


def test_a_file_cut_anywhere_reads_up_to_its_last_complete_frame(growing_file, tmp_path):
    """Cut at 100 random offsets, the file reads (with a DamagedFileWarning naming the count) exactly
    the frames that were complete before the cut: frame k is complete when the file as it stood
    right after frame k holds nothing past the cut but the zero padding gsd reserves for a grown
    index or name list. Each chunk of the last one comes back bit for bit."""
    import gsd.fl
    path, snapshots = growing_file
    data = path.read_bytes()
    cut_path = tmp_path / "cut.gsd"
    with gsd.fl.open(str(path), "r") as whole:
        for cut in np.random.default_rng(36).integers(0, len(data), 100):
            cut_path.write_bytes(data[:cut])
            expected = sum(len(then) <= cut or not any(then[cut:]) for then in snapshots)
            if cut < 256:
                with pytest.raises(ValueError, match="not a readable GSD file"):
                    svm.gsdio.Reader(cut_path)
                continue
            with pytest.warns(svm.gsdio.DamagedFileWarning, match=f"reading its {expected} complete frame"):
                reader = svm.gsdio.Reader(cut_path)
            with reader:
                assert len(reader) == expected, cut
                if expected:
                    got, want = _chunks(reader.file, expected - 1), _chunks(whole, expected - 1)
                    assert got.keys() == want.keys()
                    for name in want:
                        assert np.array_equal(got[name], want[name]) and np.asarray(got[name]).dtype == \
                            np.asarray(want[name]).dtype, name
                    state = reader.state(expected - 1)
                    assert state.positions.tobytes() == read_state(path, expected - 1).positions.tobytes()


def test_repair_writes_the_complete_frames_to_a_new_file(growing_file, tmp_path, capsys):
    import gsd.fl
    from spherevm import cli
    path, snapshots = growing_file
    cut = tmp_path / "cut.gsd"
    cut.write_bytes(path.read_bytes()[:len(snapshots[9]) + 10])   # inside frame 10
    before = cut.read_bytes()
    assert cli.main(["repair", str(cut)]) == 0
    out = tmp_path / "cut.repaired.gsd"
    assert f"wrote its 10 complete frame(s) to {out}" in capsys.readouterr().out
    assert cut.read_bytes() == before                                     # FILE itself is never changed
    with gsd.fl.open(str(out), "r") as repaired, gsd.fl.open(str(path), "r") as whole:
        assert repaired.nframes == 10 and svm.gsdrecover.whole(out)       # gsd opens it as a whole file
        for frame in (0, 9):
            got, want = _chunks(repaired, frame), _chunks(whole, frame)
            assert got.keys() == want.keys() and all(np.array_equal(got[k], want[k]) for k in want)
    with pytest.warns(svm.gsdio.DamagedFileWarning):
        assert read_state(cut).positions.tobytes() == read_state(out).positions.tobytes()
    for argv, message in ((["repair", str(cut)], "exists; give --overwrite"),
                          (["repair", str(cut), "--out", str(cut)], "is FILE itself")):
        assert cli.main(argv) == 2
        assert message in capsys.readouterr().err
    assert cli.main(["repair", str(cut), "--overwrite", "-o", str(out)]) == 0
