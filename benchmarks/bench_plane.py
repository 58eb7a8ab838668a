"""The periodic plane's costs, beside the sphere's and cellGPU's (issue 11).

    python benchmarks/bench_plane.py --cpu-only                 # the NumPy force at 1,000 cells
    python benchmarks/bench_plane.py --cellgpu .peers/cellgpu_bench --json out.json

Rows:

* CPU: one planar force evaluation at 1,000 cells (NumPy, one core; the sphere's beside it).
* GPU, per size (1e3 ... 1e6 cells, and 4,096 x 64): one force evaluation, one Brownian step with its
  T1 check, one FIRE iteration with its T1 check, on the plane and on the sphere. cellGPU's model
  (KA = KP = A0 = 1, p0 = 3.8, T1 threshold 0.01, Brownian T = dt = 1e-3): VertexModel(kA=1, kP=1,
  A0=1, P0=3.8) on random tilings with <A> = 1, T1(threshold=0.01, new_length=0.03) every step,
  Brownian(dt=1e-3, T=1e-3), FIRE(dt=0.01). A step is the updaters then the forces and the move
  (Simulation.run_updaters, integrate), as cellGPU's performTimestep is its forces, move and topology.
  "minimize ms/it": a FIRE + T1 iteration as ``Simulation.minimize`` runs it (1,000 iterations, 200
  at 1e6 cells, in CUDA graphs, with a convergence check every 10; :func:`minimize_iteration_time`).
* cellGPU (``--cellgpu PATH``): the peer binary (../shared/tools/peers/README.md) run in the same
  process with ``--sort --no-spp`` at the same sizes, its summary table parsed.

Medians of ``--reps`` calls (200, 100 at 1e6 cells) after ``--warm`` warm-up calls (20), the device
synchronised around each (cellGPU's harness does the same). The 4,096 x 64 ensembles are 64 copies
of one tiling (the cost does not depend on which tilings they are; drawing 64 planar tilings takes
longer than the timing).
"""
from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import median_time, run_step_time  # noqa: E402

import spherevm as svm  # noqa: E402
from spherevm.device import info, resolve  # noqa: E402
from spherevm.plugins.forces import VertexModel  # noqa: E402
from spherevm.plugins.integrators import FIRE, Brownian  # noqa: E402
from spherevm.plugins.updaters import T1  # noqa: E402

SIZES = (1000, 10000, 100000, 1000000)
ENSEMBLE = (4096, 64)


def model():
    return VertexModel(kA=1.0, kP=1.0, A0=1.0, P0=3.8)


def tiling(surface, n_cells, copies=1, seed=1):
    one = (svm.init.random_planar_tiling if surface == "plane" else svm.init.random_tiling)(n_cells, seed=seed)
    return one if copies == 1 else svm.State.concatenate([one] * copies)


def simulation(state, device, integrator):
    sim = svm.Simulation(device=device, seed=1)
    sim.state = state
    sim.operations.forces.append(model())
    sim.operations.updaters.append(T1(threshold=0.01, new_length=0.03))
    sim.operations.integrator = integrator
    return sim


def step(sim):
    sim.run_updaters()
    sim.integrate()


def cpu_force(surface, n_cells=1000, reps=200, warm=20):
    """ms per NumPy force evaluation at ``n_cells`` (one core: no threads below 16,384 vertices)."""
    state = tiling(surface, n_cells)
    force = model()
    return 1e3 * median_time(lambda: force.compute(state), None, repeat=reps, warmup=warm)


def gpu_row(surface, n_cells, copies, gpu, reps, warm):
    """ms per force, Brownian + T1 step and FIRE + T1 iteration on ``surface``, and tiling seconds."""
    t0 = time.perf_counter()
    state = tiling(surface, n_cells, copies)
    made = time.perf_counter() - t0
    dev_state = state.to(gpu)
    force = model()
    row = dict(surface=surface, cells=n_cells, copies=copies, tiling_s=made)
    row["force_ms"] = 1e3 * median_time(lambda: force.compute(dev_state), gpu, repeat=reps, warmup=warm)
    brown = simulation(state, gpu, Brownian(dt=1e-3, T=1e-3))
    row["brownian_t1_ms"] = 1e3 * median_time(lambda: step(brown), gpu, repeat=reps, warmup=warm)
    brown.operations.integrator.check(brown)
    graphed = simulation(state, gpu, Brownian(dt=1e-3, T=1e-3))
    row["brownian_t1_graph_ms"] = 1e3 * run_step_time(graphed, gpu, steps=200 if n_cells * copies >= 10 ** 6 else 1000)
    fire = simulation(state, gpu, FIRE(dt=0.01))
    row["fire_t1_ms"] = 1e3 * median_time(lambda: step(fire), gpu, repeat=reps, warmup=warm)
    fire.operations.integrator.check(fire)
    row["fire_t1_minimize_ms"] = 1e3 * minimize_iteration_time(state, gpu, steps=200 if n_cells * copies >= 10 ** 6 else 1000)
    row["t1_flips"] = int(brown.log("t1_total_flips").sum())
    return row


