"""Does curvature act on the glassy dynamics only through p0*(N)? tau_alpha against p0 and p0 - p0*(N).

The paper: the size of the curvature effect "will depend on p0 - p0*(N -> infinity)". Here
tau_alpha(T) at several p0 for several N (kr = 0) runs as one ensemble (per-tissue p0 and T,
``glassy_dynamics`` until every tissue's Q_s falls to 1/e or the cap), and the curves are compared
on two axes: the raw p0, and p0 - p0*(N) with p0*(N) from the rigidity sweep (default T1 rules; the
table of docs/results.md, or ``--p0star`` a sweep's ``p0star.csv``).

The collapse measure S: at each temperature, one quadratic in x (x = p0 or p0 - p0*(N)) fitted to
the mean log tau_alpha of every (N, p0), and S the root mean square of the residuals over all points
and temperatures. If the dynamics depends on N only through p0 - p0*(N), S on that axis falls to the
noise of the means (``noise``: the root mean square of their standard errors over tissues) and
below S on the raw axis. Errors of S, and the fraction of resamplings with S(shifted) < S(raw), by
bootstrap over tissues.

    python examples/curvature_collapse.py                      # N = 32, 64: a CPU, minutes
    python examples/curvature_collapse.py --full --device gpu  # N = 32 ... 1024, p0 = 3.70 ... 3.85: one GPU

Writes ``--out``/collapse_tau.csv (every tissue), collapse_measure.csv and collapse.png.
"""
from __future__ import annotations

import argparse
import csv
import os
import time

import numpy as np

from spherevm import State, init
from spherevm.progress import StageLines
from spherevm.protocols import glassy_dynamics

#: p0*(N) of the paper-size sweep with the default T1 rules (docs/results.md; one H200, 2026-11-24)
P0STAR = {32: 3.7688, 48: 3.7958, 64: 3.8062, 96: 3.8204, 128: 3.8264, 192: 3.8318, 256: 3.8344, 512: 3.8387,
          1024: 3.8435}
PRESETS = {
    "small": dict(cells=[32, 64], p0=[3.70, 3.775, 3.85], T=[0.025, 0.018], replicas=2, max_time=600.0),
    "full": dict(cells=[32, 64, 128, 256, 1024], p0=[3.70, 3.75, 3.80, 3.85], T=[0.025, 0.018, 0.013, 0.01],
                 replicas=4, max_time=20_000.0),
}


def read_p0star(path):
    """``{N: p0*}`` from a sweep's p0star.csv (columns n_cells, p0_star)."""
    with open(path) as f:
        return {int(r["n_cells"]): float(r["p0_star"]) for r in csv.DictReader(f)}


def usable(p0, logs):
    """The temperatures S uses: 4 points (N, p0) at least with every tissue relaxed, at 3 values of
    p0 at least (so that both axes fit a quadratic to the same points)."""
    ok = np.all(np.isfinite(logs), axis=2)
    return np.array([row.sum() >= 4 and len(np.unique(p0[row])) >= 3 for row in ok])


def scatter(x, logs, rows):
    """S: at each temperature of ``rows`` a quadratic in ``x`` (n_points,) fitted to ``logs`` (n_T,
    n_points, tissues) averaged over tissues; the RMS of the residuals over every point with all
    tissues relaxed."""
    residuals = []
    for row in logs.mean(axis=2)[rows]:
        ok = np.isfinite(row)
        xc = x[ok] - x[ok].mean()
        residuals.append(row[ok] - np.polyval(np.polyfit(xc, row[ok], 2), xc))
    return float(np.sqrt(np.mean(np.concatenate(residuals) ** 2))) if residuals else float("nan")


