"""Cells against the local Gaussian curvature K: quenched shapes, the zero-energy fraction and p0* on
tori, Gaussian bumps, an ellipsoid, the sphere and the plane; mobility and neighbour exchanges on a
torus and a bump at finite T (docs/results.md, "Curvature gradients").

(a) Zero temperature: FIRE + T1 quenches of random tilings (<A> = 1) at several p0, with the sweeps'
settings (kr = 0 unless --kr; per cell kA = kr / <A>, kP = 1, A0 = <A>, P0 = p0 sqrt(<A>); FIRE dt 0.02; T1 as
RigiditySweep's defaults). Per cell: shape index q = P / sqrt(A), area and side number, binned against
K <A> at the cell's centroid (errors over tissues: each replica's bin mean is one sample), beside the
local pentagon bound p_penta(K <A>); per surface the zero-energy fraction F(p0) (binomial errors) and,
with two p0 or more, p0* (the paper's estimator, analysis.rigidity.p0_star).
(b) Finite temperature: Brownian dynamics + T1 at p0 = 3.775, kr = 0 on a torus (R/r = 3) and a bump
(h/w = 2): per cell the mean-square displacement of its centroid over a fixed lag (embedding-space
chord, across a periodic box by minimum images), its self-overlap over that lag (the fraction of time
origins after which it moved at most b = 0.5 sqrt(<A>), the paper's window) and its neighbour losses
(a cell loses a neighbour in each T1 it takes part in along the lost edge; counted between snapshots,
so flips undone within one interval are missed), all against K <A>.

Every surface runs on either device (``--device``, default the GPU where CuPy sees one):

    python examples/curvature_gradients.py --out curv/           # small default, minutes on a CPU
    python examples/curvature_gradients.py --full --device gpu --out curv/   # N = 256 and 1024: ~9 min on an H200
    python examples/curvature_gradients.py --tiny --out curv/    # seconds: the test's smoke run
"""
import argparse
import csv
import os
import time

import numpy as np

import spherevm as svm
from spherevm.analysis import binned_mean, cell_curvature, pentagon_perimeter_at_curvature
from spherevm.analysis.rigidity import classify, p0_star, zero_fraction
from spherevm.shapes import shape_index_of
from spherevm.plugins.forces import VertexModel
from spherevm.plugins.forces.bending import neighbor_pairs
from spherevm.plugins.integrators import FIRE, Brownian
from spherevm.plugins.updaters import T1

SURFACES = {"plane": "plane", "sphere": "sphere", "torus R/r=2": "torus:R=2,r=1", "torus R/r=3": "torus:R=3,r=1",
            "torus R/r=5": "torus:R=5,r=1", "bump h/w=1": "bump:h=1,w=1,box=6.5", "bump h/w=2": "bump:h=2,w=1,box=6.5",
            "ellipsoid 1:1.5:2": "ellipsoid:a=1,b=1.5,c=2"}
MODES = {   # cells, p0 values, replicas per p0, FIRE max steps, K bins, dynamics (cells, replicas, steps, lag)
    "tiny": dict(cells=[64], p0=[3.8], replicas=1, max_steps=200, bins=3, surfaces=["plane", "torus R/r=3"],
                 dyn=(64, 1, 60, 20)),
    "default": dict(cells=[128], p0=[3.70, 3.80, 3.90], replicas=4, max_steps=20000, bins=4,
                    surfaces=list(SURFACES), dyn=(128, 4, 3000, 500)),
    "full": dict(cells=[256, 1024], p0=list(np.round(np.arange(3.70, 3.901, 0.02), 2)), replicas=16,
                 max_steps=20000, bins=8, surfaces=list(SURFACES), dyn=(256, 16, 40000, 4000)),
}
DYN_SURFACES = {"tiny": ["torus R/r=3"], "default": ["torus R/r=3", "bump h/w=2"], "full": ["torus R/r=3", "bump h/w=2"]}
DYN_P0, DYN_T, DYN_DT, SNAPSHOT, PRE_QUENCH, OVERLAP_WINDOW = 3.775, 0.02, 0.05, 10, 1000, 0.5
CELL_COLUMNS = ("surface", "n_cells", "p0", "replica", "status", "K_A", "p_penta", "q", "perimeter", "area", "sides")
QUANTITIES = ("q", "perimeter", "area", "sides")   # perimeter and area in units of sqrt(<A>) and <A>
STAR_COLUMNS = ("surface", "n_cells", "p0_star", "p0_star_err", "p0_half", "bracketed")
BIN_COLUMNS = ("surface", "n_cells", "p0", "quantity", "bin", "K_low", "K_high", "K_A", "mean", "sem", "n_tissues",
               "n_cells_in_bin", "p_penta")


