"""How often Brownian dynamics with T1 exchanges leave tissues that are not simple (docs/validation.md).

    python benchmarks/crossings.py                                   # the table of docs/validation.md
    python benchmarks/crossings.py --cells 64 --T 0.05 --p0 3.8 --kr 1 --surface plane
    python benchmarks/crossings.py --cost                            # ms per check, N = 1,000 and 65,536

For each case: random tilings relaxed with FIRE + T1 (at most ``--relax`` iterations, as the paper's
protocol does), then ``--steps`` Brownian steps (``--dt``, default 0.05 as examples/fig3_relaxation.py)
with the default T1 rule, checked every ``--every`` steps with :func:`spherevm.simplicity.counts`. Printed per
case: checks, cells that crossed themselves (summed over the checks), checks with at least one, the
largest number in one check, inverted cells (signed area <= 0), open cells, replicas whose areas
do not add up to the surface's, the flips, and (``--untangle``) the crossings the untangling pass
found before the checks; a run stopped by Brownian's exploding-step guard says where.
"""
import argparse
import datetime
import os
import platform
import time

import numpy as np

import spherevm as svm
from spherevm import simplicity
from spherevm.plugins.forces import VertexModel
from spherevm.plugins.integrators import FIRE, Brownian
from spherevm.plugins.updaters import T1

# (label, p0, kr, T): Fig. 3's main panel (kr = 0, p0 = 3.775, T = 0.004 ... 0.02), its inset
# (T = 5e-4, p0 = 3.75, kr = 1) and hot runs
CASES = [("fig3", 3.775, 0.0, 0.004), ("fig3", 3.775, 0.0, 0.01), ("fig3", 3.775, 0.0, 0.02),
         ("inset", 3.75, 1.0, 5e-4), ("hot", 3.775, 0.0, 0.05), ("hot", 3.8, 1.0, 0.05)]


