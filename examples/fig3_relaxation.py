"""The paper's Fig. 3: tau_alpha(T) grows with N at p0 = 3.775, kr = 0; MSD inset at p0 = 3.75, kr = 1.

    python examples/fig3_relaxation.py                 # small, minutes on a laptop CPU
    python examples/fig3_relaxation.py --full --device gpu
    python examples/fig3_relaxation.py --full --device gpu --sizes 1024 --prefix fig3_1024
    python examples/fig3_relaxation.py --full --device gpu --until-relaxed --max-time 50000 --max-seconds 120
    python examples/fig3_relaxation.py --full --sweep fig3_sweep --gpus 2     # main panel as a sweep

Main panel: one ensemble holds every size and temperature (Brownian takes one T per replica; tissues
of different N sit side by side, so a GPU steps them all in about the time of the largest alone;
``--separate``: one ensemble per size), relaxed with FIRE + T1, equilibrated, then run with T1 exchanges; tau_alpha is where the
self-overlap Q_s (b = 1/2, co-rotating frame) reaches 1/e, averaged over the replicas at each T.
``--sweep FOLDER``: the main panel as a :class:`spherevm.sweeps.DynamicsSweep` instead, one chunk per
(N, T), saved as it finishes (rerun to resume) and spread over ``--gpus N`` or a Dask ``--scheduler``;
its tables (tau_alpha.csv, curves.csv) are in FOLDER.
Inset: MSD at T = 5e-4, p0 = 3.75, kr = 1, averaged over 8192/N tissues (--full) or fewer; caging is
read off the local slope d log MSD / d log t (1: diffusive; a minimum well below 1: a plateau, cages).

``--until-relaxed``: production runs in stretches until every tissue's Q_s has fallen to 1/e, or
``--max-time`` time units (1/(mu kP)), or ``--max-seconds`` of wall time; each (N, T) gets its
tau_alpha as the mean over tissues with its standard error and the count relaxed, and each N the
fit log tau = a + b/T + c/T^2 (c < 0: sub-Arrhenius; c's error by bootstrap over tissues,
``spherevm.analysis.arrhenius_fit``). Writes <prefix>_relaxation.png, <prefix>_tau_alpha.csv,
<prefix>_tau_per_tissue.csv, <prefix>_fits.csv and <prefix>_msd.csv in ``--out``.
"""
from __future__ import annotations

import argparse
import csv
import os
import time

import numpy as np

from spherevm import State, init, sweeps
from spherevm.analysis import arrhenius_fit
from spherevm.progress import StageLines
from spherevm.protocols import glassy_dynamics


def tilings(sizes, counts, seed_of):
    """Random tilings of several sizes as one State: ``counts`` (one number, or one per size) tissues of
    each size ``n``, seeded ``seed_of(n)``."""
    counts = np.broadcast_to(counts, (len(sizes),))
    return State.concatenate([init.random_tiling(n, replicas=int(c), seed=seed_of(n)) for n, c in zip(sizes, counts)])


def msd_slopes(lag, msd, span=3):
    """The local slope d log MSD / d log t over ``span`` samples either side (log-spaced lags, t > 0):
    ``(times, slopes)``."""
    t, m = np.asarray(lag, dtype=float), np.asarray(msd, dtype=float)
    keep = (t > 0) & (m > 0)
    lt, lm = np.log(t[keep]), np.log(m[keep])
    if len(lt) <= 2 * span:
        return np.array([]), np.array([])
    return np.exp(lt[span:-span]), (lm[2 * span:] - lm[:-2 * span]) / (lt[2 * span:] - lt[:-2 * span])


