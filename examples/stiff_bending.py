"""Stiff bending: does a bending term as stiff as the vertex model make the glassy dynamics Arrhenius?

tau_alpha(T) at p0 = 3.775 (the paper's Fig. 3 point) with ``Bending(B)`` for B up to 100 (units of
kP <A>; a neighbour pair is a spring of stiffness about B / R^2, R^2 = N / 4 pi), each (N, B) one
ensemble of ``--replicas`` tissues per temperature: random tilings relaxed without bending
(``spherevm.protocols.inherent_states``), then ``glassy_dynamics(dt="auto")`` with it: FIRE's
dt_max and the Brownian step from the stiffest mode of the forces (``spherevm.protocols.stable_dt``),
production until every tissue's Q_s falls to 1/e or the cap (``--max-time`` time units, and
``--max-seconds`` of wall time shared among the groups not yet run). Per (N, B): the fit
``log tau = a + b/T + c/T^2`` of the mean of log tau over tissues (c < 0: sub-Arrhenius), c's error
by bootstrap over the tissues (``spherevm.analysis.arrhenius_fit``); the plot of c against B.

A group whose run ends in an exploding step (a cell collapsing: the normal of a cell of vanishing
area, and with it the bending force, diverges) is reported with the error and left out.

    python examples/stiff_bending.py                       # N = 32, B = 0 and 3: a CPU, a minute or two
    python examples/stiff_bending.py --full --device gpu   # N = 128 and 1024, B = 0 to 100: one GPU

Writes ``--out``/stiff_bending_tau.csv (every tissue's tau), stiff_bending_fits.csv (one row per
(N, B)) and stiff_bending.png.
"""
from __future__ import annotations

import argparse
import csv
import os
import time

import numpy as np

from spherevm.analysis import arrhenius_fit
from spherevm.plugins.forces import Bending
from spherevm.progress import StageLines
from spherevm.protocols import glassy_dynamics, inherent_states

PRESETS = {
    "small": dict(cells=[32], B=[0.0, 3.0], T=[0.025, 0.03, 0.035, 0.04], replicas=2, max_time=250.0, relax=1000),
    "full": dict(cells=[128, 1024], B=[0.0, 1.0, 3.0, 10.0, 30.0, 100.0], T=[0.01, 0.0125, 0.015, 0.02, 0.03],
                 replicas=4, max_time=2000.0, relax=5000),
}


def run_group(n, B, temps, reps, args, seconds):
    """One (N, B) ensemble; returns (tau (n_T, reps), DynamicsResult or None, error text or "")."""
    T = np.repeat(temps, reps)
    try:
        res = glassy_dynamics(None, 3.775, args.kr, T=T, dt="auto", max_time=args.max_time, seed=n,
                              device=args.device, relax_steps=args.relax, equilibrate_steps=args.equilibrate,
                              extra_forces=[Bending(B)], until_relaxed=True, max_seconds=seconds,
                              progress=StageLines(f"N={n} B={B:g}"),
                              initial_state=inherent_states(n, len(T), 3.775, args.kr, steps=args.relax, seed=n,
                                                            device=args.device))
    except FloatingPointError as err:
        return np.full((len(temps), reps), np.nan), None, str(err).splitlines()[0]
    return res.tau_alpha_per_replica.reshape(len(temps), reps), res, ""


