"""The fused small-tissue steps (spherevm.tissue_steps): bitwise the general kernels' trajectory.

Each GPU test runs the same Simulation three ways: fused (a thread block per tissue, a stretch of
steps per launch), the general kernels in CUDA graphs (``fused=False``) and step by step
(``graphs=False``), and compares every array of the State bitwise, T1's counters, the flip log's
pass number and the table width the host sees. Hot dynamics make T1 flip and widen the cell table
every few steps; ensembles mix tissue sizes, and a 1,100-cell tissue has more vertices than a
block has threads. Minimisations (FIRE + T1) are compared the same way: FIRE's state, the
convergence results and T1's flip-back memory too.
"""
import pathlib

import numpy as np
import pytest

import spherevm as svm
from spherevm import tissue_steps
from spherevm.plan import Plan
from spherevm.plugins.forces import Bending, VertexModel
from spherevm.plugins.integrators import FIRE, Active, Brownian
from spherevm.plugins.updaters import T1

from conftest import assert_same_minimizations, dynamics_simulation, minimizations, snapshot, sweep_like

pytestmark = pytest.mark.filterwarnings("ignore::RuntimeWarning")

WAYS = (dict(), dict(fused=False), dict(graphs=False))   # fused (the default), graphs, step by step


class OtherBending(Bending):
    """A subclass that computes its own force: the bending stage would compute the parent's."""

    def compute(self, state):
        return Bending.compute(self, state)


def ensemble(surface, sizes):
    tiling = svm.init.random_planar_tiling if surface == "plane" else svm.init.random_tiling
    return svm.State.concatenate([tiling(n, seed=3 + i) for i, n in enumerate(sizes)])


def three_runs(state, steps, t1=True, T=0.3, integrator=None, extra=None, arrange=None, **run):
    """``(snapshot, timestep, T1 counters)`` of the same run, fused, in graphs and step by step
    (``integrator()``: another than Brownian, its directors join the snapshot; ``extra()``: a force
    added after the vertex model; ``arrange(forces)``: edits the list of forces)."""
    out = []
    for way in WAYS:
        sim = dynamics_simulation(state, "gpu", Brownian(dt=0.01, T=T) if integrator is None else integrator())
        if extra is not None:
            sim.operations.forces.append(extra())
        if arrange is not None:
            arrange(sim.operations.forces)
        if not t1:
            sim.operations.updaters.clear()
        sim.run(steps, **run, **way)
        counters = ()
        if t1:
            u = sim.operations.updaters[0]
            u._sync_counters()
            counters = (u.total_flips, u.total_refused, u.last_flips, u.last_refused,
                        int(u._gpu["log_pass"].get()[0]))
        snap = snapshot(sim.state)
        if integrator is not None:
            snap["directors"] = sim.operations.integrator.directors.get()
        out.append((snap, sim.timestep, counters))
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
    assert runs[-1][2][1].sum() > 0, "and its checks (a warp a candidate when fused) refused flips"
    assert runs[-1][0]["cell_vertices"].shape[1] > width, "the cell table widened during the run"


@pytest.mark.gpu
@pytest.mark.parametrize("per_block, cluster", [(10 ** 6, 1), (1200, 2), (600, 4), (300, 8)])
def test_a_large_tissue_on_one_block_or_a_cluster(monkeypatch, per_block, cluster):
    """A 1,100-cell tissue beside a small one: on one block (more vertices than threads: each thread
    loops) and spread over clusters of 2, 4 and 8 blocks (distributed shared memory; every block
    detects T1's candidates on its vertices; on 8 blocks of 288 threads two lanes a cell)."""
    monkeypatch.setattr(tissue_steps, "VERTICES_PER_BLOCK", per_block)
    state = ensemble("sphere", (1100, 32))
    assert tissue_steps.cluster_size(state) == cluster
    assert state.vertices_per_replica.max() > tissue_steps.THREADS
    assert tissue_steps.why_not(dynamics_simulation(state, "gpu", Brownian(dt=0.01, T=0.2))) is None
    runs = three_runs(state, 150, T=0.2, check_every=64)
    assert_same(runs)
    assert runs[-1][2][0][0] > 0, "T1 flipped in the large tissue"


