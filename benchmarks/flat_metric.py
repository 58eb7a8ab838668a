"""The flat-facet metric against the geodesic one on the same random tilings (the table in
docs/surfaces.md): per N, the mean over cells of |A_flat / A_geodesic - 1| and |P_flat /
P_geodesic - 1|, the total flat area's shortfall 1 - sum A_flat / 4 pi R^2, and the slopes of their
logarithms against log(h / R), h = sqrt(<A>) = sqrt(4 pi R^2 / N) the cell size.

    python benchmarks/flat_metric.py                     # N = 64 .. 4096, 4 replicas each
    python benchmarks/flat_metric.py --sizes 64 256 1024 4096 16384 --replicas 2
    python benchmarks/flat_metric.py --cost              # a VertexModel force under each metric

Takes a few seconds on one core.
"""
from __future__ import annotations

import argparse
import timeit

import numpy as np

import spherevm as svm
from spherevm.constraints import Sphere


def differences(n_cells: int, replicas: int, seed: int = 1):
    """``(h / R, mean relative area difference, mean relative perimeter difference, total shortfall)``
    over ``replicas`` random tilings of ``n_cells`` cells."""
    state = svm.init.random_tiling(n_cells, replicas=replicas, seed=seed)
    geodesic = state.constraint.cell_geometry(state)
    flat = Sphere(metric="flat").cell_geometry(state)
    R = state.radius_np()
    total = np.bincount(state.cell_replica_np(), weights=flat.area) / (4.0 * np.pi * R ** 2)
    return (np.sqrt(4.0 * np.pi / n_cells), float(np.mean(np.abs(flat.area / geodesic.area - 1.0))),
            float(np.mean(np.abs(flat.perimeter / geodesic.perimeter - 1.0))), float(np.mean(1.0 - total)))


def slope(h, values) -> float:
    """Least-squares slope of log(values) against log(h)."""
    return float(np.polyfit(np.log(h), np.log(values), 1)[0])


def cost(sizes):
    """Print the best of 5 x 5 VertexModel force evaluations (NumPy) per metric and size."""
    print("| N | geodesic | flat |")
    print("| --- | --- | --- |")
    for n in sizes:
        state = svm.init.random_tiling(n, seed=1)
        model = svm.plugins.forces.VertexModel.dimensionless(kr=1.0, p0=3.8)
        times = []
        for metric in ("geodesic", "flat"):
            state.constraint = Sphere(metric=metric)
            model.compute(state)
            times.append(min(timeit.repeat(lambda: model.compute(state), number=5, repeat=5)) / 5)
        print(f"| {n} | {times[0] * 1e3:.2f} ms | {times[1] * 1e3:.2f} ms |")


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0], allow_abbrev=False)
    parser.add_argument("--sizes", type=int, nargs="+", default=[64, 256, 1024, 4096], help="cells per tiling")
    parser.add_argument("--replicas", type=int, default=4, help="tilings per size")
    parser.add_argument("--cost", action="store_true", help="time a force at 1,024 and 16,384 cells instead")
    args = parser.parse_args(argv)
    if args.cost:
        cost([1024, 16384])
        return
    rows = np.array([differences(n, args.replicas) for n in args.sizes])
    print("| N | h / R | area: mean rel. difference | perimeter: mean rel. difference | 1 - sum A / 4 pi R^2 |")
    print("| --- | --- | --- | --- | --- |")
    for n, (h, area, perimeter, total) in zip(args.sizes, rows):
        print(f"| {n} | {h:.3f} | {area:.3e} | {perimeter:.3e} | {total:.3e} |")
    print(f"| slope against h / R | | {slope(rows[:, 0], rows[:, 1]):.3f} | {slope(rows[:, 0], rows[:, 2]):.3f} | "
          f"{slope(rows[:, 0], rows[:, 3]):.3f} |")


if __name__ == "__main__":
    main()
