"""The per-replica sums of the GPU kernels (device_common.cuh: no floating-point atomics) are right
for every way a replica's cells and vertices fall on the GPU's thread blocks, and have the same bits
on every run, so a GPU run repeats exactly (restarts, sweeps on several GPUs)."""
import numpy as np
import pytest
from conftest import to_numpy

import spherevm as svm
from spherevm.device import BLOCK
from spherevm.plugins.forces import VertexModel
from spherevm.plugins.integrators import FIRE
from spherevm.plugins.updaters import T1

# replicas inside one block of cells, across a few, and one whose vertices cover more than 32
# blocks; ragged offsets throughout
SIZES = [12, 300, 40, 4500, 20, 700, 33]


@pytest.fixture(scope="module")
def ragged():
    state = svm.State.concatenate([svm.init.random_tiling(n, seed=k) for k, n in enumerate(SIZES)])
    assert state.vertices_per_replica.max() > 32 * BLOCK
    return state


def model():
    return VertexModel.dimensionless(kr=1.0, p0=3.8)


@pytest.mark.gpu
def test_energy_sums_on_ragged_replicas_match_numpy(ragged):
    cpu = model().compute(ragged)
    gpu = model().compute(ragged.to("gpu"))
    e = to_numpy(gpu.energy)
    assert np.abs(e - cpu.energy).max() <= 1e-12 * np.abs(cpu.energy).max()
    # the sums are of the per-cell energies the kernel wrote
    per_replica = np.bincount(ragged.cell_replica_np(), weights=to_numpy(gpu.cell_energy))
    assert np.abs(e - per_replica).max() <= 1e-12 * np.abs(per_replica).max()


