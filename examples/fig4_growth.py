"""Fig. 4 of the paper by growth: cells divide (a) on a sphere of fixed radius, (b) on a sphere whose
radius keeps <A> = 1, and the tissue is quenched at chosen N to see whether it is rigid.

Start: relaxed tissues (FIRE + T1) of N = 32 cells at p0 = P0/sqrt(<A>) = 3.80, kr = 0 (kA = 0),
<A> = 1 (R = sqrt(N / 4 pi)). Held fixed through the growth: P0 = 3.80 (in units of the initial
sqrt(<A>) = 1), kP = 1, kA = 0. So on the fixed sphere <A> = 4 pi R^2 / N falls and the
dimensionless p0 = P0 / sqrt(<A>) rises with N; on the growing sphere <A> = 1 and p0 = 3.80 stays.

Growth: every round, a fraction of the cells of each replica (chosen at random) divide through
their centre perpendicular to their long axis (Hertwig's rule), then FIRE + T1 relax the tissue
briefly. At each N in --measure the tissue is quenched (FIRE + T1 to force_tol or energy_tol;
Division and RadiusSchedule sit the quench out) and we count the replicas that reach zero energy
(energy per cell < 1e-12: floppy, the "compatible" side) and the mean shape index <P / sqrt(A)>.
Each row also gives what the rigidity sweep of random tilings (docs/results.md, default T1 rules)
predicts at that N and p0: P0*(N, <A>) = sqrt(<A>) p0*(N) and the zero-energy fraction
F = Phi((p0 - p0*(N)) / spread(N)).

    python examples/fig4_growth.py                  # small: N 32 -> 128, 6 replicas, a few minutes on a CPU
    python examples/fig4_growth.py --full           # paper size: N 32 -> 512, 24 replicas, one GPU
    python examples/fig4_growth.py --full --plot fig4_growth.png
"""
import argparse
import math
import time

import numpy as np

import spherevm as svm
from spherevm.analysis import rigidity
from spherevm.plugins.forces import VertexModel
from spherevm.plugins.integrators import FIRE
from spherevm.plugins.updaters import T1, Division, RadiusSchedule

# p0*(N) and the spread of the transition points, default T1 rules: docs/results.md (the paper-size
# sweep, 100 random tilings per N and p0, one H200, 2026-11-22).
SWEEP = {32: (3.7702, 0.0298), 48: (3.7943, 0.0240), 64: (3.8059, 0.0222), 96: (3.8215, 0.0174),
         128: (3.8263, 0.0149), 192: (3.8315, 0.0139), 256: (3.8346, 0.0113), 512: (3.8396, 0.0096),
         1024: (3.8434, 0.0082)}


def sweep_at(n):
    """(p0*, spread) at N cells, interpolated in log N between the sweep's sizes."""
    sizes = sorted(SWEEP)
    logn = np.log(sizes)
    return tuple(float(np.interp(math.log(n), logn, [SWEEP[s][k] for s in sizes])) for k in (0, 1))


def sweep_zero_fraction(n, p0):
    """The sweep's zero-energy fraction of random tilings of N cells at p0."""
    star, spread = sweep_at(n)
    return 0.5 * (1.0 + math.erf((p0 - star) / (spread * math.sqrt(2.0))))