def main(argv=None):
    ap = argparse.ArgumentParser(allow_abbrev=False, description=__doc__.splitlines()[0])
    ap.add_argument("--full", action="store_true", help=f"one GPU: {PRESETS['full']}")
    ap.add_argument("--cells", type=int, nargs="+")
    ap.add_argument("--B", type=float, nargs="+")
    ap.add_argument("--T", type=float, nargs="+")
    ap.add_argument("--replicas", type=int, help="tissues per (N, B, T)")
    ap.add_argument("--kr", type=float, default=0.0)
    ap.add_argument("--max-time", type=float, help="production cap in time units 1/(mu kP)")
    ap.add_argument("--max-seconds", type=float, default=None, help="wall-time cap of the whole study (the "
                    "production of each group stops after its share of what is left)")
    ap.add_argument("--relax", type=int, help="FIRE iterations at most")
    ap.add_argument("--equilibrate", type=int, default=None, help="Brownian steps before production (default: "
                    "a tenth of the cap)")
    ap.add_argument("--device", default="auto")
    ap.add_argument("--out", default="stiff_bending")
    args = ap.parse_args(argv)
    preset = PRESETS["full" if args.full else "small"]
    for key in ("cells", "B", "T", "replicas", "max_time", "relax"):
        if getattr(args, key) is None:
            setattr(args, key, preset[key])
    temps = np.sort(np.asarray(args.T, dtype=float))
    os.makedirs(args.out, exist_ok=True)
    groups = [(n, B) for n in args.cells for B in args.B]
    started, rows, fits = time.perf_counter(), [], []
    print(f"stiff_bending: N = {args.cells}, B = {args.B}, T = {temps.tolist()}, {args.replicas} tissues per T, "
          f"kr = {args.kr}, cap {args.max_time:g} time units"
          + (f" and {args.max_seconds:g} s" if args.max_seconds else ""), flush=True)
    for k, (n, B) in enumerate(groups):
        left = None if args.max_seconds is None else (args.max_seconds - (time.perf_counter() - started)) / (
            len(groups) - k)
        if left is not None and left <= 0:
            print(f"N={n} B={B:g}: not run (--max-seconds spent)", flush=True)
            fits.append(dict(N=n, B=B, R2=n / (4 * np.pi), stopped="not run"))
            continue
        t0 = time.perf_counter()
        tau, res, error = run_group(n, B, temps, args.replicas, args, left)
        seconds = time.perf_counter() - t0
        rows += [(n, B, T, j, tau[i, j]) for i, T in enumerate(temps) for j in range(args.replicas)]
        fit = None if res is None else arrhenius_fit(temps, tau)
        row = dict(N=n, B=B, R2=n / (4 * np.pi), dt=None if res is None else res.dt,
                   stopped=error or res.stopped, time_run=None if res is None else res.production_steps * res.dt,
                   relaxed=int(np.isfinite(tau).sum()), tissues=tau.size, seconds=seconds,
                   c=None if fit is None else fit.c, c_err=None if fit is None else fit.c_err,
                   verdict="failed: " + error if error else "no fit (fewer than 4 T with all relaxed)" if fit is None
                   else fit.verdict())
        fits.append(row)
        taus = "  ".join(f"T={T:g}: {np.exp(np.mean(np.log(t))):.4g}" if np.all(np.isfinite(t)) else
                         f"T={T:g}: {int(np.isfinite(t).sum())}/{len(t)} relaxed" for T, t in zip(temps, tau))
        print(f"N={n} B={B:g} (B/R^2 = {B / row['R2']:.3g}) dt={row['dt']} stopped: {row['stopped']} "
              f"[{seconds:.1f} s, total {time.perf_counter() - started:.1f} s]\n    {taus}\n    {row['verdict']}",
              flush=True)
    write(args.out, rows, fits)
    plot(args.out, fits, rows, temps)
    print_summary(fits)


def write(out, rows, fits):
    with open(os.path.join(out, "stiff_bending_tau.csv"), "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["N", "B", "T", "tissue", "tau_alpha"])
        w.writerows(rows)
    keys = ["N", "B", "R2", "dt", "stopped", "time_run", "relaxed", "tissues", "seconds", "c", "c_err", "verdict"]
    with open(os.path.join(out, "stiff_bending_fits.csv"), "w", newline="") as f:
        w = csv.DictWriter(f, keys)
        w.writeheader()
        w.writerows([{k: r.get(k) for k in keys} for r in fits])


def print_summary(fits):
    print(f"\n{'N':>5} {'B':>6} {'B/R^2':>7} {'dt':>8} {'relaxed':>8} {'c':>10} {'+-':>9}  verdict")
    for r in fits:
        dt = "-" if r.get("dt") is None else f"{r['dt']:.3g}"
        c = "-" if r.get("c") is None else f"{r['c']:.3g}"
        e = "-" if r.get("c_err") is None else f"{r['c_err']:.2g}"
        rel = "-" if "relaxed" not in r else f"{r['relaxed']}/{r['tissues']}"
        print(f"{r['N']:>5} {r['B']:>6g} {r['B'] / r['R2']:>7.3g} {dt:>8} {rel:>8} {c:>10} {e:>9}  "
              f"{r.get('verdict', r['stopped'])}")


def plot(out, fits, rows, temps):
    try:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        return
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(10, 4))
    for r in fits:
        tau = np.array([[t for (n, B, T, _, t) in rows if n == r["N"] and B == r["B"] and T == Ti] for Ti in temps])
        ok = np.all(np.isfinite(tau), axis=1) if tau.size else []
        if tau.size and np.any(ok):
            ax1.plot(1 / temps[ok], np.log(tau[ok]).mean(axis=1), "o-", label=f"N={r['N']} B={r['B']:g}")
    ax1.set_xlabel("1/T"), ax1.set_ylabel("<log tau_alpha>")
    for n in sorted({r["N"] for r in fits}):
        pts = [(r["B"], r["c"], r["c_err"]) for r in fits if r["N"] == n and r.get("c") is not None]
        if pts:
            B, c, e = map(np.array, zip(*pts))
            ax2.errorbar(B, c, yerr=e, marker="o", capsize=3, label=f"N = {n}")
    ax2.axhline(0, color="k", lw=0.5)
    ax2.set_xscale("symlog", linthresh=1.0)
    ax2.set_xlabel("B (kP <A>)"), ax2.set_ylabel("curvature c of log tau(1/T)")
    for ax in (ax1, ax2):
        if ax.get_legend_handles_labels()[0]:
            ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(os.path.join(out, "stiff_bending.png"), dpi=120)
    plt.close(fig)


if __name__ == "__main__":
    main()
