"""Where a torus unjams, against how many cells go round its tube: p0* of tori of one aspect ratio
and several tube circumferences, beside the periodic plane of the same N (docs/results.md,
"Curvature gradients: first measurements").

A torus of aspect ratio R/r whose tube is C cells round at <A> = 1 has N = C^2 R/r cells (area
4 pi^2 R r, tube circumference 2 pi r). For each C the torus and the plane of that N are quenched at
every p0 of the grid with examples/curvature_gradients.py's `quench` (the sweeps' settings: FIRE +
T1, kr = 0, per cell kA = 0, kP = 1, A0 = <A>, P0 = p0 sqrt(<A>)); F(p0) is the zero-energy fraction
and p0* the mean of the transition's distribution, `spherevm.analysis.rigidity.p0_star` (the
paper's estimator, its error from resampling each F).

    python examples/torus_tube.py --out tube/            # C = 5.1 .. 12, 16 tissues a point: ~25 min on one core
    python examples/torus_tube.py --tiny --out tube/     # seconds: the test's smoke run
"""
import argparse
import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from curvature_gradients import quench, transition, write_csv  # noqa: E402  (the sibling example)

from spherevm.analysis.rigidity import zero_fraction  # noqa: E402
from spherevm.sweeps import parse_p0_grid  # noqa: E402

MODES = {
    "default": dict(circumference=[5.1, 6.5, 8.0, 10.0, 12.0], p0="3.76:3.90:0.02", replicas=16, max_steps=20000),
    "tiny": dict(circumference=[5.1], p0="3.80:3.90:0.10", replicas=1, max_steps=3000),
}
FRACTION_COLUMNS = ("surface", "circumference", "n_cells", "p0", "n_replicas", "n_zero", "n_rigid", "n_unconverged",
                    "F", "F_err")
STAR_COLUMNS = ("surface", "circumference", "n_cells", "p0_star", "p0_star_err", "p0_half", "bracketed")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter,
                                 allow_abbrev=False)
    ap.add_argument("--tiny", action="store_true", help="seconds: one circumference, two p0, one tissue")
    ap.add_argument("--circumference", type=float, nargs="+", help="tube circumferences in cells (mode's: 5.1 .. 12)")
    ap.add_argument("--aspect", type=float, default=3.0, help="R/r of the tori (default 3)")
    ap.add_argument("--replicas", type=int, help="tissues per (surface, C, p0) (mode's: 16)")
    ap.add_argument("--out", default=".", help="folder for tube_fraction.csv and tube_p0star.csv")
    args = ap.parse_args(argv)
    mode = dict(MODES["tiny" if args.tiny else "default"])
    mode.update({k: v for k, v in (("circumference", args.circumference), ("replicas", args.replicas)) if v})
    p0s = parse_p0_grid([mode["p0"]])
    os.makedirs(args.out, exist_ok=True)
    fractions, stars = [], []
    for c in mode["circumference"]:
        n = int(round(c * c * args.aspect))
        for surface, spec in ((f"torus R/r={args.aspect:g}", f"torus:R={args.aspect:g},r=1"), ("plane", "plane")):
            t = time.time()
            _, p0, status = quench(spec, n, p0s, mode["replicas"], mode["max_steps"])
            f = zero_fraction(np.full(len(p0), n), p0, status)
            fractions += [dict(surface=surface, circumference=c, **{k: f[k][i] for k in f}) for i in range(len(f["p0"]))]
            converged = f["n_zero"] + f["n_rigid"]
            est = transition(f)
            if est is None:
                raise SystemExit(f"{surface}, C = {c}: fewer than two p0 values with a converged tissue; "
                                 "raise --replicas or the mode's max_steps")
            stars.append(dict(surface=surface, circumference=c, n_cells=n, p0_star=est.mean, p0_star_err=est.mean_err,
                              p0_half=est.p0_half, bracketed=est.bracketed))
            print(f"{surface:12s} C = {c:4.1f} N = {n:4d}: p0* = {est.mean:.4f} +- {est.mean_err:.4f} "
                  f"(F = 1/2 at {est.p0_half:.4f}); zero/converged per p0 "
                  + " ".join(f"{k}/{m}" for k, m in zip(f["n_zero"], converged)) + f" ({time.time() - t:.0f} s)",
                  flush=True)
    write_csv(os.path.join(args.out, "tube_fraction.csv"), fractions, FRACTION_COLUMNS)
    write_csv(os.path.join(args.out, "tube_p0star.csv"), stars, STAR_COLUMNS)


if __name__ == "__main__":
    main()
