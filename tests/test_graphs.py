"""CUDA graphs (spherevm.graphs): a run in graphs is bitwise the step-by-step run.

Each GPU test runs the same Simulation twice, ``run(graphs=True)`` and ``run(graphs=False)``, and
compares every array of the State (positions bitwise, the topology and the cell table's width
exactly), T1's counters and what writers saw on the way. Hot dynamics make T1 flip every step and
widen the cell table, so the device-side candidate count and width are exercised.
"""
import numpy as np
import pytest

import spherevm as svm
from spherevm import graphs
from spherevm.plugins.forces import Bending
from spherevm.plugins.integrators import FIRE, Active, Brownian
from spherevm.plugins.updaters import T1

from conftest import Snapshots, dynamics_simulation, snapshot

pytestmark = pytest.mark.filterwarnings("ignore::RuntimeWarning")


def hot_ensemble(surface):
    """Two tissues of different sizes in one ensemble (sphere or plane)."""
    if surface == "plane":
        parts = [svm.init.random_planar_tiling(n, seed=s) for n, s in ((40, 3), (150, 4))]
    else:
        parts = [svm.init.random_tiling(n, seed=s) for n, s in ((40, 3), (150, 4))]
    return svm.State.concatenate(parts)


def twin_runs(state, integrator, steps, writer_steps=(0,), forces=(), **run):
    """The same run with and without graphs: ``(state snapshot, T1 totals, writer snapshots)`` each.
    ``forces``: callables making forces added to the vertex model."""
    out = []
    for use in (True, False):
        sim = dynamics_simulation(state, "gpu", integrator())
        sim.operations.forces.extend(make() for make in forces)
        writer = Snapshots(list(writer_steps))
        sim.operations.writers.append(writer)
        sim.run(steps, graphs=use, **run)
        t1 = sim.operations.updaters[0]
        out.append((snapshot(sim.state), sim.timestep, t1.loggables["t1_total_flips"](sim),
                    t1.loggables["t1_total_refused"](sim), writer))
    return out


def assert_twins(graph, step):
    (ref_g, ts_g, flips_g, refused_g, w_g), (ref_s, ts_s, flips_s, refused_s, w_s) = graph, step
    assert ts_g == ts_s
    for key in ref_s:
        assert ref_g[key].shape == ref_s[key].shape, key
        assert ref_g[key].tobytes() == ref_s[key].tobytes(), key
    assert np.array_equal(flips_g, flips_s) and np.array_equal(refused_g, refused_s)
    assert w_g.steps == w_s.steps
    for a, b in zip(w_g.refs, w_s.refs):
        for key in b:
            assert a[key].shape == b[key].shape and a[key].tobytes() == b[key].tobytes(), key


@pytest.mark.gpu
@pytest.mark.parametrize("surface", ["sphere", "plane"])
def test_brownian_with_t1_in_graphs_is_the_step_by_step_run(surface):
    state = hot_ensemble(surface)
    width = state.max_sides
    runs = twin_runs(state, lambda: Brownian(dt=0.01, T=0.3), 437, writer_steps=(1, 2, 3, 50, 129, 300),
                     check_every=100)
    assert_twins(*runs)
    assert runs[1][2].sum() > 437, "hot enough that T1 flips every step"
    assert runs[1][0]["cell_vertices"].shape[1] > width, "the cell table widened during the run"


@pytest.mark.gpu
def test_active_cell_directors_in_graphs_are_the_step_by_step_run():
    state = hot_ensemble("sphere")
    runs = twin_runs(state, lambda: Active(dt=0.01, v0=0.5, Dr=1.0, T=0.01), 203, check_every=50)
    assert_twins(*runs)


@pytest.mark.gpu
def test_bending_fused_in_graphs_is_the_step_by_step_run():
    """VertexModel + Bending (the fused kernels, per-replica B) while T1 flips every step: the
    bending kernels walk the neighbours from the State's arrays, so graphs hold them as they are."""
    state = hot_ensemble("sphere")
    runs = twin_runs(state, lambda: Brownian(dt=0.01, T=0.3), 211, writer_steps=(1, 77, 150),
                     forces=[lambda: Bending([0.02, 0.1])], check_every=70)
    assert_twins(*runs)
    assert runs[1][2].sum() > 211, "hot enough that T1 flips every step"