def measure(surface, n_cells, replicas, p0, kr, T, steps, every, relax, seed=0, untangle=False, dt=0.05, revert=False):
    """Counts of :func:`spherevm.simplicity.counts` summed over the checks, the checks with any
    crossing, the largest count in one check and the flips. ``untangle``: T1(untangle=True), and
    its :meth:`~spherevm.plugins.updaters.T1.untangle_pass` before each check (as if run after
    every step: its updater pass would make the same flips at the next step); ``crossed_before``
    counts the crossings the pass found. ``revert``: the pass also refuses the steps of replicas
    its flips leave not simple (else its flips alone)."""
    tiling = svm.init.random_planar_tiling if surface == "plane" else svm.init.random_tiling
    sim = svm.Simulation(device="cpu", seed=seed)
    sim.state = tiling(n_cells, replicas=replicas, seed=seed)
    sim.operations.forces.append(VertexModel.dimensionless(kr=kr, p0=p0))
    t1 = T1(untangle=untangle)
    sim.operations.updaters.append(t1)
    if relax:
        sim.operations.integrator = FIRE(dt=0.02)
        sim.minimize(force_tol=1e-8, max_steps=relax)
    sim.operations.integrator = Brownian(dt=dt, T=T)
    out = dict(checks=0, crossed=0, checks_crossed=0, worst=0, inverted=0, open=0, uncovered=0, crossed_before=0)
    out["exploded"] = ""
    for _ in range(steps // every):
        try:
            sim.run(every)
        except FloatingPointError:            # hot runs at dt = 0.05 may exceed Brownian's max_step
            out["exploded"] = f"at {sim.timestep}"
            break
        if untangle:
            out["crossed_before"] += int(simplicity.counts(sim.state)["crossed"].sum())
            t1.untangle_pass(sim, revert=revert)
        c = simplicity.counts(sim.state)
        out["checks"] += 1
        for k in ("crossed", "inverted", "open", "uncovered"):
            out[k] += int(c[k].sum())
        out["checks_crossed"] += int(c["crossed"].sum() > 0)
        out["worst"] = max(out["worst"], int(c["crossed"].sum()))
    out["flips"] = int(sim.log("t1_total_flips").sum())
    return out


def cost(sizes=(1000, 65536), repeats=5):
    """Median milliseconds of :func:`spherevm.simplicity.check` (everything a check does),
    :func:`~spherevm.simplicity.self_crossings` alone, :func:`spherevm.folding.inverted_edges` (the
    untangling's test) and one force evaluation, on one random tiling per surface and size."""
    from spherevm import folding
    print(f"{'surface':<7} {'N':>6} {'check':>8} {'crossings':>9} {'inverted':>8} {'force':>8}   (ms, median of {repeats})")
    for surface in ("sphere", "plane"):
        for n in sizes:
            tiling = svm.init.random_planar_tiling if surface == "plane" else svm.init.random_tiling
            sim = svm.Simulation(device="cpu")
            sim.state = tiling(n, seed=1)
            sim.operations.forces.append(VertexModel.dimensionless(kr=1.0, p0=3.8))

            def force():
                sim.state_changed()
                sim.compute_forces()
            row = []
            for fn in (lambda: simplicity.check(sim.state), lambda: simplicity.self_crossings(sim.state),
                       lambda: folding.inverted_edges(sim.state), force):
                fn()
                times = []
                for _ in range(repeats):
                    t0 = time.perf_counter()
                    fn()
                    times.append(time.perf_counter() - t0)
                row.append(1e3 * float(np.median(times)))
            print(f"{surface:<7} {n:>6} " + " ".join(f"{t:>8.1f}" for t in row[:2]) + f" {row[2]:>8.1f} {row[3]:>8.1f}",
                  flush=True)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0], allow_abbrev=False)
    ap.add_argument("--surface", nargs="+", default=["sphere", "plane"], choices=["sphere", "plane"])
    ap.add_argument("--cells", type=int, nargs="+", default=[64, 256])
    ap.add_argument("--replicas", type=int, default=4)
    ap.add_argument("--steps", type=int, default=2000)
    ap.add_argument("--every", type=int, default=20)
    ap.add_argument("--relax", type=int, default=2000)
    ap.add_argument("--p0", type=float, help="one case of this p0 (with --kr and --T) instead of the table")
    ap.add_argument("--kr", type=float, default=0.0)
    ap.add_argument("--T", type=float, default=0.05)
    ap.add_argument("--dt", type=float, default=0.05, help="Brownian time step (hot runs explode at 0.05)")
    ap.add_argument("--untangle", action="store_true", help="T1(untangle=True), untangled before each check")
    ap.add_argument("--revert", action="store_true", help="with --untangle: untangle_pass refuses the steps of "
                    "replicas it leaves not simple (else flips alone)")
    ap.add_argument("--cost", action="store_true", help="time the checks instead (N = 1,000 and 65,536)")
    args = ap.parse_args(argv)
    if args.cost:
        return cost()
    cases = CASES if args.p0 is None else [("given", args.p0, args.kr, args.T)]
    print(f"# {datetime.date.today()} {platform.machine()} {os.cpu_count()} cores, NumPy, {args.replicas} replicas, "
          f"{args.steps} steps, dt {args.dt}, checked every {args.every}, relaxed <= {args.relax} FIRE iterations, "
          f"untangle={args.untangle}")
    print(f"{'surface':<7} {'N':>4} {'case':<6} {'p0':>6} {'kr':>3} {'T':>7} {'checks':>6} {'crossed':>7} "
          f"{'w/ any':>6} {'worst':>5} {'invert':>6} {'open':>4} {'cover':>5} {'flips':>6} {'before':>6} {'s':>5}")
    for surface in args.surface:
        for n in args.cells:
            for label, p0, kr, T in cases:
                t0 = time.time()
                r = measure(surface, n, args.replicas, p0, kr, T, args.steps, args.every, args.relax,
                            untangle=args.untangle, dt=args.dt, revert=args.revert)
                print(f"{surface:<7} {n:>4} {label:<6} {p0:>6} {kr:>3g} {T:>7g} {r['checks']:>6} {r['crossed']:>7} "
                      f"{r['checks_crossed']:>6} {r['worst']:>5} {r['inverted']:>6} {r['open']:>4} "
                      f"{r['uncovered']:>5} {r['flips']:>6} {r['crossed_before']:>6} {time.time() - t0:>5.0f} {r['exploded']}",
                      flush=True)


if __name__ == "__main__":
    np.seterr(all="ignore")
    main()
