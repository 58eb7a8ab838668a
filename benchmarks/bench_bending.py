"""VertexModel alone against VertexModel + Bending: median time of one force evaluation.

    python benchmarks/bench_bending.py                  # CPU rows: 1,000 and 65,536 cells
    python benchmarks/bench_bending.py --device gpu     # GPU rows: 1e6 cells, 4,096 x 64 cells

Each row times ``VertexModel.compute`` and ``VertexModel.compute + Bending.compute`` on the same
State (medians after warm-up, the device synchronised around every call; the first calls compile
the kernels and fill the topology caches). Target: the sum costs at most 1.5x the vertex model.
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
from spherevm.plugins.forces import Bending, VertexModel  # noqa: E402

ROWS = {"cpu": [(1000, 1), (65536, 1)], "gpu": [(1_000_000, 1), (64, 4096)]}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--device", default="cpu")
    ap.add_argument("--rows", nargs="*", default=None, help="CELLSxREPLICAS, e.g. 1000x1 64x4096")
    ap.add_argument("--repeat", type=int, default=11)
    args = ap.parse_args(argv)
    device = svm.device.resolve(args.device)
    rows = ROWS[device.name] if args.rows is None else [tuple(int(v) for v in r.split("x")) for r in args.rows]
    print(f"# spherevm bench_bending, {datetime.date.today()}, {platform.machine()}, "
          f"Python {platform.python_version()}, device={device.name}")
    print(f"{'cells':>8} {'replicas':>8} {'VM ms':>9} {'VM+B ms':>9} {'B ms':>8} {'ratio':>6}")
    for n, replicas in rows:
        state = svm.init.random_tiling(n, replicas=replicas, seed=1, device=device)
        vm, bend = VertexModel.dimensionless(kr=1.0, p0=3.8), Bending(0.1)
        t_vm = median_time(lambda: vm.compute(state), device, repeat=args.repeat)
        t_sum = median_time(lambda: (vm.compute(state), bend.compute(state)), device, repeat=args.repeat)
        t_b = median_time(lambda: bend.compute(state), device, repeat=args.repeat)
        print(f"{n:8d} {replicas:8d} {1e3 * t_vm:9.3f} {1e3 * t_sum:9.3f} {1e3 * t_b:8.3f} {t_sum / t_vm:6.2f}",
              flush=True)


if __name__ == "__main__":
    main()
