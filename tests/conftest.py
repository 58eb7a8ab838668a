import os

import numpy as np
import pytest
from hypothesis import settings

import spherevm as svm

# Property tests: the same examples on every run by default, so CI is repeatable (a new failing
# example found by chance would block a landing that changed nothing); HYPOTHESIS_PROFILE=explore
# draws fresh random examples, many more of them, to hunt for new ones.
settings.register_profile("repeatable", max_examples=60, deadline=None, derandomize=True)
settings.register_profile("explore", max_examples=1000, deadline=None)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "repeatable"))


# GPU tests: one mechanism. A test that needs the GPU carries the ``gpu`` marker (directly, or
# through the ``device`` fixture's "gpu" parameter); without CuPy and a working NVIDIA GPU every
# such test is skipped here, with the reason, and nowhere else.
HAS_GPU = svm.device.gpu_available()
GPU_REASON = "needs CuPy and a working NVIDIA GPU"


# The quick loop (`-m "not slow"`): the tests named in tests/slow.txt get the ``slow`` marker here,
# before pytest deselects by marker.
SLOW_LIST = os.path.join(os.path.dirname(__file__), "slow.txt")


def slow_ids(path=SLOW_LIST):
    """The node ids listed in ``path`` (one a line; '#' starts a comment)."""
    with open(path) as f:
        return {line.split("#")[0].strip() for line in f} - {""}


@pytest.hookimpl(tryfirst=True)
def pytest_collection_modifyitems(config, items):
    slow = slow_ids()
    for item in items:
        if item.nodeid in slow:
            item.add_marker(pytest.mark.slow)
    if HAS_GPU:
        return
    skip = pytest.mark.skip(reason=GPU_REASON)
    for item in items:
        if "gpu" in item.keywords:
            item.add_marker(skip)


@pytest.fixture(params=["cpu", pytest.param("gpu", marks=pytest.mark.gpu)])
def device(request):
    """The device name a behavioural test runs on: "cpu" always, "gpu" where CuPy sees one."""
    return request.param


def relative_gap(a, b):
    """Largest difference of ``a`` from ``b`` over the largest magnitude of ``b`` (NumPy arrays)."""
    return np.abs(a - b).max() / max(np.abs(b).max(), 1e-300)


def assert_gpu_force_matches_numpy(model, cpu):
    """``model`` on the CPU State ``cpu`` and on its GPU copy: forces, energies and cell energies
    agree to 1e-12 relative. Returns the GPU result for further checks."""
    rc, rg = model.compute(cpu), model.compute(cpu.to("gpu"))
    assert relative_gap(rg.forces.get(), rc.forces) <= 1e-12
    assert relative_gap(rg.energy.get(), rc.energy) <= 1e-12
    assert relative_gap(rg.cell_energy.get(), rc.cell_energy) <= 1e-12
    return rg


def to_numpy(a):
    """A NumPy copy of a NumPy or CuPy array."""
    return a.get() if hasattr(a, "get") else np.asarray(a)


@pytest.fixture
def tiling200():
    return svm.init.random_tiling(200, seed=11)


def fire_simulation(n_cells=16, replicas=2, seed=1, p0=3.8):
    """A CPU Simulation of random tilings with the vertex model (kr = 1), T1 and a default FIRE."""
    sim = svm.Simulation(device="cpu", seed=seed)
    sim.state = svm.init.random_tiling(n_cells, replicas=replicas, seed=seed)
    sim.operations.forces.append(svm.plugins.forces.VertexModel.dimensionless(kr=1.0, p0=p0))
    sim.operations.updaters.append(svm.plugins.updaters.T1())
    sim.operations.integrator = svm.plugins.integrators.FIRE()
    return sim


def finite_difference_forces(force, state, vertices, h=1e-6):
    """Minus the central finite-difference gradient of the total energy at the given vertices."""
    pos0 = state.positions.copy()
    out = np.zeros((len(vertices), 3))
    for i, v in enumerate(vertices):
        for d in range(3):
            state.positions = pos0.copy()
            state.positions[v, d] += h
            ep = force.energy(state).sum()
            state.positions = pos0.copy()
            state.positions[v, d] -= h
            em = force.energy(state).sum()
            out[i, d] = -(ep - em) / (2 * h)
    state.positions = pos0
    return out


# ------------------------------------------------------------------ shared by the GSD tests
STATE_TOPOLOGY = ("cell_vertices", "cell_sides", "vertex_neighbors", "vertex_cells", "vertex_start", "cell_start")


