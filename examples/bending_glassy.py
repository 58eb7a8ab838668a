"""Glassy dynamics of the spherical vertex model with a bending term (issue 12, the paper's Discussion).

tau_alpha(T) at p0 = 3.775, kr = 0, for B = 0, 0.01, 0.1, 1 (B in units of kP <A>, the energy unit
of the dimensionless model), from ``spherevm.protocols.glassy_dynamics`` with ``Bending(B)`` added.
Each system size runs as one ensemble: every (B, T) pair has its replicas, with per-replica B and
T. Per B: tau_alpha per T (mean and standard error over replicas, in log), the fit
log tau = a + b/T + c/T^2 (c < 0: sub-Arrhenius, c > 0: super-Arrhenius, c = 0: Arrhenius) with
the standard error of c, an Arrhenius plot and the MSD at the lowest T.

    python examples/bending_glassy.py                 # N = 128, minutes on a CPU
    python examples/bending_glassy.py --full          # N = 128 and 1024, more temperatures and steps: one GPU

Progress goes to stdout; the results (``--out``.json, rewritten after each system size) and the
figure (``--out``.png) are written as they come.
"""
from __future__ import annotations

import argparse
import json
import time

import numpy as np

from spherevm.plugins.forces import Bending
from spherevm.progress import StageLines
from spherevm.protocols import glassy_dynamics, inherent_states

SMALL = dict(cells=[128], T=[0.015, 0.02, 0.025, 0.03, 0.04], replicas=2, steps=4000, relax=500, dt=0.05)
# --full at dt = 0.05 stopped at production step 10,618: a step at T = 0.04 exceeded Brownian's
# max_step; at dt = 0.02 so did one with B = 1, T = 0.04 at N = 1024 (after 40,000 steps): the top T is
# 0.03. CUDA graphs make the 2.5x more steps of dt = 0.02 cheap (5,000 time units).
FULL = dict(cells=[128, 1024], T=[0.007, 0.008, 0.01, 0.0125, 0.015, 0.02, 0.025, 0.03], replicas=4,
            steps=250_000, relax=5000, dt=0.02)


def fit_log_tau(T, log_tau, weights=None):
    """Least squares log tau = a + b/T + c/T^2; returns (coefficients, standard errors, residual
    sum of squares of this fit and of the Arrhenius fit c = 0)."""
    x = 1.0 / np.asarray(T, dtype=float)
    y = np.asarray(log_tau, dtype=float)
    w = np.ones_like(y) if weights is None else np.asarray(weights, dtype=float)
    out = {}
    for name, cols in (("quadratic", [np.ones_like(x), x, x * x]), ("arrhenius", [np.ones_like(x), x])):
        A = np.stack(cols, axis=1) * np.sqrt(w)[:, None]
        yw = y * np.sqrt(w)
        coef, *_ = np.linalg.lstsq(A, yw, rcond=None)
        resid = yw - A @ coef
        dof = max(len(y) - A.shape[1], 1)
        s2 = float(resid @ resid) / dof
        cov = s2 * np.linalg.inv(A.T @ A)
        out[name] = dict(coef=coef.tolist(), err=np.sqrt(np.diag(cov)).tolist(), rss=float(resid @ resid), dof=dof)
    return out


def verdict(fit):
    c, dc = fit["quadratic"]["coef"][2], fit["quadratic"]["err"][2]
    if not np.isfinite(dc) or abs(c) < 2 * dc:
        return f"consistent with Arrhenius (c = {c:.3g} +- {dc:.2g}, |c| < 2 sigma)"
    kind = "super-Arrhenius" if c > 0 else "sub-Arrhenius"
    return f"{kind} (c = {c:.3g} +- {dc:.2g}, {abs(c) / dc:.1f} sigma)"


def analyse(n, B, temps, tau, lag, msd, seconds):
    """One row of results: ``tau`` (temperatures, replicas) for one B; ``msd`` (lags, replicas) at the lowest T."""
    reps = tau.shape[1]
    row = dict(N=n, B=B, T=temps.tolist(), tau=tau.tolist(), seconds=seconds)
    ok = np.all(np.isfinite(tau), axis=1)
    logt = np.array([np.log(t).mean() if k else np.nan for t, k in zip(tau, ok)])
    se = np.array([np.log(t).std(ddof=1) / np.sqrt(reps) if k and reps > 1 else np.nan for t, k in zip(tau, ok)])
    row.update(log_tau=logt.tolist(), log_tau_se=se.tolist())
    if ok.sum() >= 4:
        w = 1.0 / np.maximum(np.nan_to_num(se[ok], nan=0.05), 0.05) ** 2
        row["fit"] = fit_log_tau(temps[ok], logt[ok], w)
        row["verdict"] = verdict(row["fit"])
    else:
        row["verdict"] = f"only {int(ok.sum())} temperatures relaxed within the run: no fit"
    row["msd_lowest_T"] = dict(lag=lag.tolist(), msd=msd.mean(axis=1).tolist(), T=float(temps[0]))
    print(f"N={n} B={B:g}: " + "  ".join(
        f"T={t:g}: tau={np.exp(lt):.4g}" + ("" if not np.isfinite(s) else f" (x/ {np.exp(s):.2f})")
        for t, lt, s in zip(temps, logt, se)) + f"\n    {row['verdict']}", flush=True)
    return row


