"""Median time of one force evaluation (cell geometry + vertex-model forces) on the active backend.

    python benchmarks/bench_forces.py [--device cpu|gpu|auto] [--cells 1000 10000 65536 100000]

Targets for the NumPy path on a 2-core machine: <= 1.5 ms at N = 1,000 and <= 90 ms at N = 65,536.
"""
from __future__ import annotations

import argparse
import datetime
import platform
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import median_time  # noqa: E402

import spherevm as svm  # noqa: E402


def main(argv=None):
    ap = argparse.ArgumentParser(allow_abbrev=False, description=__doc__.splitlines()[0])
    ap.add_argument("--cells", type=int, nargs="+", default=[1000, 10000, 65536, 100000])
    ap.add_argument("--device", default="cpu")
    ap.add_argument("--repeat", type=int, default=9)
    args = ap.parse_args(argv)
    device = svm.device.resolve(args.device)
    print(f"# spherevm {svm.__version__}, {datetime.date.today()}, {platform.machine()}, "
          f"Python {platform.python_version()}, device={device.name}")
    print(f"{'cells':>8} {'vertices':>9} {'median ms':>10} {'ns/cell':>8}")
    for n in args.cells:
        state = svm.init.random_tiling(n, seed=1, device=device)
        force = svm.plugins.forces.VertexModel.dimensionless(kr=1.0, p0=3.8)
        t = median_time(lambda: force.compute(state), device, repeat=args.repeat)
        print(f"{n:8d} {state.n_vertices:9d} {1e3 * t:10.3f} {1e9 * t / n:8.0f}", flush=True)


if __name__ == "__main__":
    main()
