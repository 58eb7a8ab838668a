"""Tests that kill mutants of spherevm/gsdio.py that survived the existing tests.

Found with ``python3 benchmarks/mutate.py spherevm/gsdio.py ...`` (docs/testing.md, "Mutation
testing"): the stored format version, default frames (the last), the box and display diameters,
the fallbacks for a surface without areas or geodesic lengths, timesteps and frame indices.
"""
import gsd.hoomd
import numpy as np
import pytest

import spherevm as svm
from spherevm import gsdio, topology
from spherevm.constraints import Sphere
from spherevm.plugins.writers import GSD


class SphereWithoutAreas(Sphere):
    """A user surface that provides neither total areas nor geodesic lengths (the writer's fallbacks)."""
    name = "sphere_without_areas_for_mutants"

    def total_area_np(self, radius):
        raise NotImplementedError("no total area")

    def edge_lengths(self, state, u, v):
        raise NotImplementedError("no geodesic lengths")


def _three_frames(path, log=("timestep",)):
    sim = svm.Simulation(device="cpu", seed=1)
    sim.state = svm.init.random_tiling(16, replicas=2, seed=3)
    w = GSD(1, path, log=log)
    for step in (5, 6, 7):
        sim.state.positions[:] = svm.geometry.normalize(sim.state.positions + 0.001 * step) * \
            sim.state.radius_np()[sim.state.vertex_replica_np()][:, None]
        w.write(sim, step)
    w.close()
    return sim


def test_format_version_is_one_and_newer_files_are_refused(tmp_path, monkeypatch):
    path = tmp_path / "v.gsd"
    _three_frames(path)
    assert gsdio.FORMAT_VERSION == 1        # docs/file-format.md: bump only with a reader for the old one
    with gsd.hoomd.open(path) as t:
        assert t.file.read_chunk(frame=0, name="spherevm/format_version").tolist() == [1]
    newer = tmp_path / "v2.gsd"
    monkeypatch.setattr(gsdio, "FORMAT_VERSION", 2)
    _three_frames(newer)
    monkeypatch.setattr(gsdio, "FORMAT_VERSION", 1)
    with pytest.raises(ValueError, match="format version 2, newer"):
        gsdio.read_state(newer)


def test_defaults_read_the_last_frame(tmp_path):
    path = tmp_path / "last.gsd"
    sim = _three_frames(path)
    last = sim.state.positions
    assert np.array_equal(gsdio.read_state(path).positions, last)
    with gsdio.Reader(path) as r:
        assert len(r) == 3
        assert np.array_equal(r.state().positions, last)
        assert r.step(-1) == 7 and r.step(0) == 5 and r.step(-3) == 5 and r.step(1) == 6
        assert r.index(-1) == 2 and r.index(-3) == 0 and r.index(np.int64(2)) == 2
        with pytest.raises(gsdio.FrameIndexError, match="use 0..2 or -3..-1"):
            r.index(3)
        with pytest.raises(gsdio.FrameIndexError):
            r.index(-4)
        with pytest.raises(TypeError, match="frame must be an integer"):
            r.index(True)
        cv_last = r.cell_values()
        cv_first = r.cell_values(0)
    assert set(cv_last) == {"area", "perimeter", "shape_index"}
    by_func = gsdio.read_cell_values(path)
    for q in cv_last:
        assert np.array_equal(by_func[q], cv_last[q])
    assert not np.array_equal(cv_last["area"], cv_first["area"])
    area, perimeter = svm.analysis.cell_shapes(sim.state)
    assert np.array_equal(cv_last["area"], area) and np.array_equal(cv_last["perimeter"], perimeter)


def test_step_defaults_to_zero_when_no_frame_stores_it(tmp_path):
    path = tmp_path / "nostep.gsd"
    sim = svm.Simulation(device="cpu")
    sim.state = svm.init.random_tiling(12, seed=1)
    with GSD(filename=path) as w:
        w.write(sim, 0)                  # gsd leaves out a step equal to the default 0
    with gsdio.Reader(path) as r:
        assert r.step(0) == 0


