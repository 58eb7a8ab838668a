"""A rigidity sweep on several surfaces, one GPU, in one process: wall time, time waiting for the
host's tilings and minimising, per size (docs/surfaces.md, "A whole rigidity sweep").

    python benchmarks/surface_sweep.py sphere torus:R=3,r=1 sphere torus:R=3,r=1

Each argument is a surface spec (as ``spherevm rigidity --surface``), run in turn with
``run_sweep(..., timeline=True)`` into a fresh folder under ``--out``; give the same surfaces
several times to alternate them. The first sweep of a process also compiles the kernels its
surface needs: compare the later ones. ``--cells``, ``--p0`` and ``--replicas`` default to the
paper's sweep (32,400 minimisations).
"""
import argparse
import os
import shutil
import sys
import time

import numpy as np

from spherevm.sweeps import RigiditySweep, parse_p0_grid, run_sweep

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from sweep_timeline import PAPER_CELLS, summarize  # noqa: E402


def one_sweep(surface, args):
    """Run the sweep on ``surface`` and print its figures."""
    sweep = RigiditySweep(cells=args.cells, p0=parse_p0_grid([args.p0]), replicas=args.replicas, kr=0.0,
                          surface=surface)
    out = os.path.join(args.out, surface.split(":")[0])
    shutil.rmtree(out, ignore_errors=True)
    t = time.perf_counter()
    result = run_sweep(sweep, out, device=args.device, timeline=True)
    wall = time.perf_counter() - t
    figures = summarize(result, 0.0)
    per_size = {}
    for r in result.timeline:
        minimised, waited = per_size.setdefault(r["n_cells"], [0.0, 0.0])
        per_size[r["n_cells"]] = [minimised + r["minimized"] - r["built"], waited + r["submitted"] - r["asked"]]
    n, steps = np.asarray(result.records["n_cells"]), np.asarray(result.records["steps"])
    print(f"{surface}: wall {wall:.1f} s; minimised {sum(m for m, _ in per_size.values()):.1f} s, waited for "
          f"tilings {figures['waiting_for_tilings']:.1f} s; {int((steps * n).sum()):,} cell-iterations, "
          f"{int((steps >= sweep.max_steps).sum())} at max_steps", flush=True)
    print("   per N (minimised, waited s): " + "; ".join(f"{k}: {m:.1f}, {w:.1f}" for k, (m, w) in
                                                       sorted(per_size.items())), flush=True)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter,
                                 allow_abbrev=False)
    ap.add_argument("surfaces", nargs="+", help="surface specs, in the order to run them")
    ap.add_argument("--cells", type=int, nargs="+", default=list(PAPER_CELLS))
    ap.add_argument("--p0", default="3.60:3.95:0.01")
    ap.add_argument("--replicas", type=int, default=100)
    ap.add_argument("--device", default="gpu")
    ap.add_argument("--out", default="surface_sweep")
    args = ap.parse_args(argv)
    for surface in args.surfaces:
        one_sweep(surface, args)


if __name__ == "__main__":
    main()
