"""The paper's Fig. 3: tau_alpha(T) grows with N at p0 = 3.775, kr = 0; MSD inset at p0 = 3.75, kr = 1.

    python examples/fig3_relaxation.py                 # small, minutes on a laptop CPU
    python examples/fig3_relaxation.py --full --device gpu
    python examples/fig3_relaxation.py --full --device gpu --sizes 1024 --prefix fig3_1024

Main panel: for each N, one ensemble holds every temperature (Brownian takes one T per replica),
relaxed with FIRE + T1, equilibrated, then run with T1 exchanges; tau_alpha is where the
self-overlap Q_s (b = 1/2, co-rotating frame) reaches 1/e, averaged over the replicas at each T.
Inset: MSD at T = 5e-4, p0 = 3.75, kr = 1, averaged over 8192/N tissues (--full) or fewer.
Writes fig3_relaxation.png and fig3_tau_alpha.csv / fig3_msd.csv.
"""
from __future__ import annotations

import argparse
import csv
import time

import numpy as np

from spherevm.protocols import glassy_dynamics


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--full", action="store_true", help="paper size: N = 32, 128, 1024, longer runs")
    ap.add_argument("--sizes", type=int, nargs="+", help="only these N (e.g. --full --sizes 1024: one size per "
                    "run, to fit a time limit)")
    ap.add_argument("--device", default="auto")
    ap.add_argument("--prefix", default="fig3")
    args = ap.parse_args(argv)
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
    for n in sizes:
        T = np.repeat(temps, reps)
        res = glassy_dynamics(n, 3.775, 0.0, T=T, dt=dt, steps=steps, replicas=len(T), seed=n, device=args.device,
                              relax_steps=5000, equilibrate_steps=steps // 10)
        for Ti in temps:
            taus = res.tau_alpha_per_replica[T == Ti]
            relaxed = np.isfinite(taus)
            tau = float(np.mean(taus[relaxed])) if relaxed.all() else float("nan")
            rows.append((n, Ti, tau, int(relaxed.sum()), len(taus)))
            print(f"N={n:5d}  T={Ti:<7g} tau_alpha={tau:10.4g}  ({relaxed.sum()}/{len(taus)} replicas relaxed)  "
                  f"[{time.time() - t0:6.1f} s]", flush=True)
        inset = glassy_dynamics(n, 3.75, 1.0, T=5e-4, dt=dt, steps=msd_steps, replicas=max(1, msd_total // n),
                                seed=n + 1, device=args.device, relax_steps=5000)
        curves[n] = (inset.lag, inset.msd)
        print(f"N={n:5d}  MSD at t={inset.lag[-1]:g}: {inset.msd[-1]:.4g}  [{time.time() - t0:6.1f} s]", flush=True)

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
