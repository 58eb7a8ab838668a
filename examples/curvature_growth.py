"""Growth on curved surfaces: where cells divide against the local Gaussian curvature K, and where
the tissue becomes rigid first (docs/results.md, "Growth on curved surfaces").

Per surface (the torus of R/r = 3 and the Gaussian bump of h/w = 2 of examples/curvature_gradients.py)
and division rule: ``--replicas`` random tilings of ``--start`` cells (<A> = 1), kr = 0, P0 = 3.80
held fixed (the growing sphere of examples/fig4_growth.py), quenched by FIRE + T1; then rounds: a
fraction ``--grow-fraction`` of each replica's cells divide (Hertwig's rule; rule "random": cells
chosen at random, "largest": the largest by area), the surface grows so that <A> stays 1
(``RadiusSchedule("constant_area")``: every length scales, the shape is kept) and FIRE + T1 relax
``--relax`` steps. At each N of ``--measure``: a quench (FIRE + T1 to force_tol 1e-10, at most
``--max-steps``), then per cell K <A> at its area centroid and its perimeter tension
``(P - P0) / P0`` (zero on the floppy side, where every cell has its target perimeter), binned in K
quartiles (errors over tissues), and the zero-energy fraction. Every division records K <A> at the
dividing cell, beside the K <A> of all the cells of its replica at that moment.

    python examples/curvature_growth.py --out growth/          # N 64 -> 256, 8 tissues: minutes on a CPU
    python examples/curvature_growth.py --device gpu --replicas 32 --measure 128 256 512 1024 --out growth/

Writes curvature_growth_bins.csv, curvature_growth_fraction.csv, curvature_growth_divisions.csv and
curvature_growth.png in ``--out``.
"""
import argparse
import csv
import os
import time

import numpy as np

import spherevm as svm
from spherevm.analysis import binned_mean, cell_curvature
from spherevm.analysis.rigidity import classify
from spherevm.plugins.forces import VertexModel
from spherevm.plugins.integrators import FIRE
from spherevm.plugins.updaters import T1, Division, RadiusSchedule

SURFACES = {"torus R/r=3": "torus:R=3,r=1", "bump h/w=2": "bump:h=2,w=1,box=6.5"}
RULES = ("random", "largest")
BINS = 4


def grow(spec, rule_name, args, log):
    """One surface and rule: rows of the quenches (per cell K and tension, per replica status) and
    the divisions' K beside every cell's."""
    sim = svm.Simulation(device=args.device, seed=args.seed)
    sim.state = svm.init.tilings_on(spec, args.start, [(args.seed, r) for r in range(args.replicas)])
    n0 = sim.state.n_cells
    sim.operations.forces.append(VertexModel(kA=np.zeros(n0), kP=1.0, A0=np.ones(n0), P0=np.full(n0, args.p0)))
    sim.operations.updaters.append(T1())
    gen = np.random.default_rng(args.seed)
    stage = {"on": False, "target": args.start}
    divisions = {"K_divided": [], "K_all": []}

    def rule(s):
        """``--grow-fraction`` of each replica's cells, never past the stage's target N."""
        if not stage["on"]:
            return []
        state = s.state.to("cpu")
        area = state.constraint.cell_areas_np(state)
        k_cells = cell_curvature(state)
        out = []
        for a, b in zip(state.cell_start[:-1], state.cell_start[1:]):
            k = min(max(1, int(args.grow_fraction * (b - a))), stage["target"] - (b - a))
            if k > 0:
                pick = (gen.choice(b - a, size=k, replace=False) if rule_name == "random"
                        else np.argsort(-area[a:b], kind="stable")[:k])
                out.extend((a + pick).tolist())
        divisions["K_divided"].extend(k_cells[out].tolist())
        divisions["K_all"].extend(k_cells.tolist())
        return out

    sim.operations.updaters.append(Division(rule=rule, axis="hertwig"))
    sim.operations.updaters.append(RadiusSchedule("constant_area", area=1.0))
    sim.operations.integrator = FIRE(dt=0.05)
    quenches = []
    n = args.start
    for target in sorted(set(args.measure) | {args.start}):
        stage["target"] = target
        while n < target:
            sim.operations.integrator.reset()       # a quench stops converged replicas
            stage["on"] = True
            sim.run(1)                             # one division round: Division runs first in the step
            stage["on"] = False
            sim.run(args.relax)
            n = int(sim.state.cells_per_replica.min())
        res = sim.minimize(force_tol=1e-10, energy_tol=1e-16, max_steps=args.max_steps)
        state = sim.state.to("cpu")
        perimeter = np.asarray(state.constraint.cell_geometry(state).perimeter)
        quenches.append(dict(N=n, K=cell_curvature(state), tension=(perimeter - args.p0) / args.p0,
                             replica=state.cell_replica_np(), status=classify(res.energy_per_cell, res.reason)))
        log(f"  {spec} {rule_name}: N = {n}, zero-energy {np.mean(quenches[-1]['status'] == 'zero'):.2f}")
    return quenches, divisions


