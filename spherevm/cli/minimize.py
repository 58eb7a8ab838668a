"""``spherevm minimize``: FIRE minimisation of an ensemble of random tilings, one row per replica."""
from __future__ import annotations

import sys
import time

from ..progress import MinimizeBar
from .arguments import (RUNTIME_ERROR, USAGE_ERROR, CLIError, add_force_arguments, add_overwrite, add_surface,
                        add_system_arguments, build_forces, check_existing, check_in_path, check_out_path,
                        extra_forces, gsd_frames, integer, one_line, real, resume_hint, settle_restart,
                        shape_index)


def add_parser(subparsers):
    """Register ``minimize`` on the ``spherevm`` subparsers."""
    m = subparsers.add_parser("minimize", help="minimise an ensemble of random tilings with FIRE",
                              description="Minimise R random tilings of N cells with the vertex model "
                                          "E/(kP <A>) = sum kr (a - 1)^2 + (p - p0)^2 and print one row per "
                                          "replica. Progress goes to standard error, the table to standard output.")
    g = m.add_argument_group("system")
    add_system_arguments(g, "independent tilings, minimised together", "random seed of the tilings")
    g.add_argument("--p0", type=shape_index(), default=3.8, metavar="P",
                   help="target shape index p0 = P0/sqrt(<A>), in [0, 100] (default: %(default)s)")
    g.add_argument("--kr", type=real(), default=1.0, metavar="K",
                   help="area stiffness kr = kA <A>/kP, >= 0 (default: %(default)s)")
    g.add_argument("--t1", type=real(strict=True), default=0.04, metavar="THRESHOLD",
                   help="T1 neighbour exchanges of edges shorter than THRESHOLD (units of sqrt(<A>)), "
                        "new edges 3 x THRESHOLD long (default: %(default)s)")
    g.add_argument("--no-t1", dest="t1", action="store_const", const=None,
                   help="no T1 exchanges (edges may then collapse and stall the minimisation)")
    add_surface(g, restart=True)
    add_force_arguments(g)
    g = m.add_argument_group("minimiser")
    g.add_argument("--dt", type=real(strict=True), default=0.02, help="FIRE time step, > 0 (default: %(default)s)")
    g.add_argument("--force-tol", type=real(), default=1e-8,
                   help="a replica converges when its largest vertex force is below this, in units of "
                        "kP sqrt(<A>) (default: %(default)s)")
    g.add_argument("--energy-tol", type=real(), default=1e-14,
                   help="... or its energy per cell below this, in units of kP <A> (default: %(default)s)")
    g.add_argument("--max-steps", type=integer(0), default=20000, help="step limit (default: %(default)s)")
    g.add_argument("--check-every", type=integer(1), default=10,
                   help="steps between convergence checks and progress updates (default: %(default)s)")
    g = m.add_argument_group("output")
    g.add_argument("--out", "-o", default=None, metavar="FILE.gsd",
                   help="write a GSD trajectory (first frame, every --write-every steps, last frame); the --restart "
                        "file itself is appended to")
    add_overwrite(g)
    g.add_argument("--restart", default=None, metavar="FILE.gsd",
                   help="continue from the last frame of a spherevm GSD file: its state, timestep and FIRE state "
                        "(velocities, dt, alpha, convergence); FIRE goes on (resume) unless --fresh-fire; "
                        "the file gives --cells, --replicas, --surface and --seed (a contradicting value is "
                        "refused; another --seed wins, with a note)")
    g.add_argument("--fresh-fire", action="store_true",
                   help="with --restart: start FIRE afresh from the restored state instead of continuing it")
    g.add_argument("--write-every", type=integer(0), default=1000, metavar="STEPS",
                   help="frame period of --out; 0 writes the first and last frames only (default: %(default)s)")
    g.add_argument("--device", choices=("cpu", "gpu", "auto"), default="auto",
                   help="where to run; auto takes the GPU when CuPy sees one (default: %(default)s)")
    g.add_argument("--quiet", "-q", action="store_true", help="no progress or summary on standard error")
    m.set_defaults(func=run)
    return m


def _format_table(result) -> str:
    cols = ("replica", "energy/cell", "<P/sqrt(A)>", "max|F|", "converged", "reason", "steps")
    rows = []
    for r in range(len(result.converged)):
        rows.append((str(r), f"{result.energy_per_cell[r]:.6e}", f"{result.mean_shape_index[r]:.6f}",
                     f"{result.max_force[r]:.3e}", "yes" if result.converged[r] else "no",
                     str(result.reason[r]), str(int(result.steps[r]))))
    widths = [max(len(c), *(len(row[i]) for row in rows)) for i, c in enumerate(cols)]
    left = {4, 5}  # text columns
    def fmt(row):
        return "  ".join(v.ljust(w) if i in left else v.rjust(w) for i, (v, w) in enumerate(zip(row, widths))).rstrip()
    return "\n".join([fmt(cols)] + [fmt(row) for row in rows])