def snapshot(state):
    """NumPy copies of every array of a State (either device)."""
    return {k: np.array(v, copy=True) for k, v in state.arrays_np().items()}


def assert_same_state(restored, ref, where=""):
    """``restored`` holds exactly the arrays of the snapshot ``ref``: positions bitwise."""
    a = restored.arrays_np()
    assert a["positions"].dtype == np.float64
    assert a["positions"].tobytes() == ref["positions"].tobytes(), f"positions {where}"
    for k in STATE_TOPOLOGY:
        assert a[k].shape == ref[k].shape and np.array_equal(a[k], ref[k]), f"{k} {where}"
    assert np.array_equal(a["radius"], ref["radius"]), f"radius {where}"


class Snapshots(svm.plugins.Writer):
    """Records the arrays of every state a GSD writer with the same trigger sees."""

    def __init__(self, trigger):
        super().__init__(trigger)
        self.refs, self.steps = [], []

    def write(self, simulation, timestep):
        self.refs.append(snapshot(simulation.state))
        self.steps.append(timestep)


# Random123 kat_vectors, "philox4x32 R" lines: counter (4 words), key (2 words), expected (4 words).
PHILOX_KAT = [
    (10, [0x00000000, 0x00000000, 0x00000000, 0x00000000], [0x00000000, 0x00000000],
     [0x6627e8d5, 0xe169c58d, 0xbc57ac4c, 0x9b00dbd8]),
    (10, [0xffffffff, 0xffffffff, 0xffffffff, 0xffffffff], [0xffffffff, 0xffffffff],
     [0x408f276d, 0x41c83b0e, 0xa20bc7c6, 0x6d5451fd]),
    (10, [0x243f6a88, 0x85a308d3, 0x13198a2e, 0x03707344], [0xa4093822, 0x299f31d0],
     [0xd16cfe09, 0x94fdcceb, 0x5001e420, 0x24126ea1]),
    (7, [0x00000000, 0x00000000, 0x00000000, 0x00000000], [0x00000000, 0x00000000],
     [0x5f6fb709, 0x0d893f64, 0x4f121f81, 0x4f730a48]),
    (7, [0xffffffff, 0xffffffff, 0xffffffff, 0xffffffff], [0xffffffff, 0xffffffff],
     [0x5207ddc2, 0x45165e59, 0x4d8ee751, 0x8c52f662]),
    (7, [0x243f6a88, 0x85a308d3, 0x13198a2e, 0x03707344], [0xa4093822, 0x299f31d0],
     [0x4dfccaba, 0x190a87f0, 0xc47362ba, 0xb6b5242a]),
]


def t1_simulations(state, **t1):
    """One Simulation per device on the same State with only a T1 updater (``T1(**t1)``), for
    flip-for-flip comparisons of the NumPy and CUDA passes: ``{"cpu": sim, "gpu": sim}``."""
    from spherevm.plugins.updaters import T1
    sims = {}
    for dev in ("cpu", "gpu"):
        sim = svm.Simulation(device=dev)
        sim.state = state
        sim.operations.updaters.append(T1(**t1))
        sims[dev] = sim
    return sims


def assert_t1_round_matches_numpy(sims, kick, gap):
    """One round of :func:`t1_simulations`: both States kicked by ``kick`` (kick_on_surface), a T1
    pass on each, then the same flips and refusals, cell tables and vertex cells, and positions within
    1e-12 (``gap(gpu_state, cpu_state)``)."""
    for sim in sims.values():
        kick_on_surface(sim, kick)
        sim.run_updaters()
    c, g = sims["cpu"], sims["gpu"]
    assert np.array_equal(g.log("t1_flips"), c.log("t1_flips"))
    assert np.array_equal(g.log("t1_refused"), c.log("t1_refused"))
    width = int(c.state.cell_sides.max())
    assert np.array_equal(g.state.cell_vertices.get()[:, :width], c.state.cell_vertices[:, :width])
    assert np.array_equal(g.state.vertex_cells.get(), c.state.vertex_cells)
    assert gap(g.state, c.state) <= 1e-12


def dynamics_simulation(state, device, integrator, seed=11):
    """A Simulation of the vertex model (kr = 1, p0 = 3.75) with T1 and ``integrator`` on ``device``:
    the pair the CPU/GPU dynamics comparisons run (test_gpu, test_plane_gpu)."""
    from spherevm.plugins.forces import VertexModel
    from spherevm.plugins.updaters import T1
    sim = svm.Simulation(device=device, seed=seed)
    sim.state = state
    sim.operations.forces.append(VertexModel.dimensionless(kr=1.0, p0=3.75))
    sim.operations.updaters.append(T1())
    sim.operations.integrator = integrator
    return sim


