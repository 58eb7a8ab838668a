"""A VertexModel force (NumPy, one core) on implicit surfaces against the sphere's: the torus, the
ellipsoid, the Gaussian bump and the user's sinusoid of tests/plugin_example, at 1,000 and 65,536
cells (the table in docs/surfaces.md). Each surface's time is a median over rounds that time every
surface in turn (a shared machine's load changes alike), with the ratio to the geodesic sphere's.

    python benchmarks/surfaces_cpu.py                      # 1,000 and 65,536 cells
    python benchmarks/surfaces_cpu.py --sizes 1000 --repeat 5

Takes about a minute (the 65,536-cell tilings take most of it).
"""
from __future__ import annotations

import argparse
import os
import pathlib
import sys

os.environ.setdefault("OMP_NUM_THREADS", "1")           # one core: before NumPy loads
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import spherevm as svm  # noqa: E402
from spherevm.constraints import Ellipsoid, GaussianBump, Sphere, Torus  # noqa: E402
from spherevm.constraints.corners import single_threaded  # noqa: E402

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent.parent / "tests" / "plugin_example"))
from common import median_times  # noqa: E402
from spherevm_sinusoid import Sinusoid  # noqa: E402


def states(n):
    """A random tiling of n cells (<A> = 1) on each surface, by name."""
    out = {"sphere": svm.init.random_tiling(n, seed=1)}
    flat = svm.init.random_tiling(n, seed=1)
    flat.constraint = Sphere(metric="flat")
    out["sphere (flat metric)"] = flat
    for name, surface in (("torus 3:1", Torus(3.0, 1.0)), ("ellipsoid 1:1.5:2", Ellipsoid(1.0, 1.5, 2.0)),
                          ("bump", GaussianBump(1.0, 1.0, 10.0)), ("sinusoid", Sinusoid(1.0, 10.0))):
        out[name] = svm.init.random_tiling(n, seed=1, surface=surface)
    return out


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0], allow_abbrev=False)
    parser.add_argument("--sizes", type=int, nargs="+", default=[1000, 65536], help="cells per tiling")
    parser.add_argument("--repeat", type=int, default=11, help="rounds timed")
    args = parser.parse_args(argv)
    single_threaded()
    model = svm.plugins.forces.VertexModel.dimensionless(kr=1.0, p0=3.8)
    print("| surface | N | force | / sphere |")
    print("| --- | --- | --- | --- |")
    for n in args.sizes:
        tilings = states(n)
        times = median_times([lambda s=s: model.compute(s) for s in tilings.values()], repeat=args.repeat)
        for (name, _), t in zip(tilings.items(), times):
            print(f"| {name} | {n} | {t * 1e3:.2f} ms | {t / times[0]:.2f} |")


if __name__ == "__main__":
    main()
