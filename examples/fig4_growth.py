"""Fig. 4 of the paper by growth: cells divide (a) on a sphere of fixed radius, (b) on a sphere whose
radius keeps <A> = 1, and the tissue is quenched at chosen N to see whether it is rigid.

Start: relaxed tissues (FIRE + T1) of N = 32 cells at p0 = P0/sqrt(<A>) = 3.80, kr = 0 (kA = 0),
<A> = 1 (R = sqrt(N / 4 pi)). Held fixed through the growth: P0 = 3.80 (in units of the initial
sqrt(<A>) = 1), kP = 1, kA = 0. So on the fixed sphere <A> = 4 pi R^2 / N falls and the
dimensionless p0 = P0 / sqrt(<A>) rises with N; on the growing sphere <A> = 1 and p0 = 3.80 stays.

Growth: every round, a few cells per replica (chosen at random, at most doubling the tissue per
stage) divide through their centre perpendicular to their long axis (Hertwig's rule), then FIRE +
T1 relax the tissue briefly. At each N in --measure the tissue is quenched (FIRE + T1 to
force_tol or energy_tol) and we count the replicas that reach zero energy (energy per cell <
1e-12: floppy, the "compatible" side) and the mean shape index <P / sqrt(A)>.

    python examples/fig4_growth.py                  # small: N 32 -> 128, 6 replicas, CPU, a few minutes
    python examples/fig4_growth.py --full           # N 32 -> 512, 24 replicas (meant for a GPU later)
"""
import argparse
import time

import numpy as np

import spherevm as svm
from spherevm.analysis import rigidity
from spherevm.plugins.forces import VertexModel
from spherevm.plugins.integrators import FIRE
from spherevm.plugins.updaters import T1, Division, RadiusSchedule


def run(mode, args):
    sim = svm.Simulation(device=args.device, seed=args.seed)
    sim.state = svm.init.random_tiling(args.start, replicas=args.replicas, seed=args.seed)
    n0 = sim.state.n_cells
    # P0 fixed at p0 * sqrt(<A>_0) = 3.80 (<A>_0 = 1); kA = 0 (kr = 0), so A0 does not matter
    vm = VertexModel(kA=np.zeros(n0), kP=1.0, A0=np.ones(n0), P0=np.full(n0, args.p0))
    sim.operations.forces.append(vm)
    sim.operations.updaters.append(T1())
    growing = {"on": False}
    gen = np.random.default_rng(args.seed)

    def rule(s):
        if not growing["on"]:
            return []
        out = []
        for r, (a, b) in enumerate(zip(s.state.cell_start[:-1], s.state.cell_start[1:])):
            k = min(args.per_round, growing["target"] - (b - a))
            if k > 0:
                out.extend((a + gen.choice(b - a, size=k, replace=False)).tolist())
        return out

    division = Division(rule=rule, axis="hertwig")
    sim.operations.updaters.append(division)
    sim.operations.updaters.append(RadiusSchedule("fixed" if mode == "fixed" else "constant_area", area=1.0))
    sim.operations.integrator = FIRE(dt=0.05)
    rows = []

    def quench(n):
        res = sim.minimize(force_tol=1e-10, energy_tol=1e-16, max_steps=args.max_steps)
        status = rigidity.classify(res.energy_per_cell, res.reason)
        area = float(sim.state.mean_cell_area.mean())
        rows.append(dict(mode=mode, N=n, R=float(sim.state.radius_np().mean()), A=area,
                         p0=args.p0 / np.sqrt(area), zero=float(np.mean(status == "zero")),
                         unconverged=int(np.sum(~np.isin(status, ("zero", "rigid")))),
                         q=float(np.mean(res.mean_shape_index)), divisions=int(division.total_divisions.sum()),
                         refused=int(sum(v.sum() for v in division.refused.values()))))
        print(_row(rows[-1]), flush=True)

    n = args.start
    quench(n)                          # the relaxed initial tissues
    for target in sorted(t for t in args.measure if t > args.start):
        growing["target"] = target
        while n < target:
            sim.operations.integrator.reset()   # a quench stops converged replicas; Division acts on active ones
            before = sim.state.n_cells
            growing["on"] = True
            sim.run(1)                 # one division round (the Division pass runs first in the step)
            growing["on"] = False
            sim.run(args.relax)        # brief relaxation; positions keep moving, T1s happen
            n = int(sim.state.cells_per_replica.min())
            if sim.state.n_cells == before and division.last_divisions.sum() == 0:
                raise RuntimeError(f"no division in a round at N = {n}: every choice refused ({division.refused})")
        quench(n)
        sim.state.validate(orientation=False)
    return rows


HEADER = (f"{'sphere':>13s} {'N':>5s} {'R':>7s} {'<A>':>7s} {'p0=P0/sqrt<A>':>13s} {'zero-E frac':>11s} "
          f"{'unconv':>6s} {'<q>':>7s} {'divisions':>9s} {'refused':>7s}")


def _row(r):
    return (f"{r['mode']:>13s} {r['N']:5d} {r['R']:7.3f} {r['A']:7.4f} {r['p0']:13.3f} {r['zero']:11.3f} "
            f"{r['unconverged']:6d} {r['q']:7.4f} {r['divisions']:9d} {r['refused']:7d}")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--full", action="store_true", help="N 32 -> 512 with 24 replicas")
    ap.add_argument("--replicas", type=int, default=None)
    ap.add_argument("--start", type=int, default=32)
    ap.add_argument("--measure", type=int, nargs="+", default=None, help="N at which to quench")
    ap.add_argument("--p0", type=float, default=3.80, help="P0 in units of the initial sqrt(<A>) = 1")
    ap.add_argument("--per-round", type=int, default=4, help="divisions per replica per round")
    ap.add_argument("--relax", type=int, default=100, help="FIRE steps after each division round")
    ap.add_argument("--max-steps", type=int, default=20000, help="FIRE steps per quench")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--device", default="cpu")
    ap.add_argument("--modes", nargs="+", default=["fixed", "constant_area"])
    args = ap.parse_args(argv)
    if args.replicas is None:
        args.replicas = 24 if args.full else 6
    if args.measure is None:
        args.measure = [32, 64, 128, 256, 512] if args.full else [32, 64, 128]
    t0 = time.perf_counter()
    print(HEADER)
    for mode in args.modes:
        run(mode, args)
    print(f"# {time.perf_counter() - t0:.0f} s; P0 = {args.p0} fixed, kA = 0, kP = 1; zero-E: energy/cell < "
          f"{rigidity.ZERO_ENERGY_TOL:g} after FIRE + T1 (force_tol 1e-10, energy_tol 1e-16)")


if __name__ == "__main__":
    main()