@pytest.mark.gpu
def test_run_after_minimize_and_with_progress_callbacks():
    """The first step after a minimisation skips updaters that already ran; a progress callback
    sees the trimmed table and may change the State: the graphs are captured again."""
    state = hot_ensemble("sphere")
    results = []
    for use in (True, False):
        sim = dynamics_simulation(state, "gpu", FIRE(dt=0.02))
        sim.minimize(force_tol=1e-6, max_steps=50)
        sim.operations.integrator = Brownian(dt=0.01, T=0.2)
        widths = []

        def progress(done, total, sim=sim, widths=widths):
            widths.append(sim.state.max_sides)                  # the table as the host sees it
            sim.state.positions = sim.state.positions * 1.0     # a new array: the graphs must follow
        sim.run(180, check_every=40, progress=progress, graphs=use)
        results.append((snapshot(sim.state), widths))
    for key in results[1][0]:
        assert results[0][0][key].tobytes() == results[1][0][key].tobytes(), key
    assert results[0][1] == results[1][1]


@pytest.mark.gpu
def test_exploding_step_in_graphs_names_the_same_timestep():
    messages = []
    for use in (True, False):
        sim = dynamics_simulation(hot_ensemble("sphere"), "gpu", Brownian(dt=5.0, T=50.0))
        with pytest.raises(FloatingPointError) as err:
            sim.run(100, check_every=100, graphs=use)
        messages.append(str(err.value))
    assert messages[0] == messages[1]
    assert "exploding step at timestep" in messages[0]


class UserForce(svm.plugins.Force):
    """A user's force that does not declare ``capture_ready``: no forces, zero energy."""

    def compute(self, state):
        xp = state.device.xp
        return svm.plugins.ForceResult(forces=xp.zeros_like(state.positions), energy=xp.zeros(state.n_replicas))


@pytest.mark.gpu
def test_operations_that_cannot_run_in_graphs_are_named():
    sim = dynamics_simulation(hot_ensemble("sphere"), "gpu", Brownian(dt=0.01, T=0.01))
    sim.operations.forces.append(UserForce())
    with pytest.raises(ValueError, match="UserForce cannot run inside a CUDA graph"):
        sim.run(10, graphs=True)
    sim = dynamics_simulation(hot_ensemble("sphere"), "gpu", Brownian(dt=0.01, T=0.01))
    sim.operations.updaters[0] = T1(count_flip_backs=True)
    with pytest.raises(ValueError, match="T1 cannot run inside a CUDA graph"):
        sim.run(10, graphs=True)
    sim.operations.updaters[0] = T1(trigger=2)
    with pytest.raises(ValueError, match="does not fire every step"):
        sim.run(10, graphs=True)
    sim.run(10)        # auto: step by step, no error


def test_graphs_need_the_gpu_and_a_clear_choice():
    sim = dynamics_simulation(hot_ensemble("sphere"), "cpu", Brownian(dt=0.01, T=0.01))
    with pytest.raises(ValueError, match="need the GPU"):
        sim.run(5, graphs=True)
    with pytest.raises(ValueError, match="graphs must be None"):
        graphs.StepGraphs.for_run(sim, 5, "yes")
    assert graphs.StepGraphs.for_run(sim, 10_000, None) is None      # auto on the CPU: step by step
    sim.run(5)
    assert sim.timestep == 5


@pytest.mark.gpu
def test_an_operation_that_reads_back_inside_a_graph_gets_a_clear_error():
    from spherevm.plugins.forces import VertexModel

    class ReadsBack(VertexModel):
        def _compute_gpu(self, state):
            result = super()._compute_gpu(state)
            float(result.energy.sum())          # a read-back: not possible inside a CUDA graph
            return result

    sim = dynamics_simulation(hot_ensemble("sphere"), "gpu", Brownian(dt=0.01, T=0.01))
    sim.operations.forces[0] = ReadsBack.dimensionless(kr=1.0, p0=3.75)
    with pytest.raises(RuntimeError, match="capturing steps into a CUDA graph failed"):
        sim.run(20, graphs=True)
    sim.run(20, graphs=False)                   # the device works on, step by step
    assert sim.timestep >= 20


@pytest.mark.gpu
def test_a_pass_with_more_candidates_than_the_step_by_step_room():
    """Inside a graph T1 has room for a candidate per edge: a first pass with more candidates than
    the step-by-step path's first room (max(1024, V/4)) is the same pass."""
    from spherevm.plugins.updaters import T1
    state = svm.init.random_tiling(2500, seed=8)
    rules = dict(threshold=0.55, new_length=0.8)   # about 2,500 candidates, 600 refused
    u, _, _ = T1(**rules).short_edges(state)
    assert len(u) - 700 > max(1024, state.n_vertices // 4), "more candidates than the first room"
    out = []
    for use in (True, False):
        sim = dynamics_simulation(state, "gpu", Brownian(dt=0.001, T=1e-4))
        sim.operations.updaters[0] = T1(**rules)
        sim.run(20, graphs=use)
        out.append((snapshot(sim.state), sim.log("t1_total_flips")))
    for key in out[1][0]:
        assert out[0][0][key].tobytes() == out[1][0][key].tobytes(), key
    assert np.array_equal(out[0][1], out[1][1]) and out[1][1].sum() > 100
