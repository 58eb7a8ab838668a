"""Fig. 4 of the paper: the critical perimeter P0*(N, <A>) = sqrt(<A>) p0*(N).

p0*(N) is the mean of the distribution of transition points from the rigidity sweep (Fig. 2,
examples/fig2_rigidity.py); the energy's dependence on the typical cell size then gives
P0* = sqrt(<A>) p0*(N). Cells dividing in a fixed domain move along one curve towards smaller
<A>; cells dividing in a growing domain (fixed <A>) move across curves to larger N.

    python examples/fig4_critical_perimeter.py             # small sweep, shared with fig2_rigidity.py
    python examples/fig4_critical_perimeter.py --paper     # the paper's sweep (same folder as fig2 --paper)

It runs (or resumes, or simply reads) the same sweep folder as examples/fig2_rigidity.py with the
same flags, then writes fig4_critical_perimeter.png and critical_perimeter.csv to --out and prints
P0* at a few <A>. As in the paper, --paper draws N = 32, 64, 128, 256 and N = 1024 dashed.
"""
import os
import sys

import numpy as np

from spherevm import sweeps
from spherevm.analysis import rigidity

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import fig2_rigidity  # noqa: E402  (same flags, same sweep folder)

PAPER_CURVES = [32, 64, 128, 256, 1024]
AREAS = np.linspace(0.5, 1.5, 101)


def main(argv=None):
    args = fig2_rigidity.parse_args(argv)
    sweep = fig2_rigidity.sweep_from_args(args)
    print(f"rigidity sweep in {args.out}: N = {list(sweep.cells)}, {len(sweep.p0)} p0 values, "
          f"{sweep.replicas} replicas (computing only what is not on disk yet)", flush=True)
    bar = sweeps.TextProgress(sys.stderr)
    try:
        result = sweeps.run_sweep(sweep, args.out, device=args.device, workers=args.workers, progress=bar)
    finally:
        bar.close()
    _, p0star, _ = result.summarize()
    keep = np.isin(p0star["n_cells"], PAPER_CURVES) if args.paper else np.ones(len(p0star["n_cells"]), bool)
    shown = {k: v[keep] for k, v in p0star.items()}

    table = {"mean_area": [], "n_cells": [], "p0_star": [], "P0_star": []}
    for n, p in zip(shown["n_cells"], shown["p0_star"]):
        for a in AREAS:
            table["mean_area"].append(float(a))
            table["n_cells"].append(int(n))
            table["p0_star"].append(float(p))
            table["P0_star"].append(float(rigidity.critical_perimeter(p, a)))
    sweeps.write_columns(os.path.join(args.out, "critical_perimeter.csv"), table)

    print("\nP0*(N, <A>) = sqrt(<A>) p0*(N)")
    picks = [0.5, 0.75, 1.0, 1.25, 1.5]
    print("     N     p0*  " + "".join(f"  <A>={a:<5g}" for a in picks))
    for n, p in zip(shown["n_cells"], shown["p0_star"]):
        print(f"{int(n):6d}  {p:.4f}  " + "".join(f"  {rigidity.critical_perimeter(p, a):9.4f}" for a in picks))
    try:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        print("matplotlib is not installed: no figure (pip install 'spherevm[plot]')")
        return shown
    fig = rigidity.plot_critical_perimeter(shown, AREAS, dashed=1024)
    fig.tight_layout()
    path = os.path.join(args.out, "fig4_critical_perimeter.png")
    fig.savefig(path, dpi=150)
    plt.close(fig)
    print(f"\nfigure: {path}\ntable:  {os.path.join(args.out, 'critical_perimeter.csv')}")
    return shown


if __name__ == "__main__":   # needed: the CPU process pool starts fresh interpreters (spawn)
    main()
