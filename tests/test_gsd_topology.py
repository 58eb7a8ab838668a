"""GSD round trips across topology changes, in every mode, and restarts that append after T1s.

Every frame written is read back and compared exactly (bitwise positions, identical tables) with
what the State held when it was written: in "wb" files, in files appended to ("ab") after being
closed, from any frame (positive and negative indices), and across a restart from the last frame.
A frame whose topology equals the last frame's but not frame 0's is the case that matters: the
writer leaves topology chunks out only when they equal frame 0's.
"""
import gsd.hoomd
import numpy as np

import spherevm as svm
from spherevm import topology
from spherevm.gsdio import Reader, read_state
from spherevm.plugins.forces import VertexModel
from spherevm.plugins.integrators import FIRE
from spherevm.plugins.updaters import T1
from spherevm.plugins.writers import GSD

from conftest import STATE_TOPOLOGY, Snapshots, assert_same_state, snapshot, to_numpy

def same_topology(a, b):
    return all(a[k].shape == b[k].shape and np.array_equal(a[k], b[k]) for k in STATE_TOPOLOGY)


def flip_somewhere(state, rng, length=0.3):
    """One T1 (topology.t1_flip) on a random edge of each replica whose C1, C2 keep >= 3 sides."""
    vn, vc, sides = (to_numpy(a) for a in (state.vertex_neighbors, state.vertex_cells, state.cell_sides))
    us, slots = [], []
    for r in range(state.n_replicas):
        lo, hi = state.vertex_start[r], state.vertex_start[r + 1]
        while True:
            u, slot = int(rng.integers(lo, hi)), int(rng.integers(3))
            *_, C1, C2, C3, C4 = topology.t1_cells(vn, vc, np.array([u]), np.array([slot]))
            cells = {int(C1[0]), int(C2[0]), int(C3[0]), int(C4[0])}
            if sides[C1[0]] > 3 and sides[C2[0]] > 3 and len(cells) == 4:
                us.append(u)
                slots.append(slot)
                break
    topology.t1_flip(state, np.array(us), np.array(slots), length)


def _sim(state):
    sim = svm.Simulation(device="cpu")
    sim.state = state
    sim.operations.forces.append(VertexModel.dimensionless(kr=1.0, p0=3.8))
    sim.operations.integrator = FIRE(dt=0.02)
    return sim


def _write(writer, sim, refs):
    writer.write(sim, sim.timestep)
    refs.append(snapshot(sim.state))
    sim.timestep += 1


