"""GPU benchmark: one table of per-step costs, bandwidth and speed-up over the NumPy path.

    python benchmarks/bench_gpu.py                # N = 1e3 .. 1e6 cells and the ensembles
    python benchmarks/bench_gpu.py --cells 1000 10000 --numpy-max 100000

For each system: time of one force evaluation, of one FIRE iteration (forces + FIRE update), kernel
launches per step, the memory-traffic floor (each array read or written once) over the time as
achieved GB/s, compared with the device-to-device copy bandwidth measured in the same run, and
the NumPy time of the same work where it is affordable.
"""
from __future__ import annotations

import argparse
import datetime
import gc
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import median_time, minimize_step_time, run_step_time  # noqa: E402

import spherevm as svm  # noqa: E402
from spherevm.device import info, resolve  # noqa: E402


def copy_bandwidth(device, n_bytes=2 << 30):
    """Device-to-device copy bandwidth in GB/s (read + write) on a buffer of ``n_bytes``."""
    cp = device.xp
    a = cp.zeros(n_bytes // 8)
    b = cp.empty_like(a)
    t = median_time(lambda: cp.copyto(b, a), device, repeat=9)
    return 2 * a.nbytes / t / 1e9


def force_floor_bytes(state):
    """Bytes that a force evaluation must move at least: every array it touches, once."""
    nv, nc, ms = state.n_vertices, state.n_cells, state.max_sides
    cell_in = nc * (4 * ms + 4 + 4 + 4 * 8)          # table, sides, replica, 4 parameters
    cell_out = nc * (16 + 8)                          # two force coefficients, cell energy
    vert = nv * (24 + 12 + 12 + 24)                   # positions, neighbours, cells, forces
    return cell_in + cell_out + nc * 16 + vert        # the vertex kernel reads the coefficients again


def fire_floor_bytes(state):
    """Force floor plus FIRE: forces and velocities read twice, positions and velocities written."""
    nv = state.n_vertices
    return force_floor_bytes(state) + nv * (24 + 24 + 4) + nv * (24 + 24 + 24 + 24 + 4)


def build(n_cells, replicas, device):
    sim = svm.Simulation(device=device)
    sim.state = svm.init.random_tiling(n_cells, replicas=replicas, seed=1)
    sim.operations.forces.append(svm.plugins.forces.VertexModel.dimensionless(kr=1.0, p0=3.8))
    sim.operations.integrator = svm.plugins.integrators.FIRE(dt=0.01)
    return sim


def fire_iteration(sim):
    sim.state_changed()
    forces, _ = sim.compute_forces()
    sim.operations.integrator.step(sim, forces)


def brownian_sim(n_cells, replicas, device):
    sim = svm.Simulation(device=device, seed=1)
    sim.state = svm.init.random_tiling(n_cells, replicas=replicas, seed=1)
    sim.operations.forces.append(svm.plugins.forces.VertexModel.dimensionless(kr=1.0, p0=3.75))
    sim.operations.updaters.append(svm.plugins.updaters.T1())
    sim.operations.integrator = svm.plugins.integrators.Brownian(dt=0.01, T=5e-4)
    return sim


def fire_t1_sim(n_cells, replicas, device):
    """FIRE + T1, as every minimisation of the rigidity sweeps."""
    sim = build(n_cells, replicas, device)
    sim.operations.updaters.append(svm.plugins.updaters.T1())
    return sim


def brownian_step(sim):
    sim.run_updaters()
    sim.integrate()


def device_bytes_per_cell(n_cells, replicas, gpu):
    """GPU memory held by a FIRE + T1 minimisation, per cell (memory pool, after a few steps)."""
    gc.collect()                     # earlier simulations (reference cycles) must not be freed mid-count
    pool = gpu.xp.get_default_memory_pool()
    pool.free_all_blocks()
    before = pool.used_bytes()
    sim = build(n_cells, replicas, gpu)
    sim.operations.updaters.append(svm.plugins.updaters.T1())
    sim.run(3)
    used = pool.used_bytes() - before
    del sim
    return used / (n_cells * replicas)


def measure(n_cells, replicas, gpu, numpy_max, bw):
    sim = build(n_cells, replicas, gpu)
    state = sim.state
    force = sim.operations.forces[0]
    t_force = median_time(lambda: force.compute(state), gpu, repeat=51)
    t_fire = median_time(lambda: fire_iteration(sim), gpu, repeat=51)
    bsim = brownian_sim(n_cells, replicas, gpu)
    t_brown = median_time(lambda: brownian_step(bsim), gpu, repeat=101)
    steps = 200 if n_cells * replicas >= 1e6 else 1000
    t_graph = run_step_time(brownian_sim(n_cells, replicas, gpu), gpu, steps=steps, fused=False)
    t_fused = run_step_time(brownian_sim(n_cells, replicas, gpu), gpu, steps=steps)   # = t_graph where not fused
    t_min_graph = minimize_step_time(fire_t1_sim(n_cells, replicas, gpu), gpu, steps=steps, fused=False)
    t_min_fused = minimize_step_time(fire_t1_sim(n_cells, replicas, gpu), gpu, steps=steps)
    row = dict(system=f"{replicas} x {n_cells}" if replicas > 1 else f"{n_cells:.0e}",
               cells=n_cells * replicas, force_ms=1e3 * t_force, fire_ms=1e3 * t_fire, brown_ms=1e3 * t_brown,
               graph_ms=1e3 * t_graph, fused_ms=1e3 * t_fused, min_graph_ms=1e3 * t_min_graph,
               min_fused_ms=1e3 * t_min_fused,
               force_gbs=force_floor_bytes(state) / t_force / 1e9, fire_gbs=fire_floor_bytes(state) / t_fire / 1e9)
    row["fire_frac_bw"] = row["fire_gbs"] / bw
    if n_cells * replicas <= numpy_max:
        cpu = build(n_cells, replicas, "cpu")
        cs = cpu.state
        cf = cpu.operations.forces[0]
        reps = 3 if n_cells * replicas > 1e5 else 7
        row["numpy_force_ms"] = 1e3 * median_time(lambda: cf.compute(cs), None, repeat=reps, warmup=1)
        row["numpy_fire_ms"] = 1e3 * median_time(lambda: fire_iteration(cpu), None, repeat=reps, warmup=1)
        bcpu = brownian_sim(n_cells, replicas, "cpu")
        row["numpy_brown_ms"] = 1e3 * median_time(lambda: brownian_step(bcpu), None, repeat=reps, warmup=1)
    return row


def main(argv=None):
    ap = argparse.ArgumentParser(allow_abbrev=False, description="spherevm GPU benchmark")
    ap.add_argument("--cells", type=float, nargs="+", default=[1e3, 1e4, 1e5, 1e6])
    ap.add_argument("--ensembles", nargs="*", default=["4096x64", "256x1024"])
    ap.add_argument("--numpy-max", type=float, default=2e5, help="largest total cell count timed on NumPy")
    args = ap.parse_args(argv)
    gpu = resolve("gpu")
    facts = info()
    bw = copy_bandwidth(gpu)
    print(f"# spherevm GPU benchmark, {datetime.date.today()}, GPU: {facts.get('gpus')}, CuPy {facts.get('cupy')}, "
          f"CUDA runtime {facts.get('cuda_runtime')}")
    print(f"# device-to-device copy bandwidth: {bw:.0f} GB/s")
    print("# launches per step: force 2 kernels; FIRE iteration = force + 2 kernels; "
          "Brownian step with T1 check = T1 pass (1 memset + 2 kernels + 1 read-back of 12 bytes) + force + 1 kernel; "
          "in graphs: the same steps through Simulation.run(graphs=True, fused=False), no read-back, per step; "
          "run: Simulation.run(graphs=True), the fused small-tissue steps where they apply (spherevm.tissue_steps); "
          "FIRE+T1 in graphs / minimize: an iteration of Simulation.minimize(graphs=True, fused=False) / "
          "minimize(graphs=True) (fused where it applies), with T1, a check every 100 iterations")
    print("# GB/s: bytes each kernel must move at least (every array once) over the measured time")
    head = (f"{'system':>12} {'force ms':>9} {'GB/s':>6} {'FIRE it ms':>11} {'GB/s':>6} {'of copy':>8} "
            f"{'Brown+T1 ms':>12} {'in graphs':>10} {'run':>8} {'FIRE+T1 graphs':>15} {'minimize':>9} "
            f"{'NumPy force':>12} {'NumPy FIRE':>11} {'NumPy Brown':>12} {'speed-up':>9} {'B/cell':>7}")
    print(head)
    systems = [(int(n), 1) for n in args.cells]
    for e in args.ensembles:
        r, n = e.lower().split("x")
        systems.append((int(n), int(r)))
    for n, r in systems:
        row = measure(n, r, gpu, args.numpy_max, bw)
        row["bytes_per_cell"] = device_bytes_per_cell(n, r, gpu)
        npf = row.get("numpy_force_ms", np.nan)
        npi = row.get("numpy_fire_ms", np.nan)
        npb = row.get("numpy_brown_ms", np.nan)
        print(f"{row['system']:>12} {row['force_ms']:9.4f} {row['force_gbs']:6.0f} {row['fire_ms']:11.4f} "
              f"{row['fire_gbs']:6.0f} {row['fire_frac_bw']:8.2f} {row['brown_ms']:12.4f} {row['graph_ms']:10.4f} "
              f"{row['fused_ms']:8.4f} {row['min_graph_ms']:15.4f} {row['min_fused_ms']:9.4f} {npf:12.3f} {npi:11.3f} "
              f"{npb:12.3f} {npi / row['fire_ms']:9.1f} {row['bytes_per_cell']:7.0f}", flush=True)


if __name__ == "__main__":
    main()
