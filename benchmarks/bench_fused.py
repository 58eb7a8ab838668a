"""The fused small-tissue steps with other operations than the vertex model, T1 and Brownian
dynamics: each row's time a step against the reference row's, all in one process, alternated.

    python benchmarks/bench_fused.py [--tissues 8 --cells 1024 --steps 2000 --repeat 7]

Rows (each with T1, on random spherical tilings, p0 = 3.775, kr = 0):

* ``VertexModel + Brownian``: the reference;
* ``+ Active (cell directors)`` and ``+ Active (vertex directors)``: the integrator's own stage;
* ``VertexModel + line tension + Brownian``: a user's force with its fused stage
  (``tests/plugin_example``, ``FastLineTension``);
* ``VertexModel + Bending + Brownian``: the bending force's stage joined into the vertex model's
  (``Force.fused_combined``), its neighbour part a second per-cell phase (target: within 1.3x of
  the reference);
* ``... in graphs``: the same, ``run(fused=False)``, for comparison.

Each row prints ``sim.explain()``'s executor and the median ms a step over ``--repeat`` runs of
``--steps`` steps (every row run once in turn, then again). Needs a GPU.
"""
import argparse
import pathlib
import sys
import time

import numpy as np

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent.parent / "tests" / "plugin_example"))

import spherevm as svm  # noqa: E402
from spherevm.plugins.forces import Bending, VertexModel  # noqa: E402
from spherevm.plugins.integrators import Active, Brownian  # noqa: E402
from spherevm.plugins.updaters import T1  # noqa: E402
from spherevm_line_tension import FastLineTension  # noqa: E402

#: the bending rows' B: a cell's bending force grows as B / |a|, and on these unrelaxed tilings B = 0.1
#: or more explodes within 4 steps on every path, NumPy's included (B costs nothing in time)
BENDING = 0.01


def simulation(state, integrator, extra=None):
    sim = svm.Simulation(device="gpu", seed=1)
    sim.state = state
    sim.operations.forces.append(VertexModel.dimensionless(kr=0.0, p0=3.775))
    if extra is not None:
        sim.operations.forces.append(extra)
    sim.operations.updaters.append(T1())
    sim.operations.integrator = integrator
    return sim


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0], allow_abbrev=False)
    parser.add_argument("--tissues", type=int, default=8)
    parser.add_argument("--cells", type=int, default=1024)
    parser.add_argument("--steps", type=int, default=2000)
    parser.add_argument("--repeat", type=int, default=7)
    args = parser.parse_args(argv)
    import cupy as cp
    state = svm.State.concatenate([svm.init.random_tiling(args.cells, seed=1 + i) for i in range(args.tissues)])
    rows = {
        "VertexModel + Brownian": (lambda: simulation(state, Brownian(dt=0.01, T=0.01)), {}),
        "+ Active (cell directors)": (lambda: simulation(state, Active(dt=0.01, v0=0.1, Dr=0.1, T=0.01)), {}),
        "+ Active (vertex directors)": (
            lambda: simulation(state, Active(dt=0.01, v0=0.1, Dr=0.1, T=0.01, directors="vertex")), {}),
        "VertexModel + line tension + Brownian": (
            lambda: simulation(state, Brownian(dt=0.01, T=0.01), FastLineTension(0.1)), {}),
        "VertexModel + line tension, in graphs": (
            lambda: simulation(state, Brownian(dt=0.01, T=0.01), FastLineTension(0.1)), {"fused": False}),
        "VertexModel + Bending + Brownian": (
            lambda: simulation(state, Brownian(dt=0.01, T=0.01), Bending(BENDING)), {}),
        "VertexModel + Bending, in graphs": (
            lambda: simulation(state, Brownian(dt=0.01, T=0.01), Bending(BENDING)), {"fused": False}),
    }
    sims = {name: make() for name, (make, _) in rows.items()}
    times = {name: [] for name in rows}
    for name, sim in sims.items():                       # warm-up: compile, capture
        sim.run(200, **rows[name][1])
    cp.cuda.Device().synchronize()
    for _ in range(args.repeat):
        for name, sim in sims.items():
            start = time.perf_counter()
            sim.run(args.steps, **rows[name][1])
            cp.cuda.Device().synchronize()
            times[name].append((time.perf_counter() - start) / args.steps * 1e3)
    ref = np.median(times["VertexModel + Brownian"])
    print(f"{args.tissues} x {args.cells} cells, T1 every step, {args.steps} steps a run, {args.repeat} runs "
          f"alternated; {cp.cuda.runtime.getDeviceProperties(0)['name'].decode()}")
    print(f"{'row':40s} {'executor':>13s} {'ms/step':>9s} {'min':>8s} {'max':>8s} {'x ref':>6s}")
    for name, sim in sims.items():
        executor = "CUDA graphs" if rows[name][1].get("fused") is False else sim.explain().splitlines()[1].split()[1]
        t = np.array(times[name])
        print(f"{name:40s} {executor:>13s} {np.median(t):9.4f} {t.min():8.4f} {t.max():8.4f} "
              f"{np.median(t) / ref:6.2f}")


if __name__ == "__main__":
    main()