def quench(spec, n, p0s, replicas, max_steps, kr=0.0, seed=0, device="cpu"):
    """FIRE + T1 quenches of ``replicas`` tilings per p0 on ``device``; per-cell rows (q NaN where a
    cell's flat area is not positive: inverted) and per-replica statuses."""
    keys = [(seed + n, r) for r in range(replicas * len(p0s))]
    state = svm.init.tilings_on(spec, n, keys)
    p0 = np.repeat(p0s, replicas)
    rep = state.cell_replica_np()
    area = state.mean_cell_area[rep]
    sim = svm.Simulation(device=device, seed=seed)
    sim.state = state
    sim.operations.forces.append(VertexModel(kA=kr / area, kP=1.0, A0=area, P0=p0[rep] * np.sqrt(area)))
    sim.operations.updaters.append(T1())
    sim.operations.integrator = FIRE(dt=0.02)
    res = sim.minimize(force_tol=1e-12, energy_tol=1e-16, max_steps=max_steps, check_every=10)
    status = classify(res.energy_per_cell, res.reason)
    final = sim.state.to("cpu")
    geo = final.constraint.cell_geometry(final)
    a, per = np.asarray(geo.area), np.asarray(geo.perimeter)
    k = cell_curvature(final)
    cells = dict(p0=p0[rep], replica=rep, status=status[rep], K_A=k, p_penta=pentagon_perimeter_at_curvature(k),
                 q=shape_index_of(a, per), perimeter=per / np.sqrt(area), area=a / area, sides=final.cell_sides.astype(np.float64))
    return cells, p0, status


def transition(f):
    """p0* of one surface and N (:func:`spherevm.analysis.rigidity.p0_star`, the paper's estimator,
    its error from resampling each F) from :func:`~spherevm.analysis.rigidity.zero_fraction`'s
    ``f``, over the p0 with a converged tissue; None where fewer than two p0 have one."""
    converged = f["n_zero"] + f["n_rigid"]
    ok = converged > 0
    return p0_star(f["p0"][ok], f["F"][ok], n=converged[ok]) if ok.sum() >= 2 else None


def neighbour_pairs(state):
    """Sorted cell pairs sharing an edge (:func:`spherevm.plugins.forces.bending.neighbor_pairs`), as
    int64 keys ``a * n + b`` (NumPy, from a State on either device)."""
    pairs = state.device.to_numpy(neighbor_pairs(state))
    return pairs[:, 0].astype(np.int64) * state.n_cells + pairs[:, 1]


