"""Cost of growth per step: FIRE + T1 steps without growth, with a Division whose rate rule draws
every step but divides no cell, and with divisions (the host round trip of a division step).

Target (issue 16): steps without a division cost what they cost without growth, plus one small
read-back (the chosen cells' ids).

    python benchmarks/bench_growth.py --device gpu [--cells 512 --replicas 24]
"""
from __future__ import annotations

import argparse
import platform
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import median_time  # noqa: E402

import spherevm as svm  # noqa: E402
from spherevm.plugins.forces import VertexModel  # noqa: E402
from spherevm.plugins.integrators import FIRE  # noqa: E402
from spherevm.plugins.updaters import T1, Division, RadiusSchedule  # noqa: E402


def simulation(args, division):
    sim = svm.Simulation(device=args.device, seed=1)
    sim.state = svm.init.random_tiling(args.cells, replicas=args.replicas, seed=1)
    sim.operations.forces.append(VertexModel.dimensionless(kr=0.0, p0=3.8))
    sim.operations.updaters.append(T1())
    if division is not None:
        sim.operations.updaters += [division, RadiusSchedule("constant_area")]
    sim.operations.integrator = FIRE(dt=0.05, check_every=10 ** 9)   # no convergence checks in the way
    sim.run(20)                                                       # compile, warm the pools
    return sim


def main(argv=None):
    ap = argparse.ArgumentParser(allow_abbrev=False, description=__doc__.splitlines()[0])
    ap.add_argument("--cells", type=int, default=512)
    ap.add_argument("--replicas", type=int, default=24)
    ap.add_argument("--steps", type=int, default=100)
    ap.add_argument("--device", default="auto")
    args = ap.parse_args(argv)
    dev = svm.device.resolve(args.device)
    print(f"# {platform.processor() or platform.machine()}, Python {platform.python_version()}, device={dev.name}, "
          f"{args.replicas} x {args.cells} cells, {args.steps} steps per timing")
    rows = [("FIRE + T1, no growth", None),
            ("+ Division(rate) + RadiusSchedule, no cell divides", Division(rule="rate", rate=1e-12, dt=1.0)),
            ("+ Division(rate = 0)", Division(rule="rate", rate=0.0))]
    base = None
    for name, division in rows:
        sim = simulation(args, division)
        t = median_time(lambda: sim.run(args.steps, check_every=10 ** 9), dev, repeat=5, warmup=1) / args.steps
        base = t if base is None else base
        print(f"{name:55s} {1e3 * t:8.3f} ms/step  ({t / base:5.2f} x)")
    sim = simulation(args, Division(rule=lambda s: list(range(0, s.state.n_cells, args.cells // 4 or 1))))
    n0 = sim.state.n_cells
    dev.synchronize()
    t0 = time.perf_counter()
    sim.run(10, check_every=10 ** 9)
    dev.synchronize()
    t = (time.perf_counter() - t0) / 10
    per = (sim.state.n_cells - n0) / 10
    print(f"{'a division step (' + f'{per:.0f} divisions, resize, follow)':55s} {1e3 * t:8.3f} ms/step  "
          f"({t / base:5.2f} x)")


if __name__ == "__main__":
    main()