def test_box_and_diameters_known_values(tmp_path):
    path = tmp_path / "box.gsd"
    sim = svm.Simulation(device="cpu")
    sim.state = svm.State.concatenate([svm.init.random_tiling(64, seed=1, radius=2.0),
                                       svm.init.random_tiling(32, seed=2, radius=1.0)])
    with GSD(filename=path) as w:
        w.write(sim, 0)
    s = sim.state
    pos = s.positions
    bonds = topology.edges(s.vertex_neighbors)
    chord = np.linalg.norm(pos[bonds[:, 0]] - pos[bonds[:, 1]], axis=1)
    extent = max(s.radius_np().max(), np.abs(pos).max(), chord.max())
    with gsd.hoomd.open(path) as t:
        f = t[0]
        box = np.float32(gsdio.BOX_FACTOR * extent * (1 + 1e-6))
        assert gsdio.BOX_FACTOR == 2.2 and gsdio.DIAMETER_FACTOR == 0.15
        assert np.array_equal(f.configuration.box, np.array([box, box, box, 0, 0, 0], dtype=np.float32))
        d = (0.15 * np.sqrt(s.mean_cell_area)).astype(np.float32)[s.vertex_replica_np()]
        assert np.array_equal(f.particles.diameter, d)
        assert f.configuration.dimensions == 3
        assert np.array_equal(f.log["particles/replica"], s.vertex_replica_np())


def test_box_never_shrinks(tmp_path):
    path = tmp_path / "grow.gsd"
    sim = svm.Simulation(device="cpu")
    with GSD(filename=path) as w:
        sim.state = svm.init.random_tiling(16, seed=1, radius=3.0)
        w.write(sim, 0)
        sim.state = svm.init.random_tiling(16, seed=1, radius=1.0)
        w.write(sim, 1)
    with gsd.hoomd.open(path) as t:
        assert t[1].configuration.box[0] == t[0].configuration.box[0] >= 2.2 * 3.0


def test_fallbacks_for_a_surface_without_areas_or_lengths(tmp_path):
    path = tmp_path / "fallback.gsd"
    s = svm.State.concatenate([svm.init.random_tiling(16, seed=1), svm.init.random_tiling(24, seed=2, radius=2.0)])
    s = svm.State(s.positions, s.cell_vertices, s.cell_sides, s.vertex_neighbors, s.vertex_cells, s.vertex_start,
                  s.cell_start, s.radius, constraint=SphereWithoutAreas(), validate=False)
    sim = svm.Simulation(device="cpu")
    sim.state = s
    w = gsdio.FrameWriter.__new__(gsdio.FrameWriter)
    with gsd.hoomd.open(path, "w") as t:
        w.__init__(t)
        w.append(s, 3, {}, {}, {})
    bonds = topology.edges(s.vertex_neighbors)
    chord = np.linalg.norm(s.positions[bonds[:, 0]] - s.positions[bonds[:, 1]], axis=1)
    rep = s.vertex_replica_np()[bonds[:, 0]]
    want = np.array([0.25 * chord[rep == r].mean() for r in range(2)], dtype=np.float32)
    with gsd.hoomd.open(path) as t:
        f = t[0]
        assert np.allclose(f.particles.diameter, want[s.vertex_replica_np()], rtol=1e-6)
        assert np.array_equal(f.log["bonds/length"], chord)
    back = gsdio.read_state(path)
    assert type(back.constraint) is SphereWithoutAreas
    assert np.array_equal(back.positions, s.positions)


def test_constraint_json_round_trip_and_errors(tmp_path):
    raw = gsdio._constraint_json(Sphere())
    assert isinstance(gsdio._constraint_from_json(raw, "p"), Sphere)
    with pytest.raises(ValueError, match="not valid JSON"):
        gsdio._constraint_from_json(np.frombuffer(b"{nope", dtype=np.uint8), "p")
    with pytest.raises(ValueError, match="unknown constraint 'nowhere'"):
        gsdio._constraint_from_json(np.frombuffer(b'{"name": "nowhere"}', dtype=np.uint8), "p")
    with pytest.raises(ValueError, match="cannot rebuild constraint"):
        gsdio._constraint_from_json(np.frombuffer(b'{"name": "sphere", "params": {"bogus": 1}}', dtype=np.uint8), "p")


