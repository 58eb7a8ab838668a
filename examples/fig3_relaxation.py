"""The paper's Fig. 3: tau_alpha(T) grows with N at p0 = 3.775, kr = 0; MSD inset at p0 = 3.75, kr = 1.

    python examples/fig3_relaxation.py                 # small, minutes on a laptop CPU
    python examples/fig3_relaxation.py --full --device gpu
    python examples/fig3_relaxation.py --full --device gpu --sizes 1024 --prefix fig3_1024
    python examples/fig3_relaxation.py --full --sweep fig3_sweep --gpus 2     # main panel as a sweep

Main panel: one ensemble holds every size and temperature (Brownian takes one T per replica; tissues
of different N sit side by side, so a GPU steps them all in about the time of the largest alone;
``--separate``: one ensemble per size), relaxed with FIRE + T1, equilibrated, then run with T1 exchanges; tau_alpha is where the
self-overlap Q_s (b = 1/2, co-rotating frame) reaches 1/e, averaged over the replicas at each T.
``--sweep FOLDER``: the main panel as a :class:`spherevm.sweeps.DynamicsSweep` instead, one chunk per
(N, T), saved as it finishes (rerun to resume) and spread over ``--gpus N`` or a Dask ``--scheduler``;
its tables (tau_alpha.csv, curves.csv) are in FOLDER.
Inset: MSD at T = 5e-4, p0 = 3.75, kr = 1, averaged over 8192/N tissues (--full) or fewer.
Writes fig3_relaxation.png and fig3_tau_alpha.csv / fig3_msd.csv.
"""
from __future__ import annotations

import argparse
import csv
import time

import numpy as np

from spherevm import State, init, sweeps
from spherevm.protocols import glassy_dynamics


def tilings(sizes, counts, seed_of):
    """Random tilings of several sizes as one State: ``counts`` (one number, or one per size) tissues of
    each size ``n``, seeded ``seed_of(n)``."""
    counts = np.broadcast_to(counts, (len(sizes),))
    return State.concatenate([init.random_tiling(n, replicas=int(c), seed=seed_of(n)) for n, c in zip(sizes, counts)])