def rows_of(name, rule_name, quenches, divisions):
    """CSV rows: tension in K quartiles per N (rigid tissues only), the zero-energy fraction per N,
    and the divisions' share per K quartile of the cells."""
    bins, fractions = [], []
    for q in quenches:
        status = q["status"]
        fractions.append(dict(surface=name, rule=rule_name, N=q["N"], n_replicas=len(status),
                              zero=int(np.sum(status == "zero")), rigid=int(np.sum(status == "rigid"))))
        rigid = np.isin(q["replica"], np.flatnonzero(status == "rigid"))
        if rigid.sum() < BINS or np.ptp(q["K"][rigid]) == 0:
            continue
        b = binned_mean(q["K"][rigid], q["tension"][rigid], bins=BINS, groups=q["replica"][rigid])
        bins += [dict(surface=name, rule=rule_name, N=q["N"], bin=i, K_A=b.x[i], tension=b.mean[i], sem=b.sem[i],
                      n_tissues=int(b.count[i])) for i in range(len(b.x))]
    k_all, k_div = np.asarray(divisions["K_all"]), np.asarray(divisions["K_divided"])
    edges = np.quantile(k_all, np.linspace(0, 1, BINS + 1))
    share_all = np.histogram(k_all, edges)[0] / max(len(k_all), 1)
    share_div = np.histogram(k_div, edges)[0] / max(len(k_div), 1)
    div_rows = [dict(surface=name, rule=rule_name, bin=i, K_low=edges[i], K_high=edges[i + 1],
                     cells=share_all[i], divisions=share_div[i], n_divisions=len(k_div)) for i in range(BINS)]
    return bins, fractions, div_rows