def run(args) -> int:
    """The handler of ``spherevm minimize``."""
    import spherevm as svm
    from ..trigger import On, Periodic

    if args.restart is not None:
        check_in_path(args.restart, "--restart")
    settle_restart(args)
    if args.out is not None:
        check_out_path(args.out)
        check_existing(args.out, "--out", args.overwrite, args.restart)
        import importlib.util
        if importlib.util.find_spec("gsd") is None:  # the GSD writer needs it: fail before any work
            raise CLIError("argument --out: writing GSD files needs the 'gsd' package (pip install gsd)")
    specs = extra_forces(args)
    err = sys.stderr
    # set-up: anything the library refuses here is bad input (status 2)
    try:
        device = svm.device.resolve(args.device)
        sim = svm.Simulation(device=device, seed=args.seed)
        if args.restart is None:
            svm.validation.check_run_memory(f"minimize --cells {args.cells} --replicas {args.replicas}",
                                            args.cells * args.replicas, args.cells, gpu=device.is_gpu)
            sim.state = svm.init.tilings_on(args.surface, args.cells, [(args.seed, r) for r in range(args.replicas)],
                                            device=device)
        else:
            sim.create_state_from_gsd(args.restart)
        sim.operations.forces.append(svm.plugins.forces.VertexModel.dimensionless(kr=args.kr, p0=args.p0))
        sim.operations.forces.extend(build_forces(specs))
        if args.t1 is not None:
            sim.operations.updaters.append(svm.plugins.updaters.T1(threshold=args.t1, new_length=3.0 * args.t1))
        sim.operations.integrator = svm.plugins.integrators.FIRE(dt=args.dt)
        writer = None
        if args.out is not None:
            trigger = Periodic(args.write_every) if args.write_every > 0 else On(0)
            writer = svm.plugins.writers.GSD(trigger, args.out)
            sim.operations.writers.append(writer)
    except (ValueError, TypeError, RuntimeError, OSError) as exc:
        raise CLIError(one_line(exc), USAGE_ERROR) from exc

    if not args.quiet:
        err.write(f"spherevm: minimizing {args.replicas} replica(s) of {args.cells} cells on the {args.surface}, p0={args.p0:g} "
                  f"kr={args.kr:g}{'' if args.t1 is None else f' t1={args.t1:g}'} on {device.name}"
                  f"{'' if args.out is None else f', writing {args.out}'}\n")
        err.flush()
    progress = MinimizeBar(sim, stream=err, enabled=False if args.quiet else None)
    t0 = time.perf_counter()
    # the run: a failure here is a runtime failure (status 1)
    try:
        try:
            result = sim.minimize(force_tol=args.force_tol, energy_tol=args.energy_tol,
                                  max_steps=args.max_steps, check_every=args.check_every, progress=progress,
                                  resume=args.restart is not None and not args.fresh_fire)
        finally:
            progress.close()
        if writer is not None:   # the writer wrote the last frame itself (GSD(final=True))
            writer.close()
    except KeyboardInterrupt as stop:   # every frame written so far is readable: say how to go on
        if writer is not None:
            writer.close()
        stop.resume_hint = resume_hint("minimize", args.out)
        raise
    except Exception as exc:
        raise CLIError(f"minimization failed at step {sim.timestep}: {one_line(exc)}", RUNTIME_ERROR) from exc
    finally:  # also on Ctrl-C: every frame written so far stays readable
        if writer is not None:
            try:
                writer.close()
            except Exception:
                pass
    elapsed = time.perf_counter() - t0

    print(_format_table(result), file=sys.stdout)
    sys.stdout.flush()
    if not args.quiet:
        n_conv = int(result.converged.sum())
        msg = (f"spherevm: {n_conv}/{len(result.converged)} replica(s) converged in {sim.timestep} steps, "
               f"{elapsed:.2f} s on {device.name}")
        if writer is not None:
            frames = gsd_frames(args.out)[0]
            msg += f"; wrote {args.out}" + ("" if frames is None else f" ({frames} frame{'s' * (frames != 1)})")
        err.write(msg + "\n")
    return 0