def minimize_iteration_time(state, gpu, steps, repeat=3):
    """Seconds per iteration of ``Simulation.minimize(steps)`` with FIRE + T1 from ``state``: the
    iterations in CUDA graphs, a convergence check (one read-back) every 10 of them included, as a
    minimisation runs. The median of ``repeat`` minimisations from the same start, after one that
    builds the graphs' caches."""
    times = []
    for _ in range(repeat + 1):
        sim = simulation(state, gpu, FIRE(dt=0.01))
        gpu.synchronize()
        t0 = time.perf_counter()
        sim.minimize(max_steps=steps, graphs=True)
        gpu.synchronize()
        times.append((time.perf_counter() - t0) / max(sim.operations.integrator.iteration, 1))
    return float(np.median(times[1:]))


def cellgpu(path, sizes, timeout=900):
    """cellGPU's medians (ms) per size from its summary table: force, T1 check, Brownian, FIRE."""
    cmd = [str(path), "--sort", "--no-spp", "-n", ",".join(str(n) for n in sizes)]
    done = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout)
    out = {}
    lines = done.stdout.splitlines()
    summary = lines[next(i for i, line in enumerate(lines) if "===== summary" in line) + 2:]
    for line in summary:
        f = line.split()
        if len(f) >= 10 and f[0].isdigit():
            number = lambda x: float(x) if x != "fail" else float("nan")  # noqa: E731
            out[int(f[0])] = dict(force_ms=number(f[3]), t1chk_ms=number(f[6]), brownian_t1_ms=number(f[7]),
                                  fire_ms=number(f[9]))
    return out, done.stdout


def fmt(x, digits=3):
    return "" if x is None or (isinstance(x, float) and np.isnan(x)) else f"{x:.{digits}f}"


def main(argv=None):
    ap = argparse.ArgumentParser(allow_abbrev=False, description="planar benchmark (issue 11)")
    ap.add_argument("--cells", type=float, nargs="+", default=list(SIZES))
    ap.add_argument("--reps", type=int, default=200)
    ap.add_argument("--warm", type=int, default=20)
    ap.add_argument("--cpu-only", action="store_true", help="only the NumPy force at 1,000 cells")
    ap.add_argument("--no-sphere", action="store_true", help="skip the sphere's GPU rows")
    ap.add_argument("--cellgpu", default=None, help="path of cellgpu_bench, run in the same process")
    ap.add_argument("--json", default=None, help="write every number here")
    args = ap.parse_args(argv)
    facts = info()
    print(f"# {time.strftime('%Y-%m-%d %H:%M')}, spherevm {svm.__version__}, numpy {facts['numpy']}, "
          f"cupy {facts.get('cupy')}, gpus {facts.get('gpus')}")
    result = dict(info=facts, cpu={}, gpu=[], cellgpu={})
    for surface in ("plane", "sphere"):
        result["cpu"][surface] = ms = cpu_force(surface, reps=args.reps, warm=args.warm)
        print(f"CPU NumPy force, 1,000 cells, {surface}: {ms:.3f} ms (median of {args.reps})")
    if not args.cpu_only:
        gpu = resolve("gpu")
        sizes = [int(n) for n in args.cells]
        if args.cellgpu:       # first: the peer's fixed cost, before our tilings take the time there is
            result["cellgpu"], raw = cellgpu(args.cellgpu, sizes)
            result["cellgpu_stdout"] = raw
            print(raw[raw.find("# ===== summary"):], flush=True)
        systems = [(n, 1) for n in sizes] + [ENSEMBLE]
        for n, copies in systems:
            reps = max(args.reps // 2, 11) if n * copies >= 10 ** 6 else args.reps
            for surface in ("plane",) if args.no_sphere else ("plane", "sphere"):
                row = gpu_row(surface, n, copies, gpu, reps, args.warm)
                result["gpu"].append(row)
                print(json.dumps(row), flush=True)
                if args.json:
                    Path(args.json).write_text(json.dumps(result, indent=1, default=str))
        print()
        print("| system | plane force ms | sphere force ms | plane Brownian + T1 ms | sphere Brownian + T1 ms "
              "| plane in graphs | sphere in graphs | cellGPU Brownian + T1 ms | plane FIRE + T1 ms | sphere FIRE + T1 ms "
              "| plane minimize ms/it | sphere minimize ms/it | cellGPU FIRE ms |")
        print("| ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: |")
        for n, copies in systems:
            rows = {r["surface"]: r for r in result["gpu"] if r["cells"] == n and r["copies"] == copies}
            p, s = rows["plane"], rows.get("sphere", {})
            peer = result["cellgpu"].get(n, {}) if copies == 1 else {}
            name = f"{n:.0e}" if copies == 1 else f"{n} x {copies}"
            print(f"| {name} | {fmt(p['force_ms'])} | {fmt(s.get('force_ms'))} | {fmt(p['brownian_t1_ms'])} | "
                  f"{fmt(s.get('brownian_t1_ms'))} | {fmt(p['brownian_t1_graph_ms'])} | {fmt(s.get('brownian_t1_graph_ms'))} | "
                  f"{fmt(peer.get('brownian_t1_ms'))} | {fmt(p['fire_t1_ms'])} | "
                  f"{fmt(s.get('fire_t1_ms'))} | {fmt(p['fire_t1_minimize_ms'])} | {fmt(s.get('fire_t1_minimize_ms'))} | "
                  f"{fmt(peer.get('fire_ms'))} |")
    if args.json:
        Path(args.json).write_text(json.dumps(result, indent=1, default=str))


if __name__ == "__main__":
    main()