@pytest.mark.gpu
@pytest.mark.parametrize("directors", ["cell", "vertex"])
@pytest.mark.parametrize("per_block", [10 ** 6, 300])
def test_active_dynamics_fuse_with_the_general_kernels_bits(monkeypatch, directors, per_block):
    """Active + T1 (cell directors: each cell's director after the move, a phase of its own; vertex
    directors: with each vertex's move), on one block and on clusters: the general kernels' bits."""
    monkeypatch.setattr(tissue_steps, "VERTICES_PER_BLOCK", per_block)
    state = ensemble("sphere", (300, 60))
    active = lambda: Active(dt=0.01, v0=0.5, Dr=0.5, T=0.05, directors=directors)   # noqa: E731
    assert tissue_steps.why_not(dynamics_simulation(state, "gpu", active())) is None
    assert_same(three_runs(state, 150, integrator=active, check_every=64))


@pytest.mark.gpu
@pytest.mark.parametrize("per_block", [10 ** 6, 300])
def test_a_users_force_fuses_with_the_step_by_step_bits(monkeypatch, per_block):
    """The example plugin's line tension (tests/plugin_example: a CUDA string with its force function
    and a fused stage) joins the vertex model, T1 and Brownian dynamics in the fused steps, on one
    block and on clusters: the same trajectory as its own kernel step by step and in graphs."""
    monkeypatch.syspath_prepend(str(pathlib.Path(__file__).parent / "plugin_example"))
    from spherevm_line_tension import FastLineTension
    monkeypatch.setattr(tissue_steps, "VERTICES_PER_BLOCK", per_block)
    state = ensemble("sphere", (300, 60))
    sim = dynamics_simulation(state, "gpu", Brownian(dt=0.01, T=0.2))
    sim.operations.forces.append(FastLineTension(0.3))
    assert tissue_steps.why_not(sim) is None
    assert "fused" in sim.explain()
    assert_same(three_runs(state, 150, T=0.2, extra=lambda: FastLineTension(0.3), check_every=64))


# The bending force beside the vertex model (Force.combined: one stage), or alone, and the temperature
# of its run. A cell's bending force grows as B / |a|: on these unrelaxed tilings (cells down to
# 0.005 of the mean area) B = 2 at T = 0.2 explodes within three steps on every path, NumPy's
# included; with these, no force moves a vertex a third of max_step (NumPy, 200 steps, T1 flipping).
ARRANGEMENTS = {
    "after": (lambda forces: forces.append(Bending(0.5)), 0.05),
    "before": (lambda forces: forces.insert(0, Bending([0.5, 0.125])), 0.05),
    "alone": (lambda forces: forces.__setitem__(0, Bending(0.5)), 0.005),
}


def test_the_bending_runs_stay_clear_of_exploding_steps():
    """The bending runs below, on NumPy: 200 steps with T1 flipping and no exploding step, where
    B = 2 at T = 0.2 explodes at timestep 2 (the force of a cell much smaller than the mean)."""
    for arrange, T in ARRANGEMENTS.values():
        sim = dynamics_simulation(ensemble("sphere", (300, 60)), "cpu", Brownian(dt=0.01, T=T))
        arrange(sim.operations.forces)
        sim.run(200)
        assert sim.operations.updaters[0].total_flips.sum() > 0
    sim = dynamics_simulation(ensemble("sphere", (300, 60)), "cpu", Brownian(dt=0.01, T=0.2))
    sim.operations.forces.append(Bending(2.0))
    with pytest.raises(FloatingPointError, match="exploding step at timestep 2: replica 0, vertex 417"):
        sim.run(3)


@pytest.mark.gpu
@pytest.mark.parametrize("arrangement", list(ARRANGEMENTS))
@pytest.mark.parametrize("per_block", [10 ** 6, 300])
def test_bending_fuses_with_the_step_by_step_bits(monkeypatch, arrangement, per_block):
    """The vertex model + bending (their combined general kernels; fused: the bending stage an extra
    of the vertex model's, its per-cell terms over the neighbours a second cell part after T1's
    flips), or bending alone, with T1 and Brownian dynamics, on one block and on clusters: the
    step-by-step trajectory bit for bit over 200 hot steps."""
    monkeypatch.setattr(tissue_steps, "VERTICES_PER_BLOCK", per_block)
    arrange, T = ARRANGEMENTS[arrangement]
    state = ensemble("sphere", (300, 60))
    sim = dynamics_simulation(state, "gpu", Brownian(dt=0.01, T=T))
    arrange(sim.operations.forces)
    assert tissue_steps.why_not(sim) is None
    assert "fused" in sim.explain()
    runs = three_runs(state, 200, T=T, arrange=arrange, check_every=64)
    assert_same(runs)
    assert runs[-1][2][0].sum() > 0, "T1 flipped"


