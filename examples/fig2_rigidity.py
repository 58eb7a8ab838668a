"""Fig. 2 of the paper: the athermal rigidity transition of the planar (left) and spherical
(right) vertex models at kr = 0.

For every N and p0, random tilings are minimised with FIRE and T1 exchanges: on the sphere the
paper's convex-hull tilings (radius sqrt(N / 4 pi)), on the periodic plane random Voronoi tilings
of the square box of side sqrt(N) (both <A> = 1). F(p0, N) is the fraction that reach zero energy,
and its smoothed derivative is the distribution of the transition point p0*: on the plane it
sharpens with N about a fixed mean, on the sphere it also shifts with N, tracking the perimeter of
a unit-area regular pentagon on the sphere (the pentagon markers of the right panel).

    python examples/fig2_rigidity.py                   # small: N = 16, 32, 64, 8 replicas, both surfaces, a few min on 2 cores
    python examples/fig2_rigidity.py --paper           # the paper's sizes, 100 replicas (use a GPU for the sphere)
    python examples/fig2_rigidity.py --surface sphere --cells 32 64 128 --replicas 50 --p0 3.60:3.90:0.01

Results go to --out (default rigidity_sweep/; the planar sweep to <out>_plane/ beside it): per-replica chunks
as they finish (rerun the same command to resume an interrupted sweep), then fraction.csv,
p0star.csv, p0star_density.csv, fraction.png and p0star_vs_N.png in each folder; with both
surfaces, fig2_rigidity.png (the paper's figure: plane left, sphere right, F in the insets) and
p0star_plane_sphere.csv (p0*(N) side by side) in --out. examples/fig4_critical_perimeter.py reads
the spherical folder. See docs/rigidity.md and docs/plane.md.
"""
import argparse
import os
import sys
import time

from spherevm import sweeps

PAPER_CELLS = [32, 48, 64, 96, 128, 192, 256, 512, 1024]
PAPER_REPLICAS = 100
PAPER_P0 = "3.60:3.95:0.01"
SMALL_CELLS = [16, 32, 64]
SMALL_REPLICAS = 8
SMALL_P0 = "3.60:3.95:0.025"
PLANE_SUFFIX = "_plane"