def dynamics(spec, n, replicas, steps, lag, seed=1, device="cpu"):
    """Brownian + T1 at p0 = 3.775, kr = 0 on ``device``: per-cell centroid MSD and self-overlap
    (displacement at most OVERLAP_WINDOW sqrt(<A>)) at ``lag`` steps, means over time origins
    (snapshots every SNAPSHOT steps), and neighbour losses per unit time, with K <A>, after a FIRE
    quench of at most PRE_QUENCH steps."""
    state = svm.init.tilings_on(spec, n, [(seed + n, r) for r in range(replicas)])
    rep = state.cell_replica_np()
    area = state.mean_cell_area[rep]
    sim = svm.Simulation(device=device, seed=seed)
    sim.state = state
    sim.operations.forces.append(VertexModel(kA=0.0 * area, kP=1.0, A0=area, P0=DYN_P0 * np.sqrt(area)))
    sim.operations.updaters.append(T1())
    sim.operations.integrator = FIRE(dt=0.02)            # relax the random tiling's large forces first
    sim.minimize(force_tol=1e-6, max_steps=PRE_QUENCH, check_every=10)
    sim.operations.integrator = Brownian(dt=DYN_DT, T=DYN_T)
    centres, losses, pairs = [], np.zeros(state.n_cells), neighbour_pairs(sim.state)
    for _ in range(steps // SNAPSHOT + 1):
        centres.append(sim.state.device.to_numpy(sim.state.constraint.cell_centroids(sim.state, "vertex")))
        sim.run(SNAPSHOT)
        now = neighbour_pairs(sim.state)
        lost = np.setdiff1d(pairs, now, assume_unique=True)
        np.add.at(losses, np.concatenate([lost // state.n_cells, lost % state.n_cells]), 1)
        pairs = now
    c = state.constraint.unwrap_path(np.stack(centres), state.size_np()[rep])   # across a periodic box
    m = lag // SNAPSHOT
    d2 = ((c[m:] - c[:-m]) ** 2).sum(axis=-1)                       # (origins, cells)
    return dict(replica=rep, K_A=cell_curvature(sim.state.to("cpu")), msd=d2.mean(axis=0),
                overlap=(d2 <= OVERLAP_WINDOW ** 2 * area).mean(axis=0),
                t1_rate=losses / (len(centres) * SNAPSHOT * DYN_DT))


def binned_rows(name, n, p0, cells, quantity, bins, edges=None):
    """Rows of BIN_COLUMNS: ``quantity`` binned against K <A> (groups: replicas)."""
    b = binned_mean(cells["K_A"], cells[quantity], bins=bins if edges is None else edges, groups=cells["replica"])
    counts = np.histogram(cells["K_A"], bins=b.edges)[0] if b.edges[0] < b.edges[-1] else [len(cells["K_A"])]
    return [dict(surface=name, n_cells=n, p0=p0, quantity=quantity, bin=i, K_low=b.edges[i], K_high=b.edges[i + 1],
                 K_A=b.x[i], mean=b.mean[i], sem=b.sem[i], n_tissues=int(b.count[i]), n_cells_in_bin=int(counts[i]),
                 p_penta=float(pentagon_perimeter_at_curvature(b.x[i])) if np.isfinite(b.x[i]) else np.nan)
            for i in range(len(b.x))]


def write_csv(path, rows, columns):
    with open(path, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=columns, extrasaction="ignore")
        w.writeheader()
        for row in rows:
            w.writerow({k: (f"{v:.6g}" if isinstance(v, (float, np.floating)) else v) for k, v in row.items()})


def plot(bins, fractions, dyn_bins, path):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, axes = plt.subplots(2, 4, figsize=(20, 8.8))
    p0s = sorted({r["p0"] for r in bins})
    mid = p0s[len(p0s) // 2]

    def curve(ax, rows, **options):
        ax.errorbar([r["K_A"] for r in rows], [r["mean"] for r in rows], [r["sem"] for r in rows], marker="o",
                    capsize=2, **options)
    labels = {"q": "cell shape index q = P / sqrt(A)", "perimeter": "P / sqrt(<A>)", "sides": "side number",
              "area": "A / <A>"}
    for ax, quantity in zip(axes[0], labels):
        for name in dict.fromkeys(r["surface"] for r in bins):
            curve(ax, [r for r in bins if r["surface"] == name and r["quantity"] == quantity and r["p0"] == mid],
                  label=name)
        if quantity in ("q", "perimeter"):
            k = np.linspace(*ax.get_xlim(), 100)
            ax.plot(k, pentagon_perimeter_at_curvature(k), "k--", label="p_penta(K <A>)")
        ax.set(xlabel="K <A> at the cell", ylabel=labels[quantity], title=f"quenched, p0 = {mid:g}")
        ax.legend(fontsize=7)
    ax = axes[1, 0]
    for name in dict.fromkeys(r["surface"] for r in fractions):
        rows = [r for r in fractions if r["surface"] == name]
        ax.errorbar([r["p0"] for r in rows], [r["F"] for r in rows], [r["F_err"] for r in rows], marker="o",
                    capsize=2, label=name)
    ax.set(xlabel="p0", ylabel="zero-energy fraction F", title="F(p0)")
    ax.legend(fontsize=7)
    for ax, quantity, label in ((axes[1, 1], "msd", "centroid MSD at fixed lag"),
                                (axes[1, 2], "overlap", f"self-overlap at fixed lag (b = {OVERLAP_WINDOW})"),
                                (axes[1, 3], "t1_rate", "neighbour losses per cell per unit time")):
        if dyn_bins:
            for name in dict.fromkeys(r["surface"] for r in dyn_bins):
                curve(ax, [r for r in dyn_bins if r["quantity"] == quantity and r["surface"] == name], label=name)
            ax.set(xlabel="K <A> at the cell", ylabel=label, title=f"p0 = {DYN_P0}, T = {DYN_T}")
            ax.legend(fontsize=7)
        else:
            ax.axis("off")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter,
                                 allow_abbrev=False)
    group = ap.add_mutually_exclusive_group()
    group.add_argument("--full", action="store_true", help="N = 256 and 1024, 11 p0 values, 16 replicas "
                       "(one GPU: about 9 minutes on an H200; hours on a CPU)")
    group.add_argument("--tiny", action="store_true", help="seconds: one p0, a plane and a torus (smoke test)")
    ap.add_argument("--cells", type=int, nargs="+", help="these N instead of the mode's")
    ap.add_argument("--replicas", type=int, help="tissues per (surface, N, p0) instead of the mode's")
    ap.add_argument("--surfaces", nargs="+", choices=list(SURFACES), metavar="NAME",
                    help=f"these surfaces instead of the mode's (of {', '.join(SURFACES)}); the dynamics run on "
                         "those of them the mode runs dynamics on")
    ap.add_argument("--kr", type=float, default=0.0, help="area stiffness of the quenches (RigiditySweep's default 0)")
    ap.add_argument("--no-dynamics", action="store_true", help="leave out part (b), the Brownian runs")
    ap.add_argument("--dynamics-tissues", type=int, help="tissues per surface in part (b) instead of the mode's")
    ap.add_argument("--device", default="auto", help="cpu, gpu or auto (the GPU where CuPy sees one)")
    ap.add_argument("--out", default=".", help="folder for the CSV files and the figure")
    args = ap.parse_args(argv)
    name_of_mode = "full" if args.full else "tiny" if args.tiny else "default"
    mode = dict(MODES[name_of_mode])
    mode.update({k: v for k, v in (("cells", args.cells), ("replicas", args.replicas), ("surfaces", args.surfaces))
                 if v})
    os.makedirs(args.out, exist_ok=True)
    t0 = time.time()
    cell_rows, bin_rows, fractions, stars = [], [], [], []
    for n in mode["cells"]:
        for name in mode["surfaces"]:
            t = time.time()
            cells, p0, status = quench(SURFACES[name], n, mode["p0"], mode["replicas"], mode["max_steps"], args.kr,
                                       device=args.device)
            for p in mode["p0"]:
                sel = {k: v[cells["p0"] == p] for k, v in cells.items()}
                for quantity in QUANTITIES:
                    bin_rows += binned_rows(name, n, p, sel, quantity, mode["bins"])
            cell_rows += [dict(surface=name, n_cells=n, **{k: v[i] for k, v in cells.items()})
                          for i in range(len(cells["q"]))]
            f = zero_fraction(np.full(len(p0), n), p0, status)
            fractions += [dict(surface=name, **{k: f[k][i] for k in f}) for i in range(len(f["p0"]))]
            est = transition(f)
            if est is not None:
                stars.append(dict(surface=name, n_cells=n, p0_star=est.mean, p0_star_err=est.mean_err,
                                  p0_half=est.p0_half, bracketed=est.bracketed))
            print(f"{name:12s} N = {n}: quenched in {time.time() - t:.1f} s; statuses "
                  f"{dict(zip(*np.unique(status, return_counts=True)))}", flush=True)
    write_csv(os.path.join(args.out, "curvature_cells.csv"), cell_rows, CELL_COLUMNS)
    write_csv(os.path.join(args.out, "curvature_bins.csv"), bin_rows, BIN_COLUMNS)
    write_csv(os.path.join(args.out, "curvature_fraction.csv"), fractions,
              ("surface", "n_cells", "p0", "n_replicas", "n_zero", "n_rigid", "n_unconverged", "F", "F_err"))
    if stars:
        write_csv(os.path.join(args.out, "curvature_p0star.csv"), stars, STAR_COLUMNS)
    dyn_bins = []
    for name in [] if args.no_dynamics else [s for s in DYN_SURFACES[name_of_mode] if s in mode["surfaces"]]:
        t = time.time()
        n, reps, steps, lag = mode["dyn"]
        reps = args.dynamics_tissues or reps
        d = dynamics(SURFACES[name], n, reps, steps, lag, device=args.device)
        for quantity in ("msd", "overlap", "t1_rate"):
            dyn_bins += binned_rows(name, n, DYN_P0, d, quantity, mode["bins"])
        print(f"dynamics on the {name}, N = {n}, {reps} tissues, {steps} steps (lag {lag * DYN_DT:g}): "
              f"{time.time() - t:.1f} s", flush=True)
    if dyn_bins:
        write_csv(os.path.join(args.out, "curvature_dynamics.csv"), dyn_bins, BIN_COLUMNS)
    plot(bin_rows, fractions, dyn_bins, os.path.join(args.out, "curvature_gradients.png"))
    print("\nsurface       N     p0    F (err)          | q against K <A> (bins low -> high): K <A>: q +- sem "
          "[p_penta]")
    for fr in fractions:
        rows = [r for r in bin_rows if r["surface"] == fr["surface"] and r["n_cells"] == fr["n_cells"]
                and r["p0"] == fr["p0"] and r["quantity"] == "q"]
        q = "; ".join(f"{r['K_A']:+.3f}: {r['mean']:.4f} +- {r['sem']:.4f} [{r['p_penta']:.3f}]" for r in rows)
        print(f"{fr['surface']:12s} {fr['n_cells']:5d} {fr['p0']:.3f} {fr['F']:.2f} +- {fr['F_err']:.2f} "
              f"({fr['n_zero']}/{fr['n_zero'] + fr['n_rigid']}, {fr['n_unconverged']} unconv.) | {q}")
    for r in stars:
        print(f"{r['surface']:12s} {r['n_cells']:5d} p0* = {r['p0_star']:.4f} +- {r['p0_star_err']:.4f} "
              f"(F = 1/2 at {r['p0_half']:.4f}{'' if r['bracketed'] else '; not bracketed by the grid'})")
    for r in dyn_bins:
        print(f"{r['surface']:12s} {r['quantity']:8s} K <A> {r['K_A']:+.3f}: {r['mean']:.4g} +- {r['sem']:.2g} "
              f"({r['n_tissues']} tissues)")
    print(f"\ntotal {time.time() - t0:.1f} s")


if __name__ == "__main__":
    main()
