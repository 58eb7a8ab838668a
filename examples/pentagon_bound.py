"""The pentagon bound at any Gaussian curvature K, and the range of K that tori, Gaussian bumps and
spheres of N cells reach (docs/results.md, "Curvature gradients").

p_penta(K) is the perimeter of the regular pentagon of unit area on the surface of constant
curvature K (spherical K > 0, flat, hyperbolic K < 0): analysis.pentagon_perimeter_at_curvature.
With <A> the mean cell area, a cell where the local curvature is K sees K <A>. The surfaces, at
<A> = 1:

* torus of aspect ratio R/r and area 4 pi^2 R r = N: K from -1/(r (R - r)) to 1/(r (R + r));
* Gaussian bump z = h exp(-rho^2 / 2 w^2) on the periodic square of side L = sqrt(N) (area just
  above N, <A> = area / N), w = L / 6.5 (the widest that fits, L > 6 w): K from the flank's
  minimum to h^2 / w^4 on top;
* sphere of N cells: K = 4 pi / N.

    python examples/pentagon_bound.py --out pentagon_bound/     # figure + CSV, about a second
"""
import argparse
import csv
import pathlib

import numpy as np
from scipy import integrate

from spherevm.analysis import (gaussian_curvature, pentagon_perimeter_at_curvature, polygon_perimeter_at_curvature,
                               torus_curvature_range)
from spherevm.constraints import GaussianBump

ASPECTS = (2.0, 3.0, 5.0)
SLOPES = (0.5, 1.0, 2.0)           # bump height over width


def bump_range(n_cells, slope):
    """(w, K_min <A>, K_max <A>) of the Gaussian bump of height slope * w on the square of N cells."""
    box = np.sqrt(n_cells)
    width = box / 6.5
    bump = GaussianBump(height=slope * width, width=width, box=box)

    def ring(rho):              # extra area of the bump over its flat disc, per unit rho
        e = np.exp(-rho ** 2 / (2 * width ** 2))
        return (np.sqrt(1 + (slope * rho / width * e) ** 2) - 1) * 2 * np.pi * rho
    mean_area = (box ** 2 + integrate.quad(ring, 0, box / 2)[0]) / n_cells
    rho = np.linspace(0.0, box / 2, 20001)
    k = gaussian_curvature(bump, np.stack([rho, 0 * rho, 0 * rho], axis=1))
    return width, k.min() * mean_area, k.max() * mean_area


def ranges(sizes):
    """Rows (surface, N, length, K_min <A>, K_max <A>) for the tori, bumps and spheres of each N;
    ``length`` is the tube radius r, the bump's width w or the sphere's radius R."""
    rows = []
    for n in sizes:
        rows += [(f"torus R/r = {a:g}", n, np.sqrt(n / (4 * np.pi ** 2 * a)), *map(float, torus_curvature_range(a, n)))
                 for a in ASPECTS]
        rows += [(f"bump h/w = {s:g}", n, *bump_range(n, s)) for s in SLOPES]
        rows.append(("sphere", n, np.sqrt(n / (4 * np.pi)), 4 * np.pi / n, 4 * np.pi / n))
    return rows


def plot(rows, path):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig = plt.figure(figsize=(11, 5.2))
    full = fig.add_subplot(1, 2, 1)
    k = np.linspace(-1, 1, 801)
    full.plot(k, pentagon_perimeter_at_curvature(k), color="C3", lw=2, label="regular pentagon")
    full.plot(k, polygon_perimeter_at_curvature(6, k), color="C0", lw=1.5, ls="--", label="regular hexagon")
    full.axvline(0, color="0.6", lw=0.8)
    full.axhline(pentagon_perimeter_at_curvature(0.0), color="C3", lw=0.6, ls=":")
    full.set_xlabel(r"$K \langle A \rangle$")
    full.set_ylabel(r"perimeter of the unit-area regular polygon, $p(K)$")
    full.set_title(r"(a) $K<0$: hyperbolic, $K>0$: spherical", fontsize=10)

    spheres = np.array([4 * np.pi / n for n in sorted({r[1] for r in rows})])
    full.plot(spheres, pentagon_perimeter_at_curvature(spheres), "o", color="k", ms=4,
              label="spheres, N = " + ", ".join(str(n) for n in sorted({r[1] for r in rows})))
    full.legend(frameon=False)

    bars = fig.add_subplot(1, 2, 2)
    order = sorted(rows, key=lambda r: ([r[0] for r in rows].index(r[0]), r[1]))
    kinds = list(dict.fromkeys(r[0] for r in rows))
    for i, (name, n, _, k0, k1) in enumerate(order):
        color = f"C{kinds.index(name) % 10}"
        if k0 == k1:
            bars.plot([k0], [i], "o", color=color, ms=5)
        else:
            bars.plot([k0, k1], [i, i], color=color, lw=5, solid_capstyle="butt")
        p0, p1 = pentagon_perimeter_at_curvature(k0), pentagon_perimeter_at_curvature(k1)
        bars.text(k1 + 0.015, i, f"{p0:.3f}" if k0 == k1 else f"{p0:.3f} to {p1:.3f}", va="center", fontsize=7)
    bars.set_yticks(range(len(order)), [f"{name}, N = {n}" for name, n, *_ in order], fontsize=7)
    bars.invert_yaxis()
    bars.axvline(0, color="0.6", lw=0.8)
    bars.set_xlim(min(r[3] for r in rows) - 0.05, max(r[4] for r in rows) + 0.3)
    bars.set_xlabel(r"$K \langle A \rangle$")
    bars.set_title(r"(b) $K$ the surfaces reach ($\langle A\rangle = 1$); text: $p_\mathrm{penta}$ at its ends",
                   fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=130)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0], allow_abbrev=False)
    parser.add_argument("--out", type=pathlib.Path, default=pathlib.Path("pentagon_bound"),
                        help="folder for pentagon_bound.png and pentagon_bound.csv")
    parser.add_argument("--cells", type=int, nargs="+", default=[256, 1024], help="tissue sizes N")
    args = parser.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    rows = ranges(args.cells)
    head = ("surface", "N", "r, w or R", "K_min <A>", "K_max <A>", "p_penta(K_min)", "p_penta(K_max)")
    with open(args.out / "pentagon_bound.csv", "w", newline="") as f:
        out = csv.writer(f)
        out.writerow(head)
        for name, n, length, k0, k1 in rows:
            out.writerow((name, n, f"{length:.4f}", f"{k0:.5f}", f"{k1:.5f}",
                          f"{pentagon_perimeter_at_curvature(k0):.5f}",
                          f"{pentagon_perimeter_at_curvature(k1):.5f}"))
    print("| " + " | ".join(head) + " |\n|" + " --- |" * len(head))
    for name, n, length, k0, k1 in rows:
        print(f"| {name} | {n} | {length:.2f} | {k0:+.4f} | {k1:+.4f} | {pentagon_perimeter_at_curvature(k0):.4f} | "
              f"{pentagon_perimeter_at_curvature(k1):.4f} |")
    plot(rows, args.out / "pentagon_bound.png")


if __name__ == "__main__":
    main()