def collapse(p0, p0star, logs, n_boot=1000, seed=0):
    """S on the raw and the shifted axis, with bootstrap errors over tissues. ``p0``, ``p0star``:
    per point (N, p0); ``logs`` (n_T, n_points, tissues) of log tau_alpha (NaN: not relaxed)."""
    axes = {"p0": p0, "p0 - p0*(N)": p0 - p0star}
    logs = np.where(np.all(np.isfinite(logs), axis=2, keepdims=True), logs, np.nan)   # a point: all relaxed
    rows, k = usable(p0, logs), logs.shape[2]
    pick = np.random.default_rng(seed).integers(0, k, size=(n_boot,) + logs.shape)
    boot = {name: [] for name in axes}
    for b in range(n_boot):
        sample = np.take_along_axis(logs, pick[b], axis=2)
        for name, x in axes.items():
            boot[name].append(scatter(x, sample, rows))
    se = logs.std(axis=2, ddof=1) / np.sqrt(k) if k > 1 else np.full(logs.shape[:2], np.nan)
    raw, shifted = np.array(boot["p0"]), np.array(boot["p0 - p0*(N)"])
    return dict(temperatures_used=int(rows.sum()), S_raw=scatter(axes["p0"], logs, rows),
                S_raw_err=float(np.nanstd(raw, ddof=1)), S_shifted=scatter(axes["p0 - p0*(N)"], logs, rows),
                S_shifted_err=float(np.nanstd(shifted, ddof=1)), shifted_better=float(np.mean(shifted < raw)),
                noise=float(np.sqrt(np.nanmean(se[rows] ** 2))) if rows.any() else float("nan"))