def run(mode, args, log):
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
        """A fraction of each replica's cells, at random, never past the stage's target N."""
        if not growing["on"]:
            return []
        out = []
        for a, b in zip(s.state.cell_start[:-1], s.state.cell_start[1:]):
            k = min(max(1, int(args.grow_fraction * (b - a))), growing["target"] - (b - a))
            if k > 0:
                out.extend((a + gen.choice(b - a, size=k, replace=False)).tolist())
        return out

    division = Division(rule=rule, axis="hertwig")
    sim.operations.updaters.append(division)
    sim.operations.updaters.append(RadiusSchedule("fixed" if mode == "fixed" else "constant_area", area=1.0))
    sim.operations.integrator = FIRE(dt=0.05)
    rows = []
    t0 = time.perf_counter()

    def quench(n):
        def progress(step, done, total):
            if step % 5000 == 0 and step:
                log(f"    [{mode}] quench at N = {n}: {step} steps, {done}/{total} replicas done")

        res = sim.minimize(force_tol=1e-10, energy_tol=1e-16, max_steps=args.max_steps, progress=progress)
        status = rigidity.classify(res.energy_per_cell, res.reason)
        area = float(sim.state.mean_cell_area.mean())
        p0 = args.p0 / np.sqrt(area)
        rows.append(dict(mode=mode, N=n, R=float(sim.state.radius_np().mean()), A=area, p0=p0,
                         P0_star=float(rigidity.critical_perimeter(sweep_at(n)[0], area)),
                         sweep=sweep_zero_fraction(n, p0),
                         zero=float(np.mean(status == "zero")),
                         unconverged=int(np.sum(~np.isin(status, ("zero", "rigid")))),
                         q=float(np.mean(res.mean_shape_index)), steps=int(res.steps.max()),
                         divisions=int(division.total_divisions.sum()),
                         refused=int(division.refusals.sum()), seconds=time.perf_counter() - t0))
        print(_row(rows[-1]), flush=True)

    n = args.start
    quench(n)                          # the relaxed initial tissues
    for target in sorted(t for t in args.measure if t > args.start):
        growing["target"] = target
        rounds = idle = 0
        while n < target:
            sim.operations.integrator.reset()   # a quench stops converged replicas; Division acts on active ones
            before = sim.state.n_cells
            growing["on"] = True
            sim.run(1)                 # one division round (the Division pass runs first in the step)
            growing["on"] = False
            sim.run(args.relax)        # brief relaxation; positions keep moving, T1s happen
            n = int(sim.state.cells_per_replica.min())
            rounds += 1
            idle = idle + 1 if sim.state.n_cells == before else 0
            if idle == 20:
                raise RuntimeError(f"20 rounds without a division at N = {n}: every choice refused "
                                   f"({division.refused})")
        log(f"    [{mode}] grown to N = {n} in {rounds} rounds ({time.perf_counter() - t0:.0f} s)")
        quench(n)
        sim.state.validate(orientation=False)
    return rows


HEADER = (f"{'sphere':>13s} {'N':>5s} {'R':>7s} {'<A>':>7s} {'p0=P0/sqrt<A>':>13s} {'P0*(N,<A>)':>10s} "
          f"{'sweep F':>7s} {'zero-E frac':>11s} {'unconv':>6s} {'<q>':>7s} {'steps':>6s} {'divisions':>9s} "
          f"{'refused':>7s} {'time/s':>6s}")


def _row(r):
    return (f"{r['mode']:>13s} {r['N']:5d} {r['R']:7.3f} {r['A']:7.4f} {r['p0']:13.3f} {r['P0_star']:10.4f} "
            f"{r['sweep']:7.3f} {r['zero']:11.3f} {r['unconverged']:6d} {r['q']:7.4f} {r['steps']:6d} "
            f"{r['divisions']:9d} {r['refused']:7d} {r['seconds']:6.0f}")


def verdict(rows, mode):
    """One line: how the zero-energy fraction went from the first to the last N of ``mode``."""
    mine = [r for r in rows if r["mode"] == mode]
    if len(mine) < 2:
        return ""
    a, b = mine[0], mine[-1]
    trend = ("unjams (more floppy)" if b["zero"] > a["zero"] else
             "rigidifies (fewer floppy)" if b["zero"] < a["zero"] else "no change")
    return (f"# {mode}: zero-energy fraction {a['zero']:.2f} at N = {a['N']} -> {b['zero']:.2f} at N = {b['N']}: "
            f"{trend}; the sweep of random tilings says {a['sweep']:.2f} -> {b['sweep']:.2f}")