def parse_args(argv=None):
    p = argparse.ArgumentParser(allow_abbrev=False, description=__doc__.split("\n\n")[0],
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
    p.add_argument("--surface", default="both", choices=("both", "sphere", "plane"),
                   help="which panels to compute (default: %(default)s)")
    p.add_argument("--device", default="auto", choices=("cpu", "gpu", "auto"),
                   help="where the minimisations run, on both surfaces")
    p.add_argument("--workers", type=int, default=None, help="CPU processes (default: all cores)")
    p.add_argument("--out", default="rigidity_sweep", help="output folder (default: %(default)s)")
    return p.parse_args(argv)


def sweep_from_args(args, surface="sphere") -> sweeps.RigiditySweep:
    cells = args.cells or (PAPER_CELLS if args.paper else SMALL_CELLS)
    replicas = args.replicas or (PAPER_REPLICAS if args.paper else SMALL_REPLICAS)
    p0 = sweeps.parse_p0_grid(args.p0 or [PAPER_P0 if args.paper else SMALL_P0])
    t1 = sweeps.RigiditySweep.reference_t1() if args.t1_reference else {}
    return sweeps.RigiditySweep(cells=cells, p0=p0, replicas=replicas, kr=args.kr, seed=args.seed, surface=surface,
                                **t1)


def folder(args, surface):
    """The sphere's sweep in --out (where fig4_critical_perimeter.py looks), the plane's in <out>_plane."""
    return os.path.normpath(args.out) + PLANE_SUFFIX if surface == "plane" else args.out


def run_one(args, surface):
    """Run (or resume) the sweep of one surface and write its tables; returns them."""
    sweep = sweep_from_args(args, surface)
    out = folder(args, surface)
    print(f"rigidity sweep on the {surface}: N = {list(sweep.cells)}, {len(sweep.p0)} p0 values from {sweep.p0[0]} "
          f"to {sweep.p0[-1]}, {sweep.replicas} replicas each, kr = {sweep.kr}: {sweep.total_units} minimisations "
          f"-> {out}", flush=True)
    bar = sweeps.TextProgress(sys.stderr, label=f"rigidity ({surface})")
    t0 = time.perf_counter()
    try:
        result = sweeps.run_sweep(sweep, out, device=args.device,
                                  workers=args.workers, progress=bar)
    finally:
        bar.close()
    tables = sweeps.write_tables(out, result.records, surface=surface)
    frac = tables["fractions"]
    print(f"{len(result.computed)} chunk(s) computed and {result.reused} found on disk in "
          f"{time.perf_counter() - t0:.1f} s; not converged (left out of F): "
          f"{int(frac['n_max_steps'].sum())} max_steps, {int(frac['n_t1_oscillation'].sum())} t1_oscillation")
    print()
    print(sweeps.format_p0star_table(tables["p0star"]))
    print()
    return tables


def side_by_side(plane, sphere) -> dict:
    """p0*(N) of both surfaces in one table (NaN where a surface lacks that N)."""
    import numpy as np
    sizes = sorted(set(int(n) for t in (plane, sphere) if t for n in t["p0star"]["n_cells"]))
    cols = {"n_cells": sizes}
    for name, t in (("plane", plane), ("sphere", sphere)):
        for col in ("p0_star", "p0_star_err", "std", "pentagon_perimeter"):
            values = []
            for n in sizes:
                sel = np.asarray(t["p0star"]["n_cells"]) == n if t else np.zeros(0, bool)
                values.append(float(np.asarray(t["p0star"][col])[sel][0]) if t and sel.any() else float("nan"))
            cols[f"{name}_{col}"] = values
    return cols


def format_side_by_side(cols) -> str:
    head = ("N", "plane p0*", "+-", "spread", "sphere p0*", "+-", "spread", "pent(flat)", "pent(sphere)")
    keys = ("plane_p0_star", "plane_p0_star_err", "plane_std", "sphere_p0_star", "sphere_p0_star_err", "sphere_std",
            "plane_pentagon_perimeter", "sphere_pentagon_perimeter")
    rows = [[str(n)] + [f"{cols[k][i]:.4f}" for k in keys] for i, n in enumerate(cols["n_cells"])]
    widths = [max(len(h), *(len(r[j]) for r in rows)) for j, h in enumerate(head)]
    return "\n".join("  ".join(v.rjust(w) for v, w in zip(r, widths)) for r in [list(head)] + rows)


def draw_figure(plane, sphere, path):
    """The paper's Fig. 2: distributions of p0* on the plane (left) and the sphere (right), F(p0) in
    the insets, the same colour per N, pentagon markers on the spherical panel only."""
    import matplotlib
    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt
    from spherevm.analysis import rigidity
    fig, (left, right) = plt.subplots(1, 2, figsize=(12.8, 4.8), sharey=False)
    for ax, t, title, pent in ((left, plane, "periodic plane", False), (right, sphere, "sphere", True)):
        rigidity.plot_transition(t["fractions"], t["p0star"], t["density"], ax=ax, pentagons=pent)
        ax.set_title(title)
    lo = min(ax.get_xlim()[0] for ax in (left, right))
    hi = max(ax.get_xlim()[1] for ax in (left, right))
    for ax in (left, right):
        ax.set_xlim(lo, hi)
    fig.tight_layout()
    fig.savefig(path, dpi=150)
    plt.close(fig)


def main(argv=None):
    args = parse_args(argv)
    surfaces = ("plane", "sphere") if args.surface == "both" else (args.surface,)
    tables = {s: run_one(args, s) for s in surfaces}
    plane, sphere = tables.get("plane"), tables.get("sphere")
    cols = side_by_side(plane, sphere)
    os.makedirs(args.out, exist_ok=True)
    print("p0*(N), mean of the distribution of transition points (+-: error of the mean; spread: its std):")
    print(format_side_by_side(cols))
    sweeps.write_columns(os.path.join(args.out, "p0star_plane_sphere.csv"), cols)
    notes = [t["plot_note"] for t in tables.values() if t["plot_note"]]
    if notes:
        print(notes[0])
    elif plane and sphere:
        path = os.path.join(args.out, "fig2_rigidity.png")
        draw_figure(plane, sphere, path)
        print(f"\nfigure:  {path}")
    else:   # one surface: its distribution panel under the figure's name
        src = os.path.join(folder(args, surfaces[0]), "p0star_distribution.png")
        dst = os.path.join(args.out, "fig2_rigidity.png")
        with open(src, "rb") as a, open(dst, "wb") as b:
            b.write(a.read())
        print(f"\nfigure:  {dst}")
    print(f"tables:  {os.path.join(args.out, 'p0star_plane_sphere.csv')}, fraction.csv and p0star.csv in "
          + ", ".join(folder(args, s) for s in surfaces))
    return tables


if __name__ == "__main__":   # needed: the CPU process pool starts fresh interpreters (spawn)
    main()
