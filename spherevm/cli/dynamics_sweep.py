"""``spherevm dynamics`` as a sweep (:class:`spherevm.sweeps.DynamicsSweep`): several sizes,
temperatures, p0 or B values, or ``--gpus`` / ``--scheduler``; resumable, on this machine or a Dask
cluster; prints tau_alpha per point and writes the tables to the ``--out`` folder."""
from __future__ import annotations

import os
import sys

from .arguments import SYSTEM_DEFAULTS, CLIError, extra_forces, integer, run_sweep_command

#: the ``spherevm dynamics`` options that make it a sweep (besides a list of several values)
SWEEP_OPTIONS = ("gpus", "scheduler", "workers", "chunk_replicas", "sweep")
#: the options of a single run that a sweep has no use for
SINGLE_ONLY = (("restart", "--restart"), ("csv", "--csv"))


def add_sweep_arguments(parser):
    """The ``sweep`` option group of ``spherevm dynamics``."""
    g = parser.add_argument_group(
        "sweep", "several values of --cells, --T, --p0 or --bending, or any option below, make the command a "
                 "sweep over every combination: --out is then a folder (rerun the command to resume it)")
    g.add_argument("--sweep", action="store_true", help="a sweep even with one value of each (--out FOLDER)")
    g.add_argument("--chunk-replicas", type=integer(1), default=None, metavar="R",
                   help="tissues per chunk, one batched run (default: all --replicas of a point); part of the "
                        "sweep: the noise of a tissue depends on its place in its chunk")
    g.add_argument("--workers", "-j", type=integer(1), default=None,
                   help="processes on the CPU (default: all cores)")
    g.add_argument("--scheduler", default=None, metavar="ADDRESS",
                   help="run the chunks on a Dask cluster (needs spherevm[cluster]): a scheduler address "
                        "such as tcp://host:8786, or 'local' for a LocalCluster on this machine")
    g.add_argument("--gpus", type=integer(1), default=None, metavar="N",
                   help="one Dask worker per GPU of this host, GPUs 0..N-1 (needs spherevm[cluster-cuda])")


def is_sweep(args) -> bool:
    """Whether the ``spherevm dynamics`` arguments ask for a sweep."""
    lists = (args.cells, args.T, args.p0, args.bending)
    return any(getattr(args, name) for name in SWEEP_OPTIONS) or any(v is not None and len(v) > 1 for v in lists)


def sweep_from_args(args):
    """The DynamicsSweep that ``spherevm dynamics`` sweep arguments describe (CLIError on bad input)."""
    from ..sweeps import DynamicsSweep
    for name, flag in SINGLE_ONLY:
        if getattr(args, name) is not None:
            raise CLIError(f"argument {flag}: belongs to a single run; a sweep resumes when the command is rerun "
                           "with the same --out FOLDER")
    if not args.out:
        raise CLIError("argument --out: a dynamics sweep writes its tables to a folder; give --out FOLDER")
    bending, args.bending = args.bending or [0.0], None
    forces = extra_forces(args)
    if any(name == "bending" for name, _ in forces):
        raise CLIError("argument --force: give bending moduli with --bending B [B ...] in a sweep")
    try:
        given = {name: getattr(args, name) for name in SYSTEM_DEFAULTS}
        cells, replicas, seed, surface = (SYSTEM_DEFAULTS[k] if v is None else v for k, v in given.items())
        return DynamicsSweep(cells=cells, T=args.T, p0=args.p0, B=bending, replicas=replicas,
                             kr=args.kr, seed=seed, chunk_replicas=args.chunk_replicas, dt=args.dt,
                             steps=args.steps, equilibrate_steps=args.equilibrate, relax_steps=args.relax, b=args.b,
                             surface=surface, forces=tuple(forces))
    except (ValueError, TypeError) as exc:
        raise CLIError(str(exc)) from exc


def run(args) -> int:
    """``spherevm dynamics`` as a sweep."""
    from ..sweeps import format_tau_table, write_dynamics_tables
    sweep = sweep_from_args(args)
    result = run_sweep_command(
        args, sweep, f"dynamics sweep on the {sweep.surface} of N = {list(sweep.cells)}, T = {list(sweep.T)}, "
                     f"p0 = {list(sweep.p0)}, B = {list(sweep.B)}, {sweep.replicas} tissues per point, {sweep.steps} "
                     f"steps: {sweep.total_units} tissues", "dynamics", "tissues")
    tables = write_dynamics_tables(args.out, result.records)
    print(format_tau_table(tables["tau_alpha"]))
    if not args.quiet:
        sys.stderr.write(f"spherevm: {len(result.computed)} chunk(s) computed, {result.reused} found on disk, "
                         f"{result.elapsed:.1f} s; wrote {', '.join(os.path.basename(f) for f in tables['files'])} "
                         f"to {args.out}\n")
    return 0