def main(argv=None):
    ap = argparse.ArgumentParser(allow_abbrev=False, description=__doc__.splitlines()[0])
    ap.add_argument("--full", action="store_true", help=f"one GPU: {PRESETS['full']}")
    ap.add_argument("--cells", type=int, nargs="+")
    ap.add_argument("--p0", type=float, nargs="+")
    ap.add_argument("--T", type=float, nargs="+")
    ap.add_argument("--replicas", type=int, help="tissues per (N, p0, T)")
    ap.add_argument("--p0star", help="a rigidity sweep's p0star.csv (default: the table in docs/results.md)")
    ap.add_argument("--dt", type=float, default=0.05)
    ap.add_argument("--max-time", type=float, help="production cap in time units 1/(mu kP)")
    ap.add_argument("--max-seconds", type=float, default=None, help="wall-time cap of the production")
    ap.add_argument("--relax", type=int, default=5000, help="FIRE iterations at most")
    ap.add_argument("--device", default="auto")
    ap.add_argument("--out", default="curvature_collapse")
    args = ap.parse_args(argv)
    preset = PRESETS["full" if args.full else "small"]
    for key in ("cells", "p0", "T", "replicas", "max_time"):
        if getattr(args, key) is None:
            setattr(args, key, preset[key])
    p0star = read_p0star(args.p0star) if args.p0star else P0STAR
    missing = [n for n in args.cells if n not in p0star]
    if missing:
        raise SystemExit(f"--cells: no p0*(N) for N = {missing} (known: {sorted(p0star)}); give --p0star")
    os.makedirs(args.out, exist_ok=True)
    temps, p0s, reps = np.sort(args.T)[::-1], np.asarray(args.p0, dtype=float), args.replicas
    per_size = len(p0s) * len(temps) * reps
    # replicas ordered (N, p0, T, tissue)
    p0_rep = np.tile(np.repeat(p0s, len(temps) * reps), len(args.cells))
    T_rep = np.tile(np.repeat(temps, reps), len(args.cells) * len(p0s))
    state = State.concatenate([init.random_tiling(n, replicas=per_size, seed=n) for n in args.cells])
    print(f"curvature_collapse: N = {args.cells}, p0 = {p0s.tolist()}, T = {temps.tolist()}, {reps} tissues each "
          f"({state.n_replicas} tissues, {state.n_cells} cells), kr = 0, dt = {args.dt}, cap {args.max_time:g} "
          "time units" + (f" and {args.max_seconds:g} s" if args.max_seconds else ""), flush=True)
    started = time.perf_counter()
    res = glassy_dynamics(None, p0_rep[state.cell_replica_np()], 0.0, T=T_rep, dt=args.dt, seed=1,
                          device=args.device, relax_steps=args.relax, initial_state=state, until_relaxed=True,
                          max_time=args.max_time, max_seconds=args.max_seconds, progress=StageLines("collapse"))
    seconds = time.perf_counter() - started
    print(f"production {res.production_steps * args.dt:g} time units, stopped: {res.stopped}, {seconds:.1f} s",
          flush=True)
    tau = res.tau_alpha_per_replica.reshape(len(args.cells), len(p0s), len(temps), reps)
    logs = np.log(tau).transpose(2, 0, 1, 3).reshape(len(temps), -1, reps)      # (T, (N, p0), tissue)
    points_p0 = np.tile(p0s, len(args.cells))
    points_star = np.repeat([p0star[n] for n in args.cells], len(p0s))
    with open(os.path.join(args.out, "collapse_tau.csv"), "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["N", "p0", "p0_star", "T", "tissue", "tau_alpha"])
        for i, n in enumerate(args.cells):
            for j, p in enumerate(p0s):
                w.writerows((n, p, p0star[n], T, r, tau[i, j, k, r]) for k, T in enumerate(temps) for r in range(reps))
    print(f"\n{'N':>5} {'p0':>6} {'p0-p0*':>7} " + " ".join(f"{'T=' + format(T, 'g'):>14}" for T in temps))
    for i, n in enumerate(args.cells):
        for j, p in enumerate(p0s):
            cells = []
            for k in range(len(temps)):
                t = tau[i, j, k]
                cells.append(f"{np.exp(np.log(t).mean()):>14.4g}" if np.all(np.isfinite(t)) else
                             f"{str(int(np.isfinite(t).sum())) + '/' + str(reps) + ' relaxed':>14}")
            print(f"{n:>5} {p:>6.3f} {p - p0star[n]:>+7.3f} " + " ".join(cells))
    m = collapse(points_p0, points_star, logs)
    m.update(seconds=seconds, stopped=res.stopped, time_run=res.production_steps * args.dt)
    print(f"\ncollapse measure S (RMS of log tau about one quadratic per T, {m['temperatures_used']} temperatures; "
          f"noise of the means {m['noise']:.3g}):\n"
          f"  raw p0:        S = {m['S_raw']:.3g} +- {m['S_raw_err']:.2g}\n"
          f"  p0 - p0*(N):   S = {m['S_shifted']:.3g} +- {m['S_shifted_err']:.2g}\n"
          f"  shifted below raw in {100 * m['shifted_better']:.0f}% of bootstrap resamplings", flush=True)
    with open(os.path.join(args.out, "collapse_measure.csv"), "w", newline="") as f:
        w = csv.DictWriter(f, list(m))
        w.writeheader()
        w.writerow(m)
    plot(args.out, args.cells, p0s, temps, tau, p0star)


def plot(out, cells, p0s, temps, tau, p0star):
    try:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        return
    fig, axes = plt.subplots(1, 2, figsize=(10, 4), sharey=True)
    colors = plt.cm.viridis(np.linspace(0, 0.9, len(cells)))
    markers = "osD^v<>"
    for i, n in enumerate(cells):
        for k, T in enumerate(temps):
            y = np.log(tau[i, :, k]).mean(axis=1)
            for ax, x in zip(axes, (p0s, p0s - p0star[n])):
                ax.plot(x, y, marker=markers[k % len(markers)], color=colors[i], ls="-", lw=0.8,
                        label=f"N={n}" if k == 0 else None)
    axes[0].set_xlabel("p0"), axes[1].set_xlabel("p0 - p0*(N)"), axes[0].set_ylabel("<log tau_alpha>")
    axes[0].legend(fontsize=7, title="markers: T " + ", ".join(f"{T:g}" for T in temps), title_fontsize=7)
    fig.tight_layout()
    fig.savefig(os.path.join(out, "collapse.png"), dpi=120)
    plt.close(fig)


if __name__ == "__main__":
    main()