def sweep_panel(args, sizes, temps, reps, steps, dt, t0):
    """The main panel as a resumable DynamicsSweep in ``args.sweep`` (one chunk per (N, T)), on this
    machine or over ``--gpus`` / ``--scheduler``: rows (N, T, tau_alpha, its error, relaxed, tissues)."""
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
    rows = list(zip(tau["n_cells"], tau["T"], tau["tau_alpha"], tau["tau_alpha_err"], tau["relaxed"], tau["tissues"]))
    for n, T, t, _, relaxed, tissues in rows:
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
    ap.add_argument("--T", type=float, nargs="+", help="only these temperatures")
    ap.add_argument("--until-relaxed", action="store_true", help="run until every tissue relaxes (or a cap)")
    ap.add_argument("--max-time", type=float, default=None, help="--until-relaxed: the cap in time units "
                    "(default 50,000 with --full, 1,000 otherwise)")
    ap.add_argument("--max-seconds", type=float, default=None, help="wall-time cap of the main panel's "
                    "production (shared among the groups)")
    ap.add_argument("--no-inset", action="store_true", help="leave out the MSD inset")
    ap.add_argument("--out", default=".", help="folder for the CSV files and the figure")
    args = ap.parse_args(argv)
    if args.sweep and args.until_relaxed:
        ap.error("--until-relaxed runs the single-ensemble recipe; leave out --sweep")
    os.makedirs(args.out, exist_ok=True)
    prefix = os.path.join(args.out, args.prefix)
    graphs = False if args.step_by_step else None
    if args.full:
        sizes, temps, reps, steps, msd_total, msd_steps = [32, 128, 1024], [0.02, 0.01, 0.007, 0.005, 0.004], 8, \
            200_000, 8192, 100_000
    else:
        sizes, temps, reps, steps, msd_total, msd_steps = [32, 128], [0.03, 0.02, 0.015, 0.012], 2, 6000, 256, 4000
    if args.sizes:
        sizes = args.sizes
    if args.T:
        temps = sorted(args.T, reverse=True)
    dt = 0.05
    until = dict(until_relaxed=True, max_time=args.max_time or (50_000.0 if args.full else 1000.0),
                 max_seconds=args.max_seconds) if args.until_relaxed else {}
    rows, per_tissue, t0 = [], [], time.time()
    curves = {}
    groups = [[n] for n in sizes] if args.separate else [sizes]
    if args.sweep:
        rows = sweep_panel(args, sizes, temps, reps, steps, dt, t0)
    for k, group in enumerate(groups):
        # main panel: every size and temperature of the group in one ensemble (tilings seeded by N)
        if not args.sweep:
            T = np.tile(np.repeat(temps, reps), len(group))
            if until.get("max_seconds"):
                until["max_seconds"] = max((args.max_seconds - (time.time() - t0)) / (len(groups) - k), 1e-3)
            res = glassy_dynamics(None, 3.775, 0.0, T=T, dt=dt, steps=steps, seed=group[0], device=args.device,
                                  relax_steps=5000, equilibrate_steps=steps // 10, graphs=graphs,
                                  initial_state=tilings(group, len(temps) * reps, seed_of=lambda n: n),
                                  progress=StageLines(f"sizes {group}") if args.until_relaxed else None, **until)
            if args.until_relaxed:
                print(f"sizes {group}: production {res.production_steps * dt:g} time units, stopped: {res.stopped}",
                      flush=True)
            per_size = len(temps) * reps
            for g, n in enumerate(group):
                mine = slice(g * per_size, (g + 1) * per_size)
                for Ti in temps:
                    taus = res.tau_alpha_per_replica[mine][T[mine] == Ti]
                    relaxed = np.isfinite(taus)
                    tau = float(np.mean(taus[relaxed])) if relaxed.all() else float("nan")
                    err = float(np.std(taus, ddof=1) / np.sqrt(len(taus))) if relaxed.all() and len(taus) > 1 else \
                        float("nan")
                    rows.append((n, Ti, tau, err, int(relaxed.sum()), len(taus)))
                    per_tissue += [(n, Ti, j, x) for j, x in enumerate(taus)]
                    print(f"N={n:5d}  T={Ti:<7g} tau_alpha={tau:10.4g} +- {err:<8.3g} ({relaxed.sum()}/{len(taus)} "
                          f"replicas relaxed)  [{time.time() - t0:6.1f} s]", flush=True)
        if args.no_inset:
            continue
        # inset: msd_total / N tissues of each size, one ensemble
        counts = [max(1, msd_total // n) for n in group]
        inset = glassy_dynamics(None, 3.75, 1.0, T=5e-4, dt=dt, steps=msd_steps, seed=group[0] + 1, device=args.device,
                                relax_steps=5000, graphs=graphs,
                                initial_state=tilings(group, counts, seed_of=lambda n: n + 1))
        start = np.cumsum([0] + counts)
        for g, n in enumerate(group):
            m = inset.msd_per_replica[:, start[g]:start[g + 1]].mean(axis=1)   # tissues of one size: equal weights
            curves[n] = (inset.lag, m)
            ts, slope = msd_slopes(inset.lag, m)
            low = (f"; slope d log MSD / d log t: minimum {slope.min():.3g} at t = {ts[slope.argmin()]:.3g}, "
                   f"{slope[-1]:.3g} at t = {ts[-1]:.3g}") if len(slope) else ""
            print(f"N={n:5d}  MSD at t={inset.lag[-1]:g}: {m[-1]:.4g}{low}  [{time.time() - t0:6.1f} s]", flush=True)

    fits = []
    for n in sizes if per_tissue else ():
        tau = np.array([[x for (m, Ti, _, x) in per_tissue if m == n and Ti == T] for T in temps])
        fit = arrhenius_fit(temps, tau)
        fits.append((n, None if fit is None else fit.c, None if fit is None else fit.c_err,
                     "fewer than 4 temperatures with every tissue relaxed" if fit is None else fit.verdict()))
        print(f"N={n:5d}  log tau = a + b/T + c/T^2: {fits[-1][3]}", flush=True)
    with open(f"{prefix}_tau_alpha.csv", "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["N", "T", "tau_alpha", "tau_alpha_err", "replicas_relaxed", "replicas"])
        w.writerows(rows)
    with open(f"{prefix}_tau_per_tissue.csv", "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["N", "T", "tissue", "tau_alpha"])
        w.writerows(per_tissue)
    with open(f"{prefix}_fits.csv", "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["N", "c", "c_err", "verdict"])
        w.writerows(fits)
    with open(f"{prefix}_msd.csv", "w", newline="") as f:
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
        sel = [(T, tau) for (m, T, tau, *_) in rows if m == n and np.isfinite(tau)]
        if sel:
            Ts, taus = zip(*sel)
            ax.semilogy(1 / np.array(Ts), taus, "o-", color=c, label=f"N = {n}")
    ax.set_xlabel("1 / T")
    ax.set_ylabel(r"$\tau_\alpha$")
    ax.legend(frameon=False)
    if curves:
        inset = ax.inset_axes([0.58, 0.1, 0.38, 0.35])
        for c, n in zip(colors, sizes):
            lag, m = curves[n]
            inset.loglog(lag[1:], m[1:], color=c)
        inset.set_xlabel("t", fontsize=7)
        inset.set_ylabel("MSD", fontsize=7)
        inset.tick_params(labelsize=6)
    fig.tight_layout()
    fig.savefig(f"{prefix}_relaxation.png", dpi=150)
    print(f"wrote {prefix}_relaxation.png and the CSV files in {time.time() - t0:.0f} s")


if __name__ == "__main__":
    main()
