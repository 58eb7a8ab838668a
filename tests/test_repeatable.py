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


def ordered_segment_sums(values, segment, start, tile=BLOCK):
    """NumPy's replay of device_common.cuh's order of additions (``segment_sums``), for a launch of
    ``tile`` threads a block over ``values`` (one item a thread, item i in segment ``segment[i]``,
    segments the ranges ``start[s]:start[s + 1]``): each warp's segmented suffix sums, the first
    thread of a run in a tile adding the warps the run continues into, and a segment over several
    tiles finished in tile order, thread i of the finishing block adding tiles t0 + 1 + i, t0 + 1 + i
    + tile, ... (the first part in thread 0), then butterflies in each warp and over the warps."""
    n, n_seg = len(values), len(start) - 1
    n_tiles = -(-n // tile)
    v = np.zeros(n_tiles * tile)
    s = np.full(n_tiles * tile, -1)
    v[:n], s[:n] = values, segment
    lane = np.arange(32)
    w, ws = v.reshape(-1, 32).copy(), s.reshape(-1, 32)
    for offset in (1, 2, 4, 8, 16):
        other, other_segment = np.zeros_like(w), np.full_like(ws, -3)
        other[:, :32 - offset], other_segment[:, :32 - offset] = w[:, offset:], ws[:, offset:]
        w = np.where(other_segment == ws, w + other, w)
    suffix = w.reshape(-1)
    out, parts = np.zeros(n_seg), {}
    for i in np.flatnonzero((s >= 0) & ((np.arange(s.size) % tile == 0) | (np.roll(s, 1) != s))):
        seg, t, total = s[i], i // tile, suffix[i]
        for first in range((i // 32 + 1) * 32, (t + 1) * tile, 32):      # the next warps' first lanes
            if s[first] != seg:
                break
            total += suffix[first]
        t0, t1 = start[seg] // tile, (start[seg + 1] - 1) // tile
        if t0 == t1:
            out[seg] = total
        else:
            parts.setdefault(seg, {})[t] = total
    for seg, part in parts.items():
        t0, t1 = start[seg] // tile, (start[seg + 1] - 1) // tile
        thread = np.zeros(tile)
        thread[0] = part[t0]
        for k in range(tile):
            for t in range(t0 + 1 + k, t1 + 1, tile):
                thread[k] += part[t]
        x = thread.reshape(-1, 32)
        for offset in (16, 8, 4, 2, 1):
            x = x + x[:, lane ^ offset]
        y = np.zeros(32)
        y[:len(x)] = x[:, 0]
        for offset in (16, 8, 4, 2, 1):
            y = y + y[lane ^ offset]
        out[seg] = y[0]
    return out


def test_the_replayed_order_sums_right():
    """The NumPy replay of the kernels' order (the oracle of the GPU tests below) sums each segment."""
    rng = np.random.default_rng(4)
    sizes = [1, 31, 33, 300, 257, 9000, 40, 5000, 2]
    start = np.concatenate([[0], np.cumsum(sizes)])
    values = rng.normal(size=start[-1]) * 10.0 ** rng.integers(-6, 6, size=start[-1])
    got = ordered_segment_sums(values, np.repeat(np.arange(len(sizes)), sizes), start)
    want = np.add.reduceat(values, start[:-1])
    assert np.abs(got - want).max() <= 1e-12 * np.abs(values).max()


@pytest.mark.gpu
def test_segment_sums_add_in_one_fixed_order():
    """The per-replica sums have exactly the bits of ordered_segment_sums' order, on segments inside
    one block, over a few blocks (a finishing warp), over more than 33 blocks (the finishing block)
    and over hundreds: FIRE's three sums (vectors along x, so that each item's term F.v is one
    rounded product, as in NumPy) and the vertex model's energy sums over its cells' energies."""
    import cupy as cp
    from spherevm.constraints.kernels import surface_kernels
    from spherevm.device import launch
    from spherevm.plugins.integrators import fire
    sizes = [5, 300, 40, 1, 9000, 700, 33, 256, 512, 300_000, 2000]
    start = np.concatenate([[0], np.cumsum(sizes)])
    n, nr = int(start[-1]), len(sizes)
    rep = np.repeat(np.arange(nr), sizes)
    rng = np.random.default_rng(5)
    f, v = np.zeros((2, n, 3))
    f[:, 0], v[:, 0] = rng.normal(size=(2, n)) * 10.0 ** rng.integers(-4, 4, size=(2, n))
    module, _ = surface_kernels(fire._KERNELS, svm.init.random_tiling(8))
    n_tiles = (n + BLOCK - 1) // BLOCK
    sums = cp.empty((3, nr))
    launch(module.get_function("fire_reduce"), n,
           (cp.asarray(f), cp.asarray(v), cp.asarray(rep.astype(np.int32)), np.int32(n), sums[0], sums[1], sums[2],
            cp.asarray(start.astype(np.int32)), np.int32(nr), cp.empty(3 * (n_tiles + nr)), cp.zeros(nr, dtype=np.uint32),
            cp.zeros(nr, dtype=bool), cp.ones(nr), cp.ones(nr), cp.zeros(nr, dtype=np.int64), *cp.empty((3, nr)),
            np.int32(5), np.float64(1.1), np.float64(0.5), np.float64(0.1), np.float64(0.99), np.float64(1.0)))
    fx, vx = f[:, 0], v[:, 0]
    for got, terms in zip(to_numpy(sums), (fx * vx, vx * vx, fx * fx)):
        assert got.tobytes() == ordered_segment_sums(terms, rep, start).tobytes()
    state = svm.State.concatenate([svm.init.random_tiling(m, seed=k) for k, m in enumerate([12, 9000, 300, 4500, 40])])
    gpu = model().compute(state.to("gpu"))
    want = ordered_segment_sums(to_numpy(gpu.cell_energy), state.cell_replica_np(), state.cell_start)
    assert to_numpy(gpu.energy).tobytes() == want.tobytes()


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