def plot(rows, path):
    """Left: the Fig. 4 plane (P0* curves of the sweep, the growth paths at P0 = const); right: the
    zero-energy fraction against N, measured and the sweep's."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, (left, right) = plt.subplots(1, 2, figsize=(11, 4.4))
    areas = np.geomspace(min(r["A"] for r in rows) * 0.8, 1.25, 101)
    sizes = np.array(sorted(SWEEP))
    rigidity.plot_critical_perimeter({"n_cells": sizes, "p0_star": np.array([SWEEP[s][0] for s in sizes])},
                                     areas, ax=left, dashed=1024)
    for mode, marker, color in (("fixed", "o", "C0"), ("constant_area", "s", "C3")):
        mine = [r for r in rows if r["mode"] == mode]
        if not mine:
            continue
        P0 = [r["p0"] * math.sqrt(r["A"]) for r in mine]
        left.scatter([r["A"] for r in mine], P0, c=[r["zero"] for r in mine], cmap="coolwarm_r", vmin=0, vmax=1,
                     marker=marker, edgecolors="k", zorder=3, label=f"{mode} (colour: zero-E fraction)")
        right.plot([r["N"] for r in mine], [r["zero"] for r in mine], marker + "-", color=color,
                   label=f"{mode}: measured")
        right.plot([r["N"] for r in mine], [r["sweep"] for r in mine], marker + "--", color=color, alpha=0.5,
                   label=f"{mode}: sweep of random tilings")
    left.set_xscale("log")
    left.legend(fontsize=7, frameon=False, loc="lower right")
    right.set_xscale("log", base=2)
    right.set_xlabel("N")
    right.set_ylabel("zero-energy fraction after FIRE + T1")
    right.set_ylim(-0.03, 1.03)
    right.legend(fontsize=8, frameon=False)
    fig.tight_layout()
    fig.savefig(path, dpi=150)
    plt.close(fig)


def main(argv=None):
    ap = argparse.ArgumentParser(allow_abbrev=False, description=__doc__.split("\n")[0])
    ap.add_argument("--full", action="store_true", help="paper size: N 32 -> 512, 24 replicas (one GPU)")
    ap.add_argument("--replicas", type=int, default=None)
    ap.add_argument("--start", type=int, default=32)
    ap.add_argument("--measure", type=int, nargs="+", default=None, help="N at which to quench")
    ap.add_argument("--p0", type=float, default=3.80, help="P0 in units of the initial sqrt(<A>) = 1")
    ap.add_argument("--grow-fraction", type=float, default=0.1, help="fraction of cells dividing per round")
    ap.add_argument("--relax", type=int, default=100, help="FIRE steps after each division round")
    ap.add_argument("--max-steps", type=int, default=20000, help="FIRE steps per quench")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--device", default="auto", help="cpu, gpu or auto (the GPU if there is one)")
    ap.add_argument("--modes", nargs="+", default=["fixed", "constant_area"])
    ap.add_argument("--plot", default=None, help="write the figure here (needs matplotlib)")
    ap.add_argument("--quiet", action="store_true", help="no progress lines")
    args = ap.parse_args(argv)
    if args.replicas is None:
        args.replicas = 24 if args.full else 6
    if args.measure is None:
        args.measure = [32, 64, 128, 256, 512] if args.full else [32, 64, 128]
    if not 0 < args.grow_fraction <= 1:
        ap.error("--grow-fraction must be in (0, 1]")

    def log(line):
        if not args.quiet:
            print(line, flush=True)

    t0 = time.perf_counter()
    log(f"# device {svm.device.resolve(args.device).name}, {args.replicas} replicas, N {args.start} -> "
        f"{max(args.measure)}, P0 = {args.p0}, {args.grow_fraction:g} of the cells divide per round")
    print(HEADER, flush=True)
    rows = []
    for mode in args.modes:
        rows += run(mode, args, log)
    print(f"# {time.perf_counter() - t0:.0f} s; P0 = {args.p0} fixed, kA = 0, kP = 1; zero-E: energy/cell < "
          f"{rigidity.ZERO_ENERGY_TOL:g} after FIRE + T1 (force_tol 1e-10, energy_tol 1e-16)")
    for mode in args.modes:
        print(verdict(rows, mode))
    if args.plot:
        plot(rows, args.plot)
        print(f"# figure: {args.plot}")
    return rows


if __name__ == "__main__":
    main()