def sweep_panel(args, sizes, temps, reps, steps, dt, t0):
    """The main panel as a resumable DynamicsSweep in ``args.sweep`` (one chunk per (N, T)), on this
    machine or over ``--gpus`` / ``--scheduler``: rows (N, T, tau_alpha, relaxed, tissues)."""
    sweep = sweeps.DynamicsSweep(cells=sizes, T=temps, p0=[3.775], kr=0.0, replicas=reps, steps=steps, dt=dt,
                                 relax_steps=5000, equilibrate_steps=steps // 10)
    client = sweeps.cluster.client(scheduler=args.scheduler, gpus=args.gpus) if args.gpus or args.scheduler else None
    bar = sweeps.TextProgress(label="fig3", units="tissues")
    try:
        result = sweeps.run_sweep(sweep, args.sweep, executor=client, device="gpu" if args.gpus else args.device,
                                  progress=bar)
    finally:
        bar.close()
        if client is not None:
            client.close()
    tau = sweeps.write_dynamics_tables(args.sweep, result.records)["tau_alpha"]
    rows = list(zip(tau["n_cells"], tau["T"], tau["tau_alpha"], tau["relaxed"], tau["tissues"]))
    for n, T, t, relaxed, tissues in rows:
        print(f"N={n:5d}  T={T:<7g} tau_alpha={t:10.4g}  ({relaxed}/{tissues} replicas relaxed)  "
              f"[{time.time() - t0:6.1f} s]", flush=True)
    return rows


def main(argv=None):
    ap = argparse.ArgumentParser(allow_abbrev=False, description=__doc__.splitlines()[0])
    ap.add_argument("--full", action="store_true", help="paper size: N = 32, 128, 1024, longer runs")
    ap.add_argument("--sizes", type=int, nargs="+", help="only these N (e.g. --full --sizes 1024: one size per "
                    "run, to fit a time limit)")
    ap.add_argument("--device", default="auto")
    ap.add_argument("--prefix", default="fig3")
    ap.add_argument("--separate", action="store_true", help="one ensemble per size (default: all sizes in one "
                    "ensemble, which a GPU steps in about the time of the largest alone)")
    ap.add_argument("--step-by-step", action="store_true", help="no CUDA graphs on the GPU (the same numbers, "
                    "slower; to check that they are)")
    ap.add_argument("--sweep", metavar="FOLDER", help="run the main panel as a resumable dynamics sweep in FOLDER")
    ap.add_argument("--gpus", type=int, help="with --sweep: one Dask worker per GPU of this host")
    ap.add_argument("--scheduler", help="with --sweep: a Dask scheduler address, or 'local'")
    args = ap.parse_args(argv)
    graphs = False if args.step_by_step else None
    if args.full:
        sizes, temps, reps, steps, msd_total, msd_steps = [32, 128, 1024], [0.02, 0.01, 0.007, 0.005, 0.004], 8, \
            200_000, 8192, 100_000
    else:
        sizes, temps, reps, steps, msd_total, msd_steps = [32, 128], [0.03, 0.02, 0.012], 2, 6000, 256, 4000
    if args.sizes:
        sizes = args.sizes
    dt = 0.05
    rows, t0 = [], time.time()
    curves = {}
    groups = [[n] for n in sizes] if args.separate else [sizes]
    if args.sweep:
        rows = sweep_panel(args, sizes, temps, reps, steps, dt, t0)
    for group in groups:
        # main panel: every size and temperature of the group in one ensemble (tilings seeded by N)
        if not args.sweep:
            T = np.tile(np.repeat(temps, reps), len(group))
            res = glassy_dynamics(None, 3.775, 0.0, T=T, dt=dt, steps=steps, seed=group[0], device=args.device,
                                  relax_steps=5000, equilibrate_steps=steps // 10, graphs=graphs,
                                  initial_state=tilings(group, len(temps) * reps, seed_of=lambda n: n))
            per_size = len(temps) * reps
            for g, n in enumerate(group):
                mine = slice(g * per_size, (g + 1) * per_size)
                for Ti in temps:
                    taus = res.tau_alpha_per_replica[mine][T[mine] == Ti]
                    relaxed = np.isfinite(taus)
                    tau = float(np.mean(taus[relaxed])) if relaxed.all() else float("nan")
                    rows.append((n, Ti, tau, int(relaxed.sum()), len(taus)))
                    print(f"N={n:5d}  T={Ti:<7g} tau_alpha={tau:10.4g}  ({relaxed.sum()}/{len(taus)} replicas "
                          f"relaxed)  [{time.time() - t0:6.1f} s]", flush=True)
        # inset: msd_total / N tissues of each size, one ensemble
        counts = [max(1, msd_total // n) for n in group]
        inset = glassy_dynamics(None, 3.75, 1.0, T=5e-4, dt=dt, steps=msd_steps, seed=group[0] + 1, device=args.device,
                                relax_steps=5000, graphs=graphs,
                                initial_state=tilings(group, counts, seed_of=lambda n: n + 1))
        start = np.cumsum([0] + counts)
        for g, n in enumerate(group):
            m = inset.msd_per_replica[:, start[g]:start[g + 1]].mean(axis=1)   # tissues of one size: equal weights
            curves[n] = (inset.lag, m)
            print(f"N={n:5d}  MSD at t={inset.lag[-1]:g}: {m[-1]:.4g}  [{time.time() - t0:6.1f} s]", flush=True)

    with open(f"{args.prefix}_tau_alpha.csv", "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["N", "T", "tau_alpha", "replicas_relaxed", "replicas"])
        w.writerows(rows)
    with open(f"{args.prefix}_msd.csv", "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["N", "time", "msd"])
        for n, (lag, m) in curves.items():
            w.writerows((n, t, x) for t, x in zip(lag, m))
    try:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        print("matplotlib is not installed (pip install 'spherevm[plot]'): wrote the CSV files only")
        return
    fig, ax = plt.subplots(figsize=(5, 4))
    colors = plt.cm.RdYlBu(np.linspace(0.05, 0.95, len(sizes)))
    for c, n in zip(colors, sizes):
        sel = [(T, tau) for (m, T, tau, _, _) in rows if m == n and np.isfinite(tau)]
        if sel:
            Ts, taus = zip(*sel)
            ax.semilogy(1 / np.array(Ts), taus, "o-", color=c, label=f"N = {n}")
    ax.set_xlabel("1 / T")
    ax.set_ylabel(r"$\tau_\alpha$")
    ax.legend(frameon=False)
    inset = ax.inset_axes([0.58, 0.1, 0.38, 0.35])
    for c, n in zip(colors, sizes):
        lag, m = curves[n]
        inset.loglog(lag[1:], m[1:], color=c)
    inset.set_xlabel("t", fontsize=7)
    inset.set_ylabel("MSD", fontsize=7)
    inset.tick_params(labelsize=6)
    fig.tight_layout()
    fig.savefig(f"{args.prefix}_relaxation.png", dpi=150)
    print(f"wrote {args.prefix}_relaxation.png, {args.prefix}_tau_alpha.csv, {args.prefix}_msd.csv "
          f"in {time.time() - t0:.0f} s")


if __name__ == "__main__":
    main()