@pytest.mark.parametrize("sizes", [[5, 300, 40, 1], [3, 300_000, 700, 33, 256, 512]])
@pytest.mark.gpu
def test_fire_sums_and_control_match_numpy_for_any_replica_sizes(sizes):
    """FIRE's per-replica F.v, v.v, F.F (three sums in one kernel) against NumPy, on vertex ranges
    from one item to more than 4 x 256 blocks (the finishing block's unrolled loop), repeated; and
    each replica's control, which the kernel runs once the replica's sums are final (in the block
    that finished them), against FIRE's formulas in NumPy on those sums: uphill, mixing, growing
    after n_min steps, and a stopped replica that keeps its dt, alpha and counter."""
    import cupy as cp
    from spherevm.device import BLOCK, launch
    from spherevm.constraints.kernels import surface_kernels
    from spherevm.plugins.integrators import fire
    start = np.concatenate([[0], np.cumsum(sizes)])
    n, nr = int(start[-1]), len(sizes)
    rep = np.repeat(np.arange(nr), sizes)
    rng = np.random.default_rng(1)
    f, v = rng.normal(size=(2, n, 3))
    v = np.where((rep == 0)[:, None], -f, 0.5 * f + 0.1 * v)           # replica 0 uphill, the others downhill
    module, _ = surface_kernels(fire._KERNELS, svm.init.random_tiling(8))
    n_tiles = (n + BLOCK - 1) // BLOCK
    args = (cp.asarray(start.astype(np.int32)), np.int32(nr), cp.empty(3 * (n_tiles + nr)),
            cp.zeros(nr, dtype=np.uint32))
    active = np.arange(nr) != nr - 1                                   # the last replica has stopped
    dt0, alpha0 = rng.uniform(0.01, 0.05, nr), rng.uniform(0.01, 0.1, nr)
    count0 = np.arange(nr, dtype=np.int64) * 3                        # 0, 3, 6, ...: some at n_min = 5 or more
    n_min, f_inc, f_dec, alpha_start, f_alpha, dt_max = 5, 1.1, 0.5, 0.1, 0.99, 0.04
    runs = []
    for _ in range(2):
        sums, control = cp.empty((3, nr)), cp.empty((3, nr))
        dt, alpha, count = cp.asarray(dt0), cp.asarray(alpha0), cp.asarray(count0)
        launch(module.get_function("fire_reduce"), n,
               (cp.asarray(f), cp.asarray(v), cp.asarray(rep.astype(np.int32)), np.int32(n), sums[0], sums[1], sums[2],
                *args, cp.asarray(active), dt, alpha, count, control[0], control[1], control[2], np.int32(n_min),
                np.float64(f_inc), np.float64(f_dec), np.float64(alpha_start), np.float64(f_alpha), np.float64(dt_max)))
        runs.append([to_numpy(a) for a in (sums, control, dt, alpha, count)])
    for a, b in zip(*runs):
        assert a.tobytes() == b.tobytes()
    assert not to_numpy(args[3]).any()                    # the tickets are back at zero
    want = [np.bincount(rep, weights=np.einsum("ij,ij->i", a, b)) for a, b in ((f, v), (v, v), (f, f))]
    for got, ref in zip(runs[0][0], want):
        assert np.abs(got - ref).max() <= 1e-12 * np.abs(ref).max()
    (power, vv, ff), (keep, scale, step), dt, alpha, count = runs[0]
    uphill = power <= 0
    grow = ~uphill & (count0 >= n_min)
    mix = np.where(uphill, 0.0, alpha0)
    want_dt = np.where(uphill, dt0 * f_dec, np.where(grow, np.minimum(dt0 * f_inc, dt_max), dt0))
    on = active
    assert uphill[0] and grow[on].any() and (~uphill & ~grow)[on].any()     # every branch taken
    assert np.array_equal(keep[on], np.where(uphill, 0.0, 1.0 - mix)[on])
    assert np.array_equal(scale[on], (mix * np.sqrt(vv) / np.sqrt(ff))[on])
    assert np.array_equal(dt[on], want_dt[on]) and np.array_equal(step[on], want_dt[on])
    assert np.array_equal(alpha[on], np.where(uphill, alpha_start, np.where(grow, alpha0 * f_alpha, alpha0))[on])
    assert np.array_equal(count[on], np.where(uphill, 0, count0 + 1)[on])
    assert not keep[~on].any() and not scale[~on].any() and not step[~on].any()
    assert np.array_equal(dt[~on], dt0[~on]) and np.array_equal(alpha[~on], alpha0[~on])
    assert np.array_equal(count[~on], count0[~on])


def minimised(state, device):
    sim = svm.Simulation(device=device, seed=2)
    sim.state = state
    sim.operations.forces.append(model())
    sim.operations.updaters.append(T1())
    sim.operations.integrator = FIRE(dt=0.02)
    result = sim.minimize(force_tol=1e-10, max_steps=1500)
    return sim, result


def test_two_runs_have_the_same_bits(device):
    state = svm.init.random_tiling(300, replicas=5, seed=9)
    (a, ra), (b, rb) = minimised(state, device), minimised(state, device)
    assert to_numpy(a.state.positions).tobytes() == to_numpy(b.state.positions).tobytes()
    assert np.array_equal(ra.steps, rb.steps) and ra.energy.tobytes() == rb.energy.tobytes()
    assert a.log("t1_total_flips").sum() > 0 and np.array_equal(a.log("t1_total_flips"), b.log("t1_total_flips"))


@pytest.mark.gpu
def test_weighted_bincount_on_the_gpu_is_numpys():
    """spherevm.device.weighted_bincount (the GPU's per-cell sums outside the kernels) adds in
    NumPy's order: the same weights give NumPy's bits."""
    import cupy as cp
    from spherevm.device import weighted_bincount
    rng = np.random.default_rng(3)
    index = rng.integers(0, 500, size=20000)
    w = rng.normal(size=20000) * 10.0 ** rng.integers(-8, 8, size=20000)
    got = to_numpy(weighted_bincount(cp.asarray(index), cp.asarray(w), 600))
    assert got.tobytes() == np.bincount(index, weights=w, minlength=600).tobytes()
