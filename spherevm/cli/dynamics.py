"""``spherevm dynamics``: Brownian dynamics of relaxed tilings; MSD, self-overlap and tau_alpha.
Several values of --cells, --T, --p0 or --bending, or a sweep option (--gpus, --scheduler, ...),
make it a sweep (:mod:`spherevm.cli.dynamics_sweep`)."""
from __future__ import annotations

import os
import sys
import time

import numpy as np

from ..progress import StageBars
from . import dynamics_sweep
from .arguments import (RUNTIME_ERROR, USAGE_ERROR, CLIError, add_force_arguments, add_overwrite, add_surface,
                        add_system_arguments, build_forces, check_existing, check_in_path, check_out_path,
                        extra_forces, integer, one_line, real, resume_hint, settle_restart, shape_index)


def add_parser(subparsers):
    """Register ``dynamics`` on the ``spherevm`` subparsers."""
    d = subparsers.add_parser("dynamics", help="Brownian dynamics: MSD, self-overlap and tau_alpha (the paper's Fig. 3)",
                              description="Relax random tilings with FIRE + T1, equilibrate, then run overdamped "
                                          "Brownian dynamics at temperature T with T1 exchanges; record cell "
                                          "centroids at log-spaced times, and report MSD, self-overlap Q_s and "
                                          "tau_alpha (Q_s = 1/e) in the co-rotating frame.")
    g = d.add_argument_group("system")
    add_system_arguments(g, "independent tissues, averaged", "random seed", many=True)
    g.add_argument("--p0", type=shape_index(), default=[3.775], metavar="P", nargs="+",
                   help="target shape index, in [0, 100] (default: 3.775)")
    g.add_argument("--kr", type=real(), default=0.0, metavar="K", help="area stiffness (default: %(default)s)")
    add_surface(g, restart=True)
    add_force_arguments(g, many=True)
    g = d.add_argument_group("dynamics")
    g.add_argument("--T", "-T", dest="T", type=real(), default=[0.01], nargs="+",
                   help="temperature, >= 0 (default: 0.01)")
    g.add_argument("--dt", type=real(strict=True), default=0.05, help="time step, > 0 (default: %(default)s)")
    g.add_argument("--steps", type=integer(1), default=5000, help="production steps (default: %(default)s)")
    g.add_argument("--equilibrate", type=integer(0), default=None, metavar="STEPS",
                   help="equilibration steps before production (default: steps/10)")
    g.add_argument("--relax", type=integer(0), default=5000, metavar="STEPS",
                   help="FIRE steps of the initial relaxation, 0 to skip (default: %(default)s)")
    g.add_argument("--b", type=real(strict=True), default=0.5, help="self-overlap window, sqrt(<A>) (default: %(default)s)")
    g = d.add_argument_group("output")
    g.add_argument("--out", "-o", default=None, metavar="FILE.gsd",
                   help="GSD trajectory of the production run; the --restart file itself is appended to "
                        "(a sweep: the output folder)")
    g.add_argument("--restart", default=None, metavar="FILE.gsd",
                   help="continue from the last frame of a spherevm GSD file (its state and timestep); "
                        "skips relaxation and equilibration; the file gives --cells, --replicas, --surface and --seed "
                        "(a contradicting value is refused; another --seed wins, with a note)")
    g.add_argument("--csv", default=None, metavar="FILE.csv", help="time, MSD and Q_s (default: next to --out, else none)")
    add_overwrite(g)
    g.add_argument("--device", choices=("cpu", "gpu", "auto"), default="auto", help="where to run (default: %(default)s)")
    g.add_argument("--quiet", "-q", action="store_true", help="no progress on standard error")
    dynamics_sweep.add_sweep_arguments(d)
    d.set_defaults(func=run)
    return d


def run(args) -> int:
    """The handler of ``spherevm dynamics``: one run, or a sweep (:func:`dynamics_sweep.is_sweep`)."""
    from ..protocols import glassy_dynamics
    if dynamics_sweep.is_sweep(args):
        return dynamics_sweep.run(args)
    for name in ("cells", "T", "p0", "bending"):         # one value each: a single run
        value = getattr(args, name)
        setattr(args, name, None if value is None else value[0])
    for path, flag in ((args.out, "--out"), (args.csv, "--csv")):
        if path is not None:
            check_out_path(path, flag)
    if args.restart is not None:
        check_in_path(args.restart, "--restart")
    settle_restart(args)
    specs = extra_forces(args)
    csv_path = args.csv or (os.path.splitext(args.out)[0] + ".csv" if args.out else None)
    for path, flag in ((args.out, "--out"), (csv_path, "--csv")):
        check_existing(path, flag, args.overwrite, args.restart)
    err = sys.stderr
    if not args.quiet:
        err.write(f"spherevm: dynamics of {args.replicas} x {args.cells} cells on the {args.surface}, p0={args.p0:g} kr={args.kr:g} "
                  f"T={args.T:g} dt={args.dt:g}, {args.steps} steps\n")
    t0 = time.perf_counter()
    try:
        with StageBars(stream=err, enabled=False if args.quiet else None) as bars:
            res = glassy_dynamics(args.cells, args.p0, args.kr, args.T, dt=args.dt, steps=args.steps,
                                  replicas=args.replicas, seed=args.seed, device=args.device,
                                  relax_steps=args.relax, surface=args.surface, restart=args.restart,
                                  equilibrate_steps=args.equilibrate, b=args.b, out=args.out,
                                  extra_forces=build_forces(specs), progress=bars)
    except KeyboardInterrupt as stop:   # the production frames written so far are readable
        stop.resume_hint = resume_hint("dynamics", args.out)
        raise
    except (ValueError, TypeError) as exc:
        raise CLIError(one_line(exc), USAGE_ERROR) from exc
    except Exception as exc:
        raise CLIError(f"dynamics failed: {one_line(exc)}", RUNTIME_ERROR) from exc
    if csv_path:
        res.write_csv(csv_path)
    print(f"{'time':>12} {'MSD':>12} {'Q_s':>8}")
    for t, m, q in zip(res.lag, res.msd, res.self_overlap):
        print(f"{t:12.5g} {m:12.5g} {q:8.4f}")
    tau = "not reached (Q_s stays above 1/e: run longer)" if not np.isfinite(res.tau_alpha) else f"{res.tau_alpha:.5g}"
    print(f"tau_alpha = {tau}")
    if not args.quiet:
        err.write(f"spherevm: done in {time.perf_counter() - t0:.1f} s"
                  f"{'' if csv_path is None else f'; wrote {csv_path}'}{'' if args.out is None else f' and {args.out}'}\n")
        if args.out is not None:
            err.write(f"spherevm: {args.out}'s first frame is step {res.production_start}, the start of production "
                      "(after relaxation and equilibration); lags count from it\n")
    return 0
