"""Cost of a T1 pass that finds no short edge, relative to one force evaluation (NumPy path).

Target (issue: T1 neighbour exchanges): at most 30% of a force evaluation at N = 10,000 cells.

    python benchmarks/bench_t1.py [--cells 10000]
"""
from __future__ import annotations

import argparse
import platform
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import median_time  # noqa: E402

import spherevm as svm  # noqa: E402


def main(argv=None):
    ap = argparse.ArgumentParser(allow_abbrev=False, description=__doc__.splitlines()[0])
    ap.add_argument("--cells", type=int, nargs="+", default=[1000, 10000])
    ap.add_argument("--device", default="cpu")
    args = ap.parse_args(argv)
    print(f"# {platform.processor() or platform.machine()}, Python {platform.python_version()}, device={args.device}")
    print(f"{'cells':>8} {'force [ms]':>11} {'T1 pass [ms]':>13} {'ratio':>7}")
    for n in args.cells:
        sim = svm.Simulation(device=args.device)
        sim.state = svm.init.random_tiling(n, seed=1)
        force = svm.plugins.forces.VertexModel.dimensionless(kr=1.0, p0=3.8)
        t1 = svm.plugins.updaters.T1(threshold=1e-6, new_length=2e-6)  # nothing is that short
        sim.operations.updaters.append(t1)
        state = sim.state
        assert len(t1.short_edges(state)[0]) == 0
        t_force = median_time(lambda: force.compute(state), sim.device)
        t_t1 = median_time(lambda: t1.update(sim, 0), sim.device)
        print(f"{n:8d} {1e3 * t_force:11.3f} {1e3 * t_t1:13.3f} {t_t1 / t_force:7.2f}")


if __name__ == "__main__":
    main()