def test_reader_rejects_non_paths():
    with pytest.raises(TypeError, match="path must be a file path"):
        gsdio.Reader(3)


class ScaledSphere(Sphere):
    """A user surface with a public parameter (stored) and a private attribute (not stored)."""
    name = "scaled_sphere_for_mutants"

    def __init__(self, scale=1.0):
        super().__init__()
        self.scale = scale
        self._calls = 0


def test_constraint_parameters_round_trip_private_ones_left_out():
    raw = gsdio._constraint_json(ScaledSphere(scale=2.5))
    import json
    spec = json.loads(bytes(raw).decode())
    assert spec == {"name": "scaled_sphere_for_mutants", "class": "ScaledSphere", "params": {"scale": 2.5}}
    back = gsdio._constraint_from_json(raw, "p")
    assert type(back) is ScaledSphere and back.scale == 2.5


def test_box_of_a_small_sphere(tmp_path):
    # every extent below 1: the box follows the radius, with no floor at 1
    path = tmp_path / "small.gsd"
    sim = svm.Simulation(device="cpu")
    sim.state = svm.init.random_tiling(32, seed=1, radius=0.3)
    with GSD(filename=path) as w:
        w.write(sim, 0)
    s = sim.state
    bonds = topology.edges(s.vertex_neighbors)
    chord = np.linalg.norm(s.positions[bonds[:, 0]] - s.positions[bonds[:, 1]], axis=1)
    extent = max(0.3, np.abs(s.positions).max(), chord.max())
    with gsd.hoomd.open(path) as t:
        assert t[0].configuration.box[0] == np.float32(2.2 * extent * (1 + 1e-6))


# ---------------------------------------------------------------- the full pass (every site of gsdio.py)
def _one_frame(path, state, checkpoint=None, mode="w"):
    with gsd.hoomd.open(path, mode) as t:
        gsdio.FrameWriter(t).append(state, len(t), {}, {}, {}, checkpoint)


def test_reading_validates_by_default(tmp_path):
    path = tmp_path / "bad.gsd"
    s = svm.init.random_tiling(16, seed=1)
    s.vertex_neighbors[[0, 1]] = s.vertex_neighbors[[1, 0]]     # tables no longer reciprocal
    _one_frame(path, s)
    with pytest.raises(ValueError, match="the stored state is invalid.*validate=False reads it anyway"):
        gsdio.read_state(path)
    with gsdio.Reader(path) as r:
        with pytest.raises(ValueError, match="the stored state is invalid"):
            r.state()
        assert np.array_equal(r.state(validate=False).vertex_neighbors, s.vertex_neighbors)
    assert gsdio.read_state(path, validate=False).n_cells == 16


def _damaged(tmp_path, name, damage):
    """A one-frame spherevm file whose chunk ``spherevm/<name>`` is replaced by ``damage(chunk)``
    (left out where that is None), without spherevm/checksum (which would refuse any change first)."""
    good, bad = tmp_path / "good.gsd", tmp_path / "bad.gsd"
    _one_frame(good, svm.init.random_tiling(16, seed=1))
    with gsd.hoomd.open(good) as t:
        frame = t[0]
        chunks = {n: t.file.read_chunk(frame=0, name=n) for n in t.file.find_matching_chunk_names("spherevm/")
                  if n != gsdio.CHECKSUM}
    chunks["spherevm/" + name] = damage(chunks["spherevm/" + name])
    with gsd.hoomd.open(bad, "w") as t:
        for n, a in chunks.items():
            if a is not None:
                t.file.write_chunk(n, np.ascontiguousarray(a))
        t.append(frame)
    return bad


@pytest.mark.parametrize("name, damage", [
    ("position", lambda a: a[:, :2]), ("vertex_neighbors", lambda a: a[:-1]),
    ("vertex_cells", lambda a: a[:, :2]), ("cell_vertices", lambda a: a[:-1])])