def assert_brownian_with_t1_matches_numpy(state, gap, steps=1000):
    """Brownian dynamics with T1 (dynamics_simulation, T = 2e-3) of ``state`` for ``steps`` steps on
    the CPU and the GPU: some flips, the same flips, cell tables and neighbours, and positions within
    1e-9 (``gap(gpu_state, cpu_state)``, the largest distance between them)."""
    from spherevm.plugins.integrators import Brownian
    cpu = dynamics_simulation(state, "cpu", Brownian(dt=0.01, T=2e-3))
    gpu = dynamics_simulation(state, "gpu", Brownian(dt=0.01, T=2e-3))
    cpu.run(steps)
    gpu.run(steps)
    flips = cpu.log("t1_total_flips")
    assert flips.sum() > 0 and np.array_equal(gpu.log("t1_total_flips"), flips)
    width = int(cpu.state.cell_sides.max())
    assert np.array_equal(gpu.state.cell_vertices.get()[:, :width], cpu.state.cell_vertices[:, :width])
    assert np.array_equal(gpu.state.vertex_neighbors.get(), cpu.state.vertex_neighbors)
    assert gap(gpu.state, cpu.state) <= 1e-9
    gpu.state.validate(orientation=False)


def kick_on_surface(sim, kick):
    """Move every vertex by the tangent part of ``kick`` (NumPy, (V, 3)) and back onto the surface."""
    st = sim.state
    con = st.constraint
    k = st.device.asarray(kick)
    size = con.size(st, st.vertex_replica)
    st.positions = con.project_normal(st.positions + con.project_tangent(st.positions, k, size), size)


# ------------------------------------------------------------------------- minimisations (GPU)
def sweep_like(state, p0, **t1):
    """FIRE + T1 (flip-back bookkeeping on, as in every minimisation) at kr = 0 with one p0 per
    replica, as a rigidity sweep's chunk: replicas converge at different iterations (narrowing)."""
    from spherevm.plugins.integrators import FIRE
    from spherevm.plugins.updaters import T1
    sim = svm.Simulation(device="gpu")
    sim.state = state
    rep = sim.state.cell_replica_np()
    sim.operations.forces.append(svm.plugins.forces.VertexModel(kA=0.0, kP=1.0, A0=1.0, P0=np.asarray(p0)[rep]))
    sim.operations.updaters.append(T1(**t1))
    sim.operations.integrator = FIRE(dt=0.02)
    return sim


def minimizations(state, p0, ways, calls=({},), t1=None, extra=None):
    """The same minimisation(s) of :func:`sweep_like`, each of the ``ways`` (``minimize`` keywords:
    graphs, fused): everything each leaves behind (``extra()``: a force added after the vertex model)."""
    out = []
    for way in ways:
        sim = sweep_like(state, p0, **(t1 or {}))
        if extra is not None:
            sim.operations.forces.append(extra())
        results = [sim.minimize(**way, **kw) for kw in calls]
        t1_op, fire = sim.operations.updaters[0], sim.operations.integrator
        t1_op._sync_counters()
        out.append(dict(state=snapshot(sim.state), timestep=sim.timestep, iteration=fire.iteration,
                        results=[(r.reason.tolist(), r.steps.tolist(), r.energy.tobytes(), r.max_force.tobytes())
                                 for r in results],
                        velocities=fire.velocities.get().tobytes(), dt=fire.replica_dt.get().tobytes(),
                        alpha=fire.alpha.get().tobytes(), n_positive=fire.n_positive.get().tobytes(),
                        flips=t1_op.total_flips.copy(), refused=t1_op.total_refused.copy(),
                        flip_backs=t1_op.flip_backs.copy(), separated=t1_op._separated.copy(),
                        rejoins=t1_op._rejoins.copy()))
    return out


def assert_same_minimizations(graph, step):
    """Two of :func:`minimizations`' records are equal, the State bitwise."""
    for key in step:
        if key == "state":
            for k in step["state"]:
                assert graph["state"][k].shape == step["state"][k].shape, k
                assert graph["state"][k].tobytes() == step["state"][k].tobytes(), k
        elif isinstance(step[key], np.ndarray):
            assert np.array_equal(graph[key], step[key]), key
        else:
            assert graph[key] == step[key], key