def write_csv(path, rows):
    if not rows:
        return
    with open(path, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows({k: (f"{v:.6g}" if isinstance(v, (float, np.floating)) else v) for k, v in r.items()} for r in rows)


def plot(bins, fractions, div_rows, path):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, axes = plt.subplots(1, 3, figsize=(16, 4.6))
    for (name, rule_name), marker in zip([(s, r) for s in SURFACES for r in RULES], "os^v"):
        mine = [r for r in fractions if r["surface"] == name and r["rule"] == rule_name]
        line, = axes[0].plot([r["N"] for r in mine], [r["zero"] / max(r["zero"] + r["rigid"], 1) for r in mine],
                             marker + "-", label=f"{name}, {rule_name}: zero / converged")
        axes[0].plot([r["N"] for r in mine], [1 - (r["zero"] + r["rigid"]) / r["n_replicas"] for r in mine],
                     marker + ":", color=line.get_color(), alpha=0.6, label="not converged / all")
        last = max((r["N"] for r in bins if r["surface"] == name and r["rule"] == rule_name), default=None)
        rows = [r for r in bins if r["surface"] == name and r["rule"] == rule_name and r["N"] == last]
        axes[1].errorbar([r["K_A"] for r in rows], [r["tension"] for r in rows], [r["sem"] for r in rows],
                         marker=marker, capsize=2, label=f"{name}, {rule_name}, N = {last}")
        rows = [r for r in div_rows if r["surface"] == name and r["rule"] == rule_name]
        axes[2].plot([0.5 * (r["K_low"] + r["K_high"]) for r in rows], [r["divisions"] / r["cells"] for r in rows],
                     marker + "-", label=f"{name}, {rule_name}")
    axes[0].set(xlabel="N", ylabel="fraction of tissues", title="growing at <A> = 1, P0 = 3.80", xscale="log")
    axes[1].set(xlabel="K <A> at the cell", ylabel="(P - P0) / P0, rigid tissues", title="tension at the last N")
    axes[2].axhline(1.0, color="k", lw=0.5)
    axes[2].set(xlabel="K <A> at the cell (quartiles)", ylabel="share of divisions / share of cells",
                title="where cells divide")
    for ax in axes:
        ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter,
                                 allow_abbrev=False)
    ap.add_argument("--replicas", type=int, default=8, help="tissues per surface and rule")
    ap.add_argument("--start", type=int, default=64)
    ap.add_argument("--measure", type=int, nargs="+", default=[96, 128, 192, 256], help="N at which to quench")
    ap.add_argument("--p0", type=float, default=3.80, help="P0 in units of sqrt(<A>) = 1")
    ap.add_argument("--grow-fraction", type=float, default=0.1, help="fraction of cells dividing per round")
    ap.add_argument("--relax", type=int, default=100, help="FIRE steps after each division round")
    ap.add_argument("--max-steps", type=int, default=20000, help="FIRE steps per quench")
    ap.add_argument("--surfaces", nargs="+", default=list(SURFACES), choices=list(SURFACES))
    ap.add_argument("--rules", nargs="+", default=list(RULES), choices=list(RULES))
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--device", default="auto", help="cpu, gpu or auto (the GPU where CuPy sees one)")
    ap.add_argument("--out", default=".", help="folder for the CSV files and the figure")
    args = ap.parse_args(argv)
    os.makedirs(args.out, exist_ok=True)
    t0 = time.time()
    log = lambda text: print(f"{text} [{time.time() - t0:.0f} s]", flush=True)   # noqa: E731
    bins, fractions, div_rows = [], [], []
    for name in args.surfaces:
        for rule_name in args.rules:
            quenches, divisions = grow(SURFACES[name], rule_name, args, log)
            b, f, d = rows_of(name, rule_name, quenches, divisions)
            bins, fractions, div_rows = bins + b, fractions + f, div_rows + d
    for rows, stem in ((bins, "bins"), (fractions, "fraction"), (div_rows, "divisions")):
        write_csv(os.path.join(args.out, f"curvature_growth_{stem}.csv"), rows)
    plot(bins, fractions, div_rows, os.path.join(args.out, "curvature_growth.png"))
    print("\nsurface, rule: zero-energy fraction by N | divisions / cells per K quartile (low -> high K)")
    for name in args.surfaces:
        for rule_name in args.rules:
            f = [r for r in fractions if r["surface"] == name and r["rule"] == rule_name]
            d = [r for r in div_rows if r["surface"] == name and r["rule"] == rule_name]
            counts = ", ".join(f"N={r['N']}: {r['zero']}/{r['rigid']}/{r['n_replicas']}" for r in f)
            shares = ", ".join(f"{r['divisions'] / r['cells']:.2f}" for r in d)
            print(f"{name}, {rule_name} (zero/rigid/all): {counts} | {shares} ({d[0]['n_divisions']} divisions)")
    for r in bins:
        print(f"{r['surface']}, {r['rule']}, N = {r['N']}: K <A> {r['K_A']:+.3f}: tension {r['tension']:.4f} "
              f"+- {r['sem']:.4f} ({r['n_tissues']} tissues)")
    print(f"\ntotal {time.time() - t0:.0f} s")


if __name__ == "__main__":
    main()