def scrambled(state, seed):
    """One tiling with its vertices numbered at random: each block of a cluster then owns vertices
    all over the tissue, whose cells are most of its cells."""
    from spherevm.topology import renumber
    arrays = state.arrays_np()
    order = np.random.default_rng(seed).permutation(len(arrays["positions"]))
    keys = ("positions", "cell_vertices", "cell_sides", "vertex_neighbors", "vertex_cells")
    arrays.update(zip(keys, renumber(*(arrays[k] for k in keys), order, np.arange(len(arrays["cell_sides"])))))
    return svm.State(**arrays, constraint=state.constraint)


@pytest.mark.gpu
def test_bending_fuses_with_the_step_by_step_bits_whatever_the_vertex_order(monkeypatch):
    """The neighbour parts each block computes are those of the cells of its own vertices (found
    each step after T1's flips): with vertices numbered at random, every block needs most cells,
    and the fused trajectory is still the step-by-step one bit for bit."""
    monkeypatch.setattr(tissue_steps, "VERTICES_PER_BLOCK", 300)
    state = svm.State.concatenate([scrambled(svm.init.random_tiling(n, seed=3 + i), i) for i, n in
                                   enumerate((300, 60))])
    arrange, T = ARRANGEMENTS["after"]
    sim = dynamics_simulation(state, "gpu", Brownian(dt=0.01, T=T))
    arrange(sim.operations.forces)
    assert "fused" in sim.explain()
    runs = three_runs(state, 200, T=T, arrange=arrange, check_every=64)
    assert_same(runs)
    assert runs[-1][2][0].sum() > 0, "T1 flipped"


@pytest.mark.gpu
def test_bending_fuses_in_minimisations_with_the_step_by_step_bits():
    """FIRE + T1 with the vertex model and bending: the fused minimisation is the general one's."""
    sizes = (40, 150, 32, 90)
    p0 = np.linspace(3.7, 3.9, len(sizes))
    sim = sweep_like(ensemble("sphere", sizes), p0)
    sim.operations.forces.append(Bending(1.0))
    assert tissue_steps.why_not(sim, minimizing=True) is None
    *others, step = minimizations(ensemble("sphere", sizes), p0, MINIMIZE_WAYS, extra=lambda: Bending(1.0),
                                  calls=({"max_steps": 1500, "check_every": 50},))
    for other in others:
        assert_same_minimizations(other, step)
    assert step["flips"].sum() > 0, "T1 flipped"


@pytest.mark.gpu
def test_small_tissues_split_their_cells_corners():
    """Blocks of at most 256 threads give a spherical cell 2, 4 or 8 threads (tissue_cell_lanes: the
    12-cell tissue 8, the 32-cell one 4, the others 2), which compute its corners apart and add
    them in the cell's order: the same bits as one thread a cell, in dynamics and in minimisations."""
    state = ensemble("sphere", (12, 40, 32, 60))
    assert_same(three_runs(state, 300, check_every=100))
    sizes = (12, 32, 20, 48)
    *others, step = minimizations(ensemble("sphere", sizes), np.linspace(3.7, 3.9, len(sizes)), MINIMIZE_WAYS,
                                  calls=({"max_steps": 1500, "check_every": 50},))
    for other in others:
        assert_same_minimizations(other, step)
    assert step["flips"].sum() > 0, "T1 flipped"


@pytest.mark.gpu
def test_without_t1_and_between_writes():
    """No updater at all; and stretches cut by a writer and by checks that do not divide 64."""
    assert_same(three_runs(ensemble("sphere", (100, 30)), 203, t1=False, check_every=37))


