"""CUDA graphs (spherevm.graphs): a run in graphs is bitwise the step-by-step run.

Each GPU test runs the same Simulation twice, ``run(graphs=True)`` and ``run(graphs=False)``, and
compares every array of the State (positions bitwise, the topology and the cell table's width
exactly), T1's counters and what writers saw on the way. Hot dynamics make T1 flip every step and
widen the cell table, so the device-side candidate count and width are exercised.
"""
import numpy as np
import pytest

from spherevm.plan import Plan

import spherevm as svm
from spherevm import graphs
from spherevm.plugins.forces import Bending
from spherevm.plugins.integrators import FIRE, Active, Brownian
from spherevm.plugins.updaters import T1

from conftest import (Snapshots, assert_same_minimizations, dynamics_simulation, minimizations, snapshot,
                      sweep_like)

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
    bending kernels walk the neighbours from the State's arrays, so graphs hold them as they are
    (``fused=False``: the fused small-tissue steps would take these tissues, test_tissue_steps.py)."""
    state = hot_ensemble("sphere")
    runs = twin_runs(state, lambda: Brownian(dt=0.01, T=0.3), 211, writer_steps=(1, 77, 150),
                     forces=[lambda: Bending([0.02, 0.1])], check_every=70, fused=False)
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
    with pytest.raises(ValueError, match="UserForce has no capture_ready"):
        sim.run(10, graphs=True)
    sim = dynamics_simulation(hot_ensemble("sphere"), "gpu", Brownian(dt=0.01, T=0.01))
    sim.operations.integrator = FIRE(check_every=10)      # a convergence check would fall inside
    with pytest.raises(ValueError, match="FIRE cannot run inside a CUDA graph"):
        sim.run(30, graphs=True)
    sim.operations.integrator = Brownian(dt=0.01, T=0.01)
    sim.operations.updaters[0] = T1(trigger=2)
    with pytest.raises(ValueError, match="does not fire every step"):
        sim.run(10, graphs=True)
    sim.run(10)        # auto: step by step, no error


def test_graphs_need_the_gpu_and_a_clear_choice():
    sim = dynamics_simulation(hot_ensemble("sphere"), "cpu", Brownian(dt=0.01, T=0.01))
    with pytest.raises(ValueError, match="need the GPU"):
        sim.run(5, graphs=True)
    with pytest.raises(ValueError, match="graphs must be None"):
        graphs.StepGraphs.for_run(Plan(sim), 5, "yes")
    assert graphs.StepGraphs.for_run(Plan(sim), 10_000, None) is None      # auto on the CPU: step by step
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


# ---------------------------------------------------------------------------------------- minimize
def twin_minimizations(state, p0, calls=({},), t1=None):
    """The same minimisation(s) in graphs (the general kernels) and step by step."""
    return minimizations(state, p0, (dict(graphs=True, fused=False), dict(graphs=False)), calls, t1)


@pytest.mark.gpu
def test_minimize_in_graphs_is_the_step_by_step_minimisation():
    """A sweep-like chunk (12 replicas, p0 3.6 to 3.95): replicas stop at different checks, the State
    narrows twice, T1 flips and logs its flips for the flip-back memory inside the graphs."""
    state = svm.init.random_tiling(64, replicas=12, seed=5)
    p0 = np.linspace(3.6, 3.95, 12)
    graph, step = twin_minimizations(state, p0, calls=({"max_steps": 20_000},))
    assert_same_minimizations(graph, step)
    steps = np.array(step["results"][0][1])
    assert len(set(steps.tolist())) > 3, "replicas stopped at different checks (narrowing)"
    assert step["flips"].sum() > 0 and len(step["separated"]) > 0, "T1 flipped and kept its memory"


@pytest.mark.gpu
def test_minimize_in_graphs_halts_oscillating_replicas_as_step_by_step():
    """Long T1 thresholds make pairs of cells flip back and forth: the replicas halted for
    ``t1_oscillation`` (read from the flip log replayed at checks) are the step-by-step ones."""
    state = svm.init.random_tiling(80, replicas=6, seed=9)
    graph, step = twin_minimizations(state, np.full(6, 3.9), calls=({"max_steps": 3_000},),
                                     t1=dict(threshold=0.3, new_length=0.45, max_flip_backs=3))
    assert_same_minimizations(graph, step)
    assert "t1_oscillation" in step["results"][0][0], "some replica was halted"
    assert step["rejoins"].sum() > 0


@pytest.mark.gpu
def test_minimize_resumed_in_graphs_is_one_minimisation():
    """``max_steps`` that is no multiple of the check interval, then a resumed call: the stretches
    end at the limit as step by step."""
    state = svm.init.random_tiling(100, replicas=4, seed=12)
    graph, step = twin_minimizations(state, np.array([3.7, 3.8, 3.85, 3.9]),
                                     calls=({"max_steps": 137}, {"max_steps": 205, "resume": True}))
    assert_same_minimizations(graph, step)
    assert "max_steps" in step["results"][0][0], "the first call stopped at its limit, not at a check"


@pytest.mark.gpu
def test_minimize_graphs_refusals():
    sim = sweep_like(svm.init.random_tiling(64, replicas=2, seed=1), [3.7, 3.9])
    sim.operations.writers.append(Snapshots([0]))
    with pytest.raises(ValueError, match="a writer is attached"):
        sim.minimize(max_steps=100, graphs=True)
    sim.operations.writers.clear()
    sim.operations.forces.append(UserForce())
    with pytest.raises(ValueError, match="UserForce has no capture_ready"):
        sim.minimize(max_steps=100, graphs=True)
    result = sim.minimize(max_steps=100)           # auto: step by step from the refusal on
    assert result.steps.max() <= 100


@pytest.mark.gpu
def test_flip_log_in_graphs_has_room_for_each_stretch():
    """Flip-back bookkeeping in graphs (``count_flip_backs=True`` under Brownian dynamics): with the
    log cut to four rows, a stretch whose flips might not fit must replay and grow it first, so
    nothing is written past its end; the flip-back memory is the step-by-step run's."""
    import cupy as cp
    out = []
    for use in (True, False):
        sim = dynamics_simulation(hot_ensemble("sphere"), "gpu", Brownian(dt=0.01, T=0.3))
        sim.operations.updaters[0] = t1 = T1(count_flip_backs=True)
        sim.run(1)                                   # step by step: the device buffers exist
        guard = cp.full((64, 6), -7, dtype=cp.int32)
        t1._gpu_buffers(sim.state)["log"] = guard[:4]
        sim.run(100, check_every=50, graphs=use)
        assert bool((guard[4:] == -7).all()), "a pass wrote past the end of the flip log"
        t1._sync_counters()
        out.append((snapshot(sim.state), t1._separated.copy(), t1._rejoins.copy(), t1.flip_backs.copy()))
    (a, *memory_a), (b, *memory_b) = out
    for key in b:
        assert a[key].tobytes() == b[key].tobytes(), key
    for x, y in zip(memory_a, memory_b):
        assert np.array_equal(x, y)
    assert memory_b[1].sum() > 0, "pairs were joined again"
