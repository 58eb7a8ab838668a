"""VertexModel alone against VertexModel + Bending: median time of one force evaluation.

    python benchmarks/bench_bending.py                  # CPU rows: 1,000 and 65,536 cells
    python benchmarks/bench_bending.py --device gpu     # GPU rows: 1e6 cells, 4,096 x 64 cells

A force evaluation is what a Simulation does per step (``Simulation.compute_forces`` after
``state_changed``): with both forces attached, Bending.combined computes them together (one corner
pass on the CPU; on the GPU the vertex model's kernels with the bending terms fused in). Columns:
``VM`` the vertex model alone, ``VM+B`` both in a Simulation, ``ratio`` VM+B / VM (target <= 1.5),
``apart`` the two ``compute`` calls one after the other, ``B`` Bending.compute alone. Medians of
``--repeat`` rounds after warm-up, the five timed in turn within each round (so that a shared
machine's changing load affects them alike), the device synchronised around every call; the first
calls compile the kernels and fill the topology caches. The CPU rows print the load average;
``--cpu-time`` times the CPU time of all threads instead of wall time.
"""
from __future__ import annotations

import argparse
import datetime
import os
import platform
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import median_times  # noqa: E402

import spherevm as svm  # noqa: E402
from spherevm.plugins.forces import Bending, VertexModel  # noqa: E402

ROWS = {"cpu": [(1000, 1), (65536, 1)], "gpu": [(1_000_000, 1), (64, 4096)]}


def evaluation(state, *forces):
    """A callable doing one Simulation force evaluation of ``forces`` on ``state``."""
    sim = svm.Simulation(device=state.device)
    sim.state = state
    sim.operations.forces.extend(forces)

    def run():
        sim.state_changed()
        return sim.compute_forces()
    return run


def main(argv=None):
    ap = argparse.ArgumentParser(allow_abbrev=False, description=__doc__.splitlines()[0])
    ap.add_argument("--device", default="cpu")
    ap.add_argument("--rows", nargs="*", default=None, help="CELLSxREPLICAS, e.g. 1000x1 64x4096")
    ap.add_argument("--repeat", type=int, default=11)
    ap.add_argument("--cpu-time", action="store_true",
                    help="time the CPU time of all threads (time.process_time), not wall time: ratios less "
                         "sensitive to other processes on a shared machine")
    args = ap.parse_args(argv)
    device = svm.device.resolve(args.device)
    rows = ROWS[device.name] if args.rows is None else [tuple(int(v) for v in r.split("x")) for r in args.rows]
    print(f"# spherevm bench_bending, {datetime.date.today()}, {platform.machine()}, {os.cpu_count()} cores, "
          f"Python {platform.python_version()}, device={device.name}, {'CPU' if args.cpu_time else 'wall'} time")
    print(f"{'cells':>8} {'replicas':>8} {'VM ms':>9} {'VM+B ms':>9} {'ratio':>6} {'apart ms':>9} {'B ms':>8}"
          + ("" if device.is_gpu else f" {'load':>5}"))
    for n, replicas in rows:
        state = svm.init.random_tiling(n, replicas=replicas, seed=1, device=device)
        vm, bend = VertexModel.dimensionless(kr=1.0, p0=3.8), Bending(0.1)
        t_vm, t_sum, t_apart, t_b = median_times(
            [evaluation(state, vm), evaluation(state, vm, bend),
             lambda: (vm.compute(state), bend.compute(state)), lambda: bend.compute(state)], device, repeat=args.repeat,
            clock=time.process_time if args.cpu_time else time.perf_counter)
        load = "" if device.is_gpu else f" {os.getloadavg()[0]:5.1f}"
        print(f"{n:8d} {replicas:8d} {1e3 * t_vm:9.3f} {1e3 * t_sum:9.3f} {t_sum / t_vm:6.2f} {1e3 * t_apart:9.3f} "
              f"{1e3 * t_b:8.3f}{load}", flush=True)


if __name__ == "__main__":
    main()
