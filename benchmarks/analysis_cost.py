"""Cost of the dynamics analysis (docs/analysis.md, "Cost"): one time origin, and all origins.

    python benchmarks/analysis_cost.py [--replicas 256] [--cells 32] [--frames 60] [--seed 0]

A synthetic trajectory: ``replicas`` tissues of ``cells`` cells (radius sqrt(N / 4 pi)), each cell
diffusing on its sphere, ``frames`` frames. Times ``self_overlap`` with ``origins="first"`` (one
origin, ``frames`` lags) and ``origins="all"`` (every pair of frames), rotation removal on. Run on
one core (BLAS threads pinned to 1 before NumPy is imported).
"""
import os

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import argparse  # noqa: E402
import datetime  # noqa: E402
import platform  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402

from spherevm.analysis import Trajectory, self_overlap  # noqa: E402


def synthetic(replicas, cells, frames, seed):
    rng = np.random.default_rng(seed)
    radius = np.full(replicas, np.sqrt(cells / (4 * np.pi)))
    x = rng.normal(size=(replicas * cells, 3))
    steps = rng.normal(scale=0.05, size=(frames, replicas * cells, 3)).cumsum(axis=0)
    pos = x[None] + steps
    pos *= radius[0] / np.linalg.norm(pos, axis=2, keepdims=True)
    return Trajectory(np.arange(frames, dtype=float), pos, np.repeat(np.arange(replicas), cells), radius)


def best_of(fn, repeat=3):
    out = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        out.append(time.perf_counter() - t0)
    return min(out)


def main(argv=None):
    ap = argparse.ArgumentParser(allow_abbrev=False, description=__doc__.splitlines()[0])
    ap.add_argument("--replicas", type=int, default=256)
    ap.add_argument("--cells", type=int, default=32)
    ap.add_argument("--frames", type=int, default=60)
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args(argv)
    traj = synthetic(args.replicas, args.cells, args.frames, args.seed)
    print(f"# {datetime.date.today()} {platform.machine()}, one core, {args.replicas} tissues x {args.cells} cells, "
          f"{args.frames} frames, seed {args.seed}")
    t1 = best_of(lambda: self_overlap(traj, origins="first"))
    ta = best_of(lambda: self_overlap(traj, origins="all"), repeat=1)
    print(f"self_overlap, one origin ({args.frames - 1} lags): {t1:.3f} s;  origins='all': {ta:.2f} s")


if __name__ == "__main__":
    main()