def plot(results, path):
    try:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        return
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(10, 4))
    for row in results:
        T, lt, se = np.array(row["T"]), np.array(row["log_tau"]), np.array(row["log_tau_se"])
        label = f"N={row['N']} B={row['B']:g}"
        line = ax1.errorbar(1 / T, lt, yerr=np.nan_to_num(se), marker="o", ls="", label=label)
        if "fit" in row:
            x = np.linspace((1 / T).min(), (1 / T).max(), 50)
            a, b, c = row["fit"]["quadratic"]["coef"]
            ax1.plot(x, a + b * x + c * x * x, color=line[0].get_color())
        m = row["msd_lowest_T"]
        ax2.loglog(m["lag"][1:], m["msd"][1:], label=f"{label} T={m['T']:g}")
    ax1.set_xlabel("1/T"), ax1.set_ylabel("log tau_alpha"), ax1.legend(fontsize=7)
    ax2.set_xlabel("t"), ax2.set_ylabel("MSD / <A>"), ax2.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def main(argv=None):
    ap = argparse.ArgumentParser(allow_abbrev=False, description=__doc__.splitlines()[0])
    ap.add_argument("--full", action="store_true", help=f"the GPU study: {FULL}")
    ap.add_argument("--cells", type=int, nargs="+", default=None)
    ap.add_argument("--B", type=float, nargs="+", default=[0.0, 0.01, 0.1, 1.0])
    ap.add_argument("--T", type=float, nargs="+", default=None)
    ap.add_argument("--replicas", type=int, default=None, help="replicas per (B, T)")
    ap.add_argument("--steps", type=int, default=None, help="production steps (equilibration: a tenth)")
    ap.add_argument("--dt", type=float, default=None, help="Brownian timestep (preset: 0.05 small, 0.02 --full)")
    ap.add_argument("--relax", type=int, default=None, help="FIRE steps at most before the dynamics")
    ap.add_argument("--device", default="auto")
    ap.add_argument("--out", default="bending_glassy", help="prefix of the JSON results and the figure")
    args = ap.parse_args(argv)
    preset = FULL if args.full else SMALL
    cells = args.cells or preset["cells"]
    temps = np.array(args.T or preset["T"], dtype=float)
    temps.sort()
    reps = args.replicas or preset["replicas"]
    steps = args.steps or preset["steps"]
    relax = args.relax if args.relax is not None else preset["relax"]
    dt = args.dt or preset["dt"]
    Bs = np.array(args.B, dtype=float)
    # replicas ordered (B, T, replica): one ensemble per system size
    B_all, T_all = np.repeat(Bs, len(temps) * reps), np.tile(np.repeat(temps, reps), len(Bs))
    print(f"bending_glassy: N = {cells}, B = {Bs.tolist()}, T = {temps.tolist()}, {reps} replicas per (B, T) "
          f"({len(T_all)} per N), {relax} + {relax} FIRE (without, then with bending) + {steps // 10} + {steps} Brownian steps at dt = {dt}, "
          f"device = {args.device}", flush=True)
    results = []
    for n in cells:
        t0 = time.perf_counter()
        start = inherent_states(n, len(T_all), 3.775, 0.0, steps=relax, seed=12, device=args.device)
        res = glassy_dynamics(None, 3.775, 0.0, T_all, dt=dt, steps=steps, seed=12, initial_state=start,
                              device=args.device, relax_steps=relax, extra_forces=[Bending(B_all)],
                              progress=StageLines(f"N={n}"))
        seconds = time.perf_counter() - t0
        print(f"N={n}: {seconds:.0f} s on {res.simulation.device.name}", flush=True)
        tau = res.tau_alpha_per_replica.reshape(len(Bs), len(temps), reps)
        msd = res.msd_per_replica.reshape(len(res.lag), len(Bs), len(temps), reps)
        for k, B in enumerate(Bs):
            results.append(analyse(n, float(B), temps, tau[k], res.lag, msd[:, k, 0], seconds))
        with open(args.out + ".json", "w") as fh:
            json.dump(results, fh, indent=1)
        plot(results, args.out + ".png")
    print(f"results: {args.out}.json, figure: {args.out}.png")


if __name__ == "__main__":
    main()