def test_inconsistent_chunk_shapes_are_refused_even_without_validation(tmp_path, name, damage):
    bad = _damaged(tmp_path, name, damage)
    for validate in (True, False):
        with pytest.raises(ValueError, match=f"frame 0, chunk 'spherevm/{name}': expected shape"):
            gsdio.read_state(bad, validate=validate)


def test_a_missing_chunk_is_named(tmp_path):
    bad = _damaged(tmp_path, "cell_start", lambda a: None)
    with pytest.raises(ValueError, match="frame 0 lacks chunk 'spherevm/cell_start'"):
        gsdio.read_state(bad, validate=False)


def test_checkpoint_chunks_round_trip_and_default_to_the_last_frame(tmp_path):
    path = tmp_path / "ck.gsd"
    s = svm.init.random_tiling(16, seed=1)
    saved = [{"op/mine/flag": np.array([True, False, True]), "op/mine/v": np.linspace(0.1, 0.9, 4) * k,
              "simulation/count": np.int64(k)} for k in (1, 2, 3)]
    for k, ck in enumerate(saved):
        _one_frame(path, s, ck, mode="w" if k == 0 else "a")
    with gsdio.Reader(path) as r:
        assert len(r) == 3
        for frame, k in ((None, 2), (-1, 2), (1, 1), (0, 0)):
            got = r.checkpoint() if frame is None else r.checkpoint(frame)
            assert got["simulation"]["count"].tolist() == [k + 1]
            assert got["op"]["mine"]["flag"].dtype == np.uint8
            assert got["op"]["mine"]["flag"].tolist() == [1, 0, 1]
            assert got["op"]["mine"]["v"].tobytes() == saved[k]["op/mine/v"].tobytes()


def test_appending_to_a_one_frame_file_keeps_its_box_and_per_vertex_keys(tmp_path):
    """A file of exactly one frame, reopened: the box does not shrink and frame 0's per-vertex
    keys are written (NaN) in a later frame that lacks them, with that frame's length."""
    path = tmp_path / "one.gsd"
    sim = svm.Simulation(device="cpu")
    sim.state = svm.init.random_tiling(16, seed=1, radius=3.0)
    sim.operations.forces.append(svm.plugins.forces.VertexModel.dimensionless(kr=1.0, p0=3.8))
    with GSD(filename=path) as w:
        w.write(sim, 0)
    sim.operations.forces.clear()
    sim.state = svm.init.random_tiling(24, seed=2, radius=1.0)
    with GSD(filename=path, mode="ab") as w:
        w.write(sim, 1)
    with gsd.hoomd.open(path) as t:
        assert t[1].configuration.box[0] == t[0].configuration.box[0] >= 2.2 * 3.0
        assert t[1].log["particles/force"].shape == (t[1].particles.N, 3) != t[0].log["particles/force"].shape
        assert np.all(np.isnan(t[1].log["particles/force"]))


def test_one_writer_a_frame_like_the_last_not_the_first(tmp_path):
    """Frames A, B, B from one writer (never closed): the third keeps B's topology."""
    from conftest import assert_same_state, snapshot
    from test_gsd_topology import flip_somewhere
    path = tmp_path / "abb.gsd"
    sim = svm.Simulation(device="cpu")
    sim.state = svm.init.random_tiling(24, seed=3)
    refs = []
    with GSD(trigger=1, filename=path) as w:
        for step in range(3):
            if step == 1:
                flip_somewhere(sim.state, np.random.default_rng(1))
                sim.state_changed()
            w.write(sim, step)
            refs.append(snapshot(sim.state))
    for i, ref in enumerate(refs):
        assert_same_state(gsdio.read_state(path, frame=i), ref, f"frame {i}")


class SphereKeepingItsName(Sphere):
    """A user subclass that keeps the parent's ``name``: the stored class name tells them apart."""


def test_constraint_class_is_chosen_by_name_and_class():
    for constraint in (Sphere(), SphereKeepingItsName()):
        assert constraint.name == "sphere"
        back = gsdio._constraint_from_json(gsdio._constraint_json(constraint), "p")
        assert type(back) is type(constraint)