@pytest.mark.gpu
def test_the_fused_steps_are_chosen_only_where_they_apply():
    sim = dynamics_simulation(ensemble("sphere", (40, 50)), "gpu", Brownian(dt=0.01, T=0.1))
    assert tissue_steps.why_not(sim) is None
    assert "Brownian has no fused stage for minimize" in tissue_steps.why_not(sim, minimizing=True)
    sim.operations.integrator = FIRE()
    assert tissue_steps.why_not(sim, minimizing=True) is None
    assert "FIRE has no fused stage for run" in tissue_steps.why_not(sim)
    sim = dynamics_simulation(ensemble("sphere", (1500,)), "gpu", FIRE())
    assert "shared memory" in tissue_steps.why_not(sim, minimizing=True)     # one block a tissue
    sim = dynamics_simulation(ensemble("sphere", (40,)), "gpu", Active(dt=0.01, v0=0.1, Dr=0.1))
    assert tissue_steps.why_not(sim) is None                                 # cell directors: a stage too
    sim = dynamics_simulation(ensemble("sphere", (40,)), "gpu", Brownian(dt=0.01))
    sim.operations.forces.append(Bending(0.1))
    assert tissue_steps.why_not(sim) is None                                 # with the vertex model: one stage
    sim.operations.forces[1] = OtherBending(0.1)
    assert "OtherBending has no fused stage" in tissue_steps.why_not(sim)
    with pytest.raises(ValueError, match=r"run\(fused=True\): OtherBending has no fused stage"):
        sim.run(10, fused=True)
    assert "OtherBending" in sim.explain() and "CUDA graphs" in sim.explain()
    sim = dynamics_simulation(ensemble("sphere", (2500,)), "gpu", Brownian(dt=0.01))
    assert "shared memory" in tissue_steps.why_not(sim)
    with pytest.raises(ValueError, match=r"fused must be None \(auto\), True or False"):
        sim.run(10, fused="yes")


@pytest.mark.gpu
def test_flip_backs_are_counted_in_the_fused_steps():
    """``count_flip_backs=True`` under dynamics: the fused steps write the flip log as t1_apply does
    (each flip's pass), so the flip-back memory is the general kernels'."""
    out = []
    for way in WAYS:
        sim = dynamics_simulation(ensemble("sphere", (40, 150)), "gpu", Brownian(dt=0.01, T=0.3))
        sim.operations.updaters[0] = t1 = T1(count_flip_backs=True)
        sim.run(300, check_every=100, **way)
        t1._sync_counters()
        out.append((snapshot(sim.state), t1._separated.copy(), t1._rejoins.copy(), t1.flip_backs.copy()))
    (ref, *memory) = out[-1]
    for snap, *other in out[:-1]:
        for key in ref:
            assert snap[key].tobytes() == ref[key].tobytes(), key
        for x, y in zip(other, memory):
            assert np.array_equal(x, y)
    assert memory[1].sum() > 0, "pairs were joined again"


MINIMIZE_WAYS = (dict(graphs=True), dict(graphs=True, fused=False), dict(graphs=False))


@pytest.mark.gpu
@pytest.mark.parametrize("surface", ["sphere", "plane"])
def test_fused_minimisation_is_the_general_one(surface):
    """A sweep-like chunk of mixed sizes: tissues that start inside a warp, span several tiles of the
    general sums (150 and 600 cells) and have more vertices than a block has threads (600 cells);
    replicas stop at different checks (stopped ones stay in the State until it narrows); checks
    farther apart than a launch's stretch."""
    sizes = (40, 150, 32, 600, 64, 90)
    p0 = np.linspace(3.6, 3.95, len(sizes))
    assert tissue_steps.why_not(sweep_like(ensemble(surface, sizes), p0), minimizing=True) is None
    *others, step = minimizations(ensemble(surface, sizes), p0, MINIMIZE_WAYS,
                                  calls=({"max_steps": 4000, "check_every": 90},))   # > graphs.MAX_STRETCH
    for other in others:
        assert_same_minimizations(other, step)
    assert len(set(step["results"][0][1])) > 2, "replicas stopped at different checks"
    assert step["flips"].sum() > 0 and len(step["separated"]) > 0, "T1 flipped and kept its memory"
    assert step["refused"].sum() > 0, "T1's checks (a warp a candidate when fused) refused flips"


@pytest.mark.gpu
def test_fused_minimisation_halts_resumes_and_explodes_as_the_general_one():
    """Oscillating replicas halted from the flip log; a limit that is no multiple of the check
    interval, then a resumed call; an exploding FIRE step named at the same timestep."""
    state = ensemble("sphere", (80, 60, 120))
    runs = minimizations(ensemble("sphere", (100, 60, 120)), np.array([3.7, 3.8, 3.9]), MINIMIZE_WAYS[::2],
                         calls=({"max_steps": 137}, {"max_steps": 205, "resume": True}))
    assert_same_minimizations(*runs)
    assert "max_steps" in runs[1]["results"][0][0], "the first call stopped at its limit, not at a check"
    runs = minimizations(state, np.full(3, 3.9), MINIMIZE_WAYS[::2], calls=({"max_steps": 2000},),
                         t1=dict(threshold=0.3, new_length=0.45, max_flip_backs=3))
    assert_same_minimizations(*runs)
    assert "t1_oscillation" in runs[1]["results"][0][0], "some replica was halted"
    messages = []
    for way in MINIMIZE_WAYS[::2]:
        sim = dynamics_simulation(state, "gpu", FIRE(dt=50.0, dt_max=500.0, max_step=0.05))
        with pytest.raises(FloatingPointError) as err:
            sim.minimize(max_steps=200, **way)
        messages.append(str(err.value))
    assert messages[0] == messages[1] and "exploding step at timestep" in messages[0]


