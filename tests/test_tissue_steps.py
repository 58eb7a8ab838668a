"""The fused small-tissue steps (spherevm.tissue_steps): bitwise the general kernels' trajectory.

Each GPU test runs the same Simulation three ways: fused (a thread block per tissue, a stretch of
steps per launch), the general kernels in CUDA graphs (``fused=False``) and step by step
(``graphs=False``), and compares every array of the State bitwise, T1's counters, the flip log's
pass number and the table width the host sees. Hot dynamics make T1 flip and widen the cell table
every few steps; ensembles mix tissue sizes, and a 1,500-cell tissue has more vertices than a
block has threads.
"""
import numpy as np
import pytest

import spherevm as svm
from spherevm import tissue_steps
from spherevm.plugins.forces import Bending
from spherevm.plugins.integrators import Active, Brownian

from conftest import dynamics_simulation, snapshot

pytestmark = pytest.mark.filterwarnings("ignore::RuntimeWarning")

WAYS = (dict(), dict(fused=False), dict(graphs=False))   # fused (the default), graphs, step by step


def ensemble(surface, sizes):
    tiling = svm.init.random_planar_tiling if surface == "plane" else svm.init.random_tiling
    return svm.State.concatenate([tiling(n, seed=3 + i) for i, n in enumerate(sizes)])


def three_runs(state, steps, t1=True, T=0.3, **run):
    """``(snapshot, timestep, T1 counters)`` of the same run, fused, in graphs and step by step."""
    out = []
    for way in WAYS:
        sim = dynamics_simulation(state, "gpu", Brownian(dt=0.01, T=T))
        if not t1:
            sim.operations.updaters.clear()
        sim.run(steps, **run, **way)
        counters = ()
        if t1:
            u = sim.operations.updaters[0]
            u._sync_counters()
            counters = (u.total_flips, u.total_refused, u.last_flips, u.last_refused,
                        int(u._gpu["log_pass"].get()[0]))
        out.append((snapshot(sim.state), sim.timestep, counters))
    return out


def assert_same(runs):
    ref, timestep, counters = runs[-1]
    for way, (snap, ts, count) in zip(("fused", "graphs"), runs[:-1]):
        assert ts == timestep, way
        for key in ref:
            assert snap[key].shape == ref[key].shape, (way, key)
            assert snap[key].tobytes() == ref[key].tobytes(), (way, key)
        for a, b in zip(count, counters):
            assert np.array_equal(a, b), way


@pytest.mark.gpu
@pytest.mark.parametrize("surface", ["sphere", "plane"])
def test_hot_ensemble_is_the_general_kernels_trajectory(surface):
    state = ensemble(surface, (40, 150))
    width = state.max_sides
    runs = three_runs(state, 437, check_every=100)
    assert_same(runs)
    assert runs[-1][2][0].sum() > 437, "hot enough that T1 flips every step"
    assert runs[-1][0]["cell_vertices"].shape[1] > width, "the cell table widened during the run"


@pytest.mark.gpu
@pytest.mark.parametrize("per_block, cluster", [(10 ** 6, 1), (1200, 2), (600, 4), (300, 8)])
def test_a_large_tissue_on_one_block_or_a_cluster(monkeypatch, per_block, cluster):
    """A 1,200-cell tissue beside a small one: on one block (more vertices than threads: each thread
    loops) and spread over clusters of 2, 4 and 8 blocks (distributed shared memory)."""
    monkeypatch.setattr(tissue_steps, "VERTICES_PER_BLOCK", per_block)
    state = ensemble("sphere", (1200, 32))
    assert tissue_steps.cluster_size(state) == cluster
    assert state.vertices_per_replica.max() > tissue_steps.THREADS
    runs = three_runs(state, 150, T=0.2, check_every=64)
    assert_same(runs)
    assert runs[-1][2][0][0] > 0, "T1 flipped in the large tissue"


@pytest.mark.gpu
def test_without_t1_and_between_writes():
    """No updater at all; and stretches cut by a writer and by checks that do not divide 64."""
    assert_same(three_runs(ensemble("sphere", (100, 30)), 203, t1=False, check_every=37))


@pytest.mark.gpu
def test_the_fused_steps_are_chosen_only_where_they_apply():
    sim = dynamics_simulation(ensemble("sphere", (40, 50)), "gpu", Brownian(dt=0.01, T=0.1))
    assert tissue_steps.why_not(sim) is None
    sim.operations.updaters[0].count_flip_backs = True
    assert "flip-backs" in tissue_steps.why_not(sim)
    sim = dynamics_simulation(ensemble("sphere", (40,)), "gpu", Active(dt=0.01, v0=0.1, Dr=0.1))
    assert "Active" in tissue_steps.why_not(sim)
    sim = dynamics_simulation(ensemble("sphere", (40,)), "gpu", Brownian(dt=0.01))
    sim.operations.forces.append(Bending(0.1))
    assert "one VertexModel" in tissue_steps.why_not(sim)
    sim = dynamics_simulation(ensemble("sphere", (2500,)), "gpu", Brownian(dt=0.01))
    assert "shared memory" in tissue_steps.why_not(sim)
    with pytest.raises(ValueError, match="fused must be None"):
        sim.run(10, fused=True)


def test_the_fused_steps_need_the_gpu():
    sim = dynamics_simulation(ensemble("plane", (16,)), "cpu", Brownian(dt=0.01))
    assert "GPU" in tissue_steps.why_not(sim)
    state = ensemble("sphere", (40, 100))
    # 2 x 100 - 4 = 196 vertices on a sphere; on 1 block and on 2
    assert tissue_steps.shared_bytes(state, 1) == 8 * (6 * 196 + 2 * 100 + 3 * 196) + 4 * 100
    assert tissue_steps.shared_bytes(state, 2) == 8 * (6 * 196 + 2 * 100 + 3 * 98) + 4 * 100
    assert tissue_steps.cluster_size(state) == 1
    big = ensemble("sphere", (1024,))
    assert tissue_steps.cluster_size(big) == 2                      # 2,044 vertices: two blocks
    assert tissue_steps.cluster_size(big, n_sm=1) == 1              # ... unless the SMs run out

