"""Implicit surfaces on the GPU against the sphere (issue 38's speed rows; the table in
docs/surfaces.md): the torus (R/r = 3), the ellipsoid (1 : 1.5 : 2) and the user's sinusoid of
tests/plugin_example, each beside the geodesic sphere, at three sizes:

* 1e6 cells (one tiling) and 4,096 x 64 (64 copies of one tiling): one VertexModel force evaluation,
  and one Brownian step with its T1 check as ``Simulation.run`` takes it (CUDA graphs, a check every
  100 steps; ms a step over ``--steps`` steps);
* 8 x 1,024 (eight tilings): the same step on the fused small-tissue path.

The model is the digests' (``VertexModel.dimensionless(kr=0, p0=3.775)``, ``T1()``,
``Brownian(dt=0.01, T=0.05)``); every tiling has <A> = 1. Within a size the surfaces are timed in
turn, round after round (:func:`common.median_times`), and each row prints its median and its ratio
to the sphere's, with ``sim.explain()``'s executor.

    python benchmarks/surfaces_gpu.py                     # all three sizes (under 2 minutes on an H200)
    python benchmarks/surfaces_gpu.py --sizes 8x1024 --repeat 5

The tilings are built first, in parallel processes, before CUDA starts.
"""
from __future__ import annotations

import argparse
import pathlib
import sys
import time
from concurrent.futures import ProcessPoolExecutor

HERE = pathlib.Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(HERE.parent / "tests" / "plugin_example"))

import spherevm as svm  # noqa: E402
from common import median_times  # noqa: E402

SIZES = {"1e6": (1_000_000, 1), "4096x64": (4096, 64), "8x1024": (1024, 8)}
SURFACES = ("sphere", "torus 3:1", "ellipsoid 1:1.5:2", "sinusoid")


def surface(name):
    """The constraint a surface's tilings are drawn on (None: the geodesic sphere)."""
    from spherevm.constraints import Ellipsoid, Torus
    from spherevm_sinusoid import Sinusoid
    return {"sphere": None, "torus 3:1": Torus(3.0, 1.0), "ellipsoid 1:1.5:2": Ellipsoid(1.0, 1.5, 2.0),
            "sinusoid": Sinusoid(1.0, 10.0)}[name]


def tiling(job):
    """The State of one (surface, size) pair: one tiling copied, or distinct tilings when fused."""
    name, size = job
    n, copies = SIZES[size]
    kind = surface(name)
    distinct = copies if size == "8x1024" else 1
    state = svm.init.random_tiling(n, replicas=distinct, seed=1, surface=kind)
    return state if distinct == copies else svm.State.concatenate([state] * copies)


def simulation(state):
    from spherevm.plugins.forces import VertexModel
    from spherevm.plugins.integrators import Brownian
    from spherevm.plugins.updaters import T1
    sim = svm.Simulation(device="gpu", seed=3)
    sim.state = state
    sim.operations.forces.append(VertexModel.dimensionless(kr=0.0, p0=3.775))
    sim.operations.updaters.append(T1())
    sim.operations.integrator = Brownian(dt=0.01, T=0.05)
    return sim


def executor(sim):
    """How ``run`` takes the vertex model (fused, CUDA graphs, step by step), from ``sim.explain()``."""
    line = next(x for x in sim.explain().splitlines() if x.split()[:1] == ["VertexModel"])
    return line.split(None, 1)[1].split("(")[0].strip()


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0], allow_abbrev=False)
    parser.add_argument("--sizes", nargs="+", default=list(SIZES), choices=list(SIZES))
    parser.add_argument("--surfaces", nargs="+", default=list(SURFACES), choices=list(SURFACES))
    parser.add_argument("--repeat", type=int, default=7, help="rounds timed")
    parser.add_argument("--steps", type=int, default=None, help="steps a timed run (default 200 at 1e6 cells, "
                                                                  "1,000 otherwise)")
    args = parser.parse_args(argv)
    jobs = [(name, size) for size in args.sizes for name in args.surfaces]
    t0 = time.perf_counter()
    with ProcessPoolExecutor(max_workers=min(len(jobs), 8)) as pool:
        states = dict(zip(jobs, pool.map(tiling, jobs)))
    print(f"# tilings built in {time.perf_counter() - t0:.1f} s", flush=True)
    from spherevm.device import info, resolve
    from spherevm.plugins.forces import VertexModel
    gpu = resolve("gpu")
    facts = info()
    print(f"# {time.strftime('%Y-%m-%d %H:%M')}, spherevm {svm.__version__}, cupy {facts.get('cupy')}, "
          f"gpus {facts.get('gpus')}")
    print("| size | surface | force ms | / sphere | Brownian + T1 ms a step | / sphere | executor |")
    print("| --- | --- | ---: | ---: | ---: | ---: | --- |")
    force = VertexModel.dimensionless(kr=0.0, p0=3.775)
    for size in args.sizes:
        steps = args.steps or (200 if size == "1e6" else 1000)
        on_gpu = {name: states[name, size].to(gpu) for name in args.surfaces}
        sims = {name: simulation(states[name, size]) for name in args.surfaces}
        forces = median_times([lambda s=s: force.compute(s) for s in on_gpu.values()], gpu, repeat=args.repeat)
        runs = median_times([lambda s=s: s.run(steps) for s in sims.values()], gpu, repeat=args.repeat, warmup=1)
        base_f, base_r = forces[0], runs[0]
        for name, f, r in zip(args.surfaces, forces, runs):
            print(f"| {size} | {name} | {f * 1e3:.3f} | {f / base_f:.2f} | {r / steps * 1e3:.4f} | {r / base_r:.2f} "
                  f"| {executor(sims[name])} |", flush=True)


if __name__ == "__main__":
    main()