def shapes(minimizing=False):
    """The stages' shapes of the vertex model with Brownian dynamics (or FIRE), as the layout sees them."""
    from spherevm.plugins.fusion import FusedStage
    vm = FusedStage("force", "VertexModelStage", "", VertexModel.FUSED_ARGS, cell_doubles=2, measures=True)
    move = FusedStage("move", "FireStage", "", FIRE.FUSED_ARGS, sums=3, vertex_doubles=3) if minimizing else \
        FusedStage("move", "BrownianStage<0>", "", Brownian.FUSED_ARGS)
    return (vm,), move, None


def test_the_fused_steps_need_the_gpu():
    sim = dynamics_simulation(ensemble("plane", (16,)), "cpu", Brownian(dt=0.01))
    assert "GPU" in tissue_steps.why_not(sim)
    state = ensemble("sphere", (40, 100))
    # 2 x 100 - 4 = 196 vertices on a sphere, each with two kept inverse norms; on 1 block and on 2;
    # the claims and a pass's flips (at most 100 / 4: a flip's four cells are its own)
    assert tissue_steps.shared_bytes(state, 1, False, shapes()) == 8 * (6 * 196 + 2 * 100 + 2 * 196 + 3 * 196) + 4 * (100 + 25)
    assert tissue_steps.shared_bytes(state, 2, False, shapes()) == 8 * (6 * 196 + 2 * 100 + 2 * 196 + 3 * 98) + 4 * (100 + 25)
    # minimising: positions, forces, velocities, one kept inverse norm; the sums' parts of
    # (196 + 62) // 32 = 8 warps, one more
    assert tissue_steps.shared_bytes(state, 1, True, shapes(True)) == 8 * (9 * 196 + 2 * 100 + 196 + 3 * 9) + 4 * 100
    plane = ensemble("plane", (100,))   # 200 vertices on a torus, no norms kept
    assert tissue_steps.shared_bytes(plane, 1, False, shapes()) == 8 * (6 * 200 + 2 * 100 + 3 * 200) + 4 * (100 + 25)
    assert tissue_steps.shared_bytes(plane, 1, True, shapes(True)) == 8 * (9 * 200 + 2 * 100 + 3 * 9) + 4 * 100
    assert tissue_steps.cluster_size(state) == 1
    big = ensemble("sphere", (1024,))
    assert tissue_steps.cluster_size(big) == 4                      # 2,044 vertices: four blocks
    assert tissue_steps.cluster_size(big, n_sm=3) == 2              # ... fewer where the SMs run out
    assert tissue_steps.cluster_size(big, n_sm=1) == 1


def cpu_plan(*forces):
    """A Plan of ``forces`` on a CPU sphere of 40 cells (the forces' stages need no GPU)."""
    sim = svm.Simulation(device="cpu")
    sim.state = svm.init.random_tiling(40, seed=1)
    sim.operations.forces.extend(forces)
    sim.operations.integrator = Brownian(dt=0.01)
    return Plan(sim)