@pytest.mark.parametrize("value", ["nv", -2])
def test_cell_vertex_outside_the_vertex_range_is_named(tmp_path, value):
    path = tmp_path / "range.gsd"
    s = svm.init.random_tiling(16, seed=1)
    s.cell_vertices[3, 0] = s.n_vertices if value == "nv" else value
    _one_frame(path, s)
    with pytest.raises(ValueError, match=rf"cell_vertices of cell 3 is .*outside -1..{s.n_vertices - 1}") as err:
        gsdio.read_state(path)
    assert "validate=False reads it anyway" in str(err.value)
    assert gsdio.read_state(path, validate=False).cell_vertices[3, 0] == s.cell_vertices[3, 0]


def test_an_integer_per_vertex_key_missing_from_a_later_frame_is_minus_one(tmp_path):
    path = tmp_path / "tags.gsd"
    a, b = svm.init.random_tiling(16, seed=1), svm.init.random_tiling(24, seed=2)
    with gsd.hoomd.open(path, "w") as t:
        w = gsdio.FrameWriter(t)
        w.append(a, 0, {}, {}, {"tag": np.arange(a.n_vertices, dtype=np.int32)})
        w.append(b, 1, {}, {}, {})
    with gsd.hoomd.open(path) as t:
        tag = t[1].log["particles/tag"]
        assert tag.dtype == np.int32 and tag.tolist() == [-1] * b.n_vertices


def test_reopened_file_leaves_out_topology_equal_to_frame_0(tmp_path):
    """Frames A, A (frame 1 stores no topology), closed, reopened, A again: left out again."""
    path = tmp_path / "aaa.gsd"
    sim = svm.Simulation(device="cpu")
    sim.state = svm.init.random_tiling(16, seed=1)
    with GSD(trigger=1, filename=path) as w:
        w.write(sim, 0)
        w.write(sim, 1)
    with GSD(trigger=1, filename=path, mode="ab") as w:
        w.write(sim, 2)
    with gsd.hoomd.open(path) as t:
        for name in gsdio.TOPOLOGY:
            assert [t.file.chunk_exists(frame=i, name="spherevm/" + name) for i in range(3)] == [True, False, False]


def test_reopened_file_takes_the_last_frame_box_and_keys_first_seen_there(tmp_path):
    """Frames at radius 1 without forces, then radius 3 with forces; reopened, a frame at radius 1
    without forces keeps the last (largest) box and writes the force key, NaN."""
    path = tmp_path / "last.gsd"
    sim = svm.Simulation(device="cpu")
    with GSD(trigger=1, filename=path) as w:
        sim.state = svm.init.random_tiling(16, seed=1, radius=1.0)
        w.write(sim, 0)
        sim.state = svm.init.random_tiling(16, seed=1, radius=3.0)
        sim.operations.forces.append(svm.plugins.forces.VertexModel.dimensionless(kr=1.0, p0=3.8))
        w.write(sim, 1)
    sim.operations.forces.clear()
    sim.state = svm.init.random_tiling(16, seed=1, radius=1.0)
    with GSD(trigger=1, filename=path, mode="ab") as w:
        w.write(sim, 2)
    with gsd.hoomd.open(path) as t:
        assert t[0].configuration.box[0] < t[1].configuration.box[0] == t[2].configuration.box[0]
        assert t[2].log["particles/force"].shape == (t[2].particles.N, 3)
        assert np.all(np.isnan(t[2].log["particles/force"]))


def test_planar_frame_positions_are_centred_in_the_largest_box(tmp_path):
    path = tmp_path / "plane.gsd"
    s = svm.State.concatenate([svm.init.random_planar_tiling(16, seed=1, box=(4.0, 5.0)),
                               svm.init.random_planar_tiling(16, seed=2, box=(6.0, 3.0))])
    _one_frame(path, s)
    with gsd.hoomd.open(path) as t:
        f = t[0]
    assert f.configuration.box.tolist() == [6.0, 5.0, 0.0, 0.0, 0.0, 0.0] and f.configuration.dimensions == 2
    assert np.array_equal(f.particles.position, (s.positions - [3.0, 2.5, 0.0]).astype(np.float32))
    assert np.all(f.particles.position[:, 2] == 0)
