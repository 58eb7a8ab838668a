"""Fig. 2 of the paper: the athermal rigidity transition of the spherical vertex model at kr = 0.

For every N and p0, random tilings (the paper's convex-hull protocol) are minimised with FIRE and
T1 exchanges; F(p0, N) is the fraction that reach zero energy, and its smoothed derivative is the
distribution of the transition point p0*, which shifts with N and tracks the perimeter of a
unit-area regular pentagon on the sphere.

    python examples/fig2_rigidity.py                   # small: N = 16..128, ~1.5 min on 2 cores
    python examples/fig2_rigidity.py --paper           # the paper's sizes, 100 replicas (use a GPU)
    python examples/fig2_rigidity.py --cells 32 64 128 --replicas 50 --p0 3.60:3.90:0.01

Results go to --out (default rigidity_sweep/): per-replica chunks as they finish (rerun the same
command to resume an interrupted sweep), then fraction.csv, p0star.csv, p0star_density.csv and
the figures fig2_rigidity.png (distributions, F in the inset), fraction.png and p0star_vs_N.png.
examples/fig4_critical_perimeter.py reads the same folder. See docs/rigidity.md.
"""
import argparse
import os
import sys
import time

from spherevm import sweeps

PAPER_CELLS = [32, 48, 64, 96, 128, 192, 256, 512, 1024]
PAPER_REPLICAS = 100
PAPER_P0 = "3.60:3.95:0.01"
SMALL_CELLS = [16, 32, 64, 128]
SMALL_REPLICAS = 12
SMALL_P0 = "3.55:3.95:0.025"


def parse_args(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--paper", action="store_true",
                   help=f"the paper's sweep: N = {PAPER_CELLS}, {PAPER_REPLICAS} replicas, p0 = {PAPER_P0}")
    p.add_argument("--cells", type=int, nargs="+", default=None, help=f"sizes (default: {SMALL_CELLS})")
    p.add_argument("--p0", nargs="+", default=None, help=f"p0 values or START:STOP:STEP (default: {SMALL_P0})")
    p.add_argument("--replicas", type=int, default=None, help=f"tilings per (N, p0) (default: {SMALL_REPLICAS})")
    p.add_argument("--kr", type=float, default=0.0)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--t1-reference", action="store_true",
                   help="T1 rules of the paper's own code (threshold 0.1, new edge twice the old one)")
    p.add_argument("--device", default="auto", choices=("cpu", "gpu", "auto"))
    p.add_argument("--workers", type=int, default=None, help="CPU processes (default: all cores)")
    p.add_argument("--out", default="rigidity_sweep", help="output folder (default: %(default)s)")
    return p.parse_args(argv)


def sweep_from_args(args) -> sweeps.RigiditySweep:
    cells = args.cells or (PAPER_CELLS if args.paper else SMALL_CELLS)
    replicas = args.replicas or (PAPER_REPLICAS if args.paper else SMALL_REPLICAS)
    p0 = sweeps.parse_p0_grid(args.p0 or [PAPER_P0 if args.paper else SMALL_P0])
    t1 = sweeps.RigiditySweep.reference_t1() if args.t1_reference else {}
    return sweeps.RigiditySweep(cells=cells, p0=p0, replicas=replicas, kr=args.kr, seed=args.seed, **t1)


def main(argv=None):
    args = parse_args(argv)
    sweep = sweep_from_args(args)
    print(f"rigidity sweep: N = {list(sweep.cells)}, {len(sweep.p0)} p0 values from {sweep.p0[0]} to "
          f"{sweep.p0[-1]}, {sweep.replicas} replicas each, kr = {sweep.kr}: {sweep.total_units} minimisations",
          flush=True)
    bar = sweeps.TextProgress(sys.stderr)
    t0 = time.perf_counter()
    try:
        result = sweeps.run_sweep(sweep, args.out, device=args.device, workers=args.workers, progress=bar)
    finally:
        bar.close()
    tables = sweeps.write_tables(args.out, result.records)
    frac = tables["fractions"]
    print(f"{len(result.computed)} chunk(s) computed and {result.reused} found on disk in "
          f"{time.perf_counter() - t0:.1f} s; not converged (left out of F): "
          f"{int(frac['n_max_steps'].sum())} max_steps, {int(frac['n_t1_oscillation'].sum())} t1_oscillation")
    print()
    print(sweeps.format_p0star_table(tables["p0star"]))
    if tables["plot_note"]:
        print(tables["plot_note"])
    else:
        # the paper's Fig. 2 (right panel) under its own name
        src = os.path.join(args.out, "p0star_distribution.png")
        dst = os.path.join(args.out, "fig2_rigidity.png")
        with open(src, "rb") as a, open(dst, "wb") as b:
            b.write(a.read())
        print(f"\nfigures: {dst}, {os.path.join(args.out, 'fraction.png')}, "
              f"{os.path.join(args.out, 'p0star_vs_N.png')}")
    print(f"tables:  {os.path.join(args.out, 'fraction.csv')}, {os.path.join(args.out, 'p0star.csv')}")
    return tables


if __name__ == "__main__":   # needed: the CPU process pool starts fresh interpreters (spawn)
    main()