def test_a_pair_that_combined_computes_is_one_fused_force():
    """Force.fused_combined pairs the forces as compute_all does (both ways round, in order): the
    vertex model's stage, then the bending stage joined into its vertex force (an extra, with a second
    cell part over the neighbours); bending alone, or beside a vertex model subclass, is its own."""
    def shape(*forces):
        found = tissue_steps.force_stages(cpu_plan(*forces))
        return found if isinstance(found, str) else [(s.struct, s.extra) for s in found]

    pair = [("VertexModelStage", False), ("BendingStage", True)]
    assert shape(VertexModel(), Bending(1.0)) == pair
    assert shape(Bending(1.0), VertexModel()) == pair
    assert shape(Bending(1.0)) == [("BendingStage", False)]
    assert shape(Bending(1.0), VertexModel(), Bending(0.5)) == pair + [("BendingStage", False)]

    class OtherModel(VertexModel):
        def compute(self, state):
            return VertexModel.compute(self, state)

    assert shape(Bending(1.0), OtherModel()) == "OtherModel has no fused stage for run " \
        "(Operation.fused_stage; docs/plugins.md, making your plugin fusable)"
    assert shape(OtherBending(1.0), VertexModel()) == "OtherBending has no fused stage for run " \
        "(Operation.fused_stage; docs/plugins.md, making your plugin fusable)"

    class Joiner(Bending):   # joins a force whose stage takes no extra
        def fused_combined(self, other, simulation, minimizing):
            return Bending.fused_combined(self, VertexModel(), simulation, minimizing)

    assert shape(Joiner(1.0), Bending(1.0)) == "Bending's fused stage takes no extra, which Joiner's combined " \
        "stage needs"


def test_the_fused_kernel_joins_the_bending_stage_into_the_vertex_models(monkeypatch):
    """The kernel's source: the bending stage's cell part beside the vertex model's, its neighbour part,
    and its gradient inside the vertex model's vertex force (StageExtra), summed with the others'
    forces in order; the shared memory holds its 4 + 3 doubles a cell, and two ints a cell for the
    cells whose neighbour parts a block computes in a run's steps (not in a minimisation, one block)."""
    monkeypatch.syspath_prepend(str(pathlib.Path(__file__).parent / "plugin_example"))
    from spherevm_line_tension import FastLineTension
    forces = tissue_steps.force_stages(cpu_plan(VertexModel(), Bending(1.0), FastLineTension(0.1)))
    move = shapes()[1]
    source = tissue_steps.kernel_source((tuple(forces), move, None), False)
    assert "s1.cell(A, P, c, s, data + 2L * nc - 4L * c0, pos, row, n);" in source
    assert "s1.neighbours(pos, vc, cell_vertices, sides, max_sides, c, s, data + 2L * nc - 4L * c0, " \
        "more + 0L * nc - 3L * c0);" in source
    assert "vec3 f = s0.vertex(pos, vn, vc, v, s, data + 0L * nc - 2L * c0, norm, StageExtra<BendingStage>{s1, " \
        "data + 2L * nc - 4L * c0, more + 0L * nc - 3L * c0});" in source
    assert "f = add3_rn(f, s2.vertex(pos, vn, vc, v, s, data + 6L * nc - 0L * c0, norm));" in source
    assert "s1.vertex" not in source
    state = ensemble("sphere", (40, 100))   # 196 vertices; as test_the_fused_steps_need_the_gpu, 7 doubles a cell more
    assert tissue_steps.shared_bytes(state, 1, False, (tuple(forces), move, None)) == \
        8 * (6 * 196 + 9 * 100 + 2 * 196 + 3 * 196) + 4 * (100 + 25 + 2 * 100)
    assert tissue_steps.shared_bytes(state, 1, True, (tuple(forces), shapes(True)[1], None)) == \
        8 * (9 * 196 + 9 * 100 + 196 + 3 * 9) + 4 * 100


def test_the_register_bound_keeps_every_block_of_a_launch_on_the_sms():
    """layout's bound: 512 threads (128 registers a thread, a few dozen bytes spilled) where the
    launch's blocks take at most 512 threads of each SM, else 1,024 (64 registers: more blocks on an
    SM at once)."""
    def blocks_threads_bound(state, minimizing, n_sm):
        cluster, _, threads, bound = tissue_steps.layout(state, minimizing, n_sm, shapes(minimizing))
        return cluster, threads, bound

    state = svm.State.concatenate([svm.init.random_tiling(300, seed=1 + i) for i in range(3)])   # 596 vertices each
    assert blocks_threads_bound(state, False, 12) == (2, 320, 512)    # two blocks a tissue, one an SM
    assert blocks_threads_bound(state, False, 4) == (1, 608, 1024)    # no SMs to spare: one block a tissue
    assert blocks_threads_bound(state, True, 12) == (1, 640, 1024)    # minimising: from a warp's start
    small = ensemble("sphere", (32,) * 24)                            # 60 vertices: blocks of 64 threads
    assert blocks_threads_bound(small, False, 4) == (1, 64, 512)      # six blocks an SM
    assert blocks_threads_bound(small, False, 2) == (1, 64, 1024)     # twelve