def _check_all_frames(path, refs):
    n = len(refs)
    with Reader(path) as r:
        assert len(r) == n
        for i, ref in enumerate(refs):
            assert_same_state(r.state(i), ref, f"frame {i}")
            assert_same_state(r.state(i - n), ref, f"frame {i - n}")
    for i in (0, n // 2, n - 1):
        assert_same_state(svm.init.from_gsd(path, frame=i), refs[i], f"from_gsd frame {i}")
        assert_same_state(read_state(path, frame=i), refs[i], f"read_state frame {i}")


def test_write_then_append_across_topology_changes(tmp_path):
    """wb: A, B, C (each a T1 away from the one before, C also wider); ab: C again, A, B; ab: B."""
    path = tmp_path / "topo.gsd"
    rng = np.random.default_rng(1)
    sim = _sim(svm.init.random_tiling(24, replicas=2, seed=3))
    refs = []
    writer = GSD(1, path, mode="wb")
    A = sim.state.copy()
    _write(writer, sim, refs)                          # A
    flip_somewhere(sim.state, rng)
    B = sim.state.copy()
    _write(writer, sim, refs)                          # B
    while sim.state.max_sides == B.max_sides:          # C: more flips until cell_vertices widens
        flip_somewhere(sim.state, rng)
    C = sim.state.copy()
    _write(writer, sim, refs)                          # C
    writer.close()
    assert not same_topology(refs[1], refs[0]) and not same_topology(refs[2], refs[1])
    assert refs[2]["cell_vertices"].shape[1] > refs[0]["cell_vertices"].shape[1]
    _check_all_frames(path, refs)

    # append to the closed file from a new writer: the last frame's topology first (C != A)
    writer2 = GSD(1, path, mode="ab")
    for s in (C, A, B):
        sim.state.positions = s.positions.copy()
        for k in STATE_TOPOLOGY:
            setattr(sim.state, k, getattr(s, k).copy())
        sim.state.topology_version += 1
        sim.state_changed()
        _write(writer2, sim, refs)
    writer2.close()
    _check_all_frames(path, refs)

    # and once more: append B after a file that ends with B
    writer3 = GSD(1, path, mode="ab")
    _write(writer3, sim, refs)
    writer3.close()
    _check_all_frames(path, refs)
    # frames equal to frame 0's topology leave the chunks out, others keep them
    with gsd.hoomd.open(path) as t:
        stored = [t.file.chunk_exists(frame=i, name="spherevm/vertex_neighbors") for i in range(len(refs))]
    assert stored == [True, True, True, True, False, True, True]


def test_same_writer_closed_and_reopened_appends(tmp_path):
    """A writer that was closed reopens its file in append mode at the next write."""
    path = tmp_path / "reopen.gsd"
    rng = np.random.default_rng(2)
    sim = _sim(svm.init.random_tiling(20, seed=6))
    writer = GSD(1, path, mode="wb")
    refs = []
    _write(writer, sim, refs)
    flip_somewhere(sim.state, rng)
    _write(writer, sim, refs)
    writer.close()
    _write(writer, sim, refs)              # same topology as the last frame, not frame 0
    flip_somewhere(sim.state, rng)
    writer.close()
    _write(writer, sim, refs)
    writer.close()
    _check_all_frames(path, refs)


def _t1_sim(state, device, writers):
    sim = svm.Simulation(device=device)
    sim.state = state
    sim.operations.forces.append(VertexModel.dimensionless(kr=1.0, p0=3.8))
    t1 = T1(threshold=0.3, new_length=0.45)
    sim.operations.updaters.append(t1)
    sim.operations.integrator = FIRE(dt=0.01)
    sim.operations.writers.extend(writers)
    return sim, t1


def test_restart_appends_after_t1s(tmp_path, device):
    """Run with T1s writing every 5 steps; restart a new Simulation from the last frame, append to
    the same file while flipping more; every frame reads back as written."""
    path = tmp_path / "restart.gsd"
    rec1 = Snapshots(trigger=5)
    sim, t1 = _t1_sim(svm.init.random_tiling(50, replicas=2, seed=7), device, [rec1, GSD(5, path)])
    sim.run(30)
    sim.operations.writers[1].close()
    assert rec1.steps == [0, 5, 10, 15, 20, 25, 30]
    assert (sim.log("t1_total_flips") > 0).all()
    assert not same_topology(rec1.refs[-1], rec1.refs[0])      # the case that matters

    sim2 = svm.Simulation(device=device)
    sim2.create_state_from_gsd(path)
    assert_same_state(sim2.state, rec1.refs[-1], "restart")
    with Reader(path) as r:
        sim2.timestep = r.step(-1)
    assert sim2.timestep == 30
    rec2 = Snapshots(trigger=5)
    writer2 = GSD(5, path, mode="ab")
    sim2, t1b = _t1_sim(sim2.state, device, [rec2, writer2])
    sim2.timestep = 30
    sim2.run(30)
    writer2.close()
    assert rec2.steps == [30, 35, 40, 45, 50, 55, 60]
    assert (sim2.log("t1_total_flips") > 0).all()
    refs = rec1.refs + rec2.refs
    _check_all_frames(path, refs)
    with Reader(path) as r:
        assert [r.step(i) for i in range(len(r))] == rec1.steps + rec2.steps
    # the appended segment changed topology too, and the final state restores and is valid
    assert not same_topology(rec2.refs[-1], rec2.refs[0])
    read_state(path).validate(orientation=False)   # T1s at threshold 0.3 may fold a cell
