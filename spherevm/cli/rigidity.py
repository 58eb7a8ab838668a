"""``spherevm rigidity``: a rigidity sweep (:mod:`spherevm.sweeps`) from the shell, resumable,
on this machine or a Dask cluster; prints p0*(N) and writes the tables and plots."""
from __future__ import annotations

import os
import sys

from ..sweeps import (CPU_BATCH_CELLS, GPU_BATCH_CELLS, STATE_DIR, RigiditySweep, format_p0star_table, parse_p0_grid,
                      write_tables)
from .arguments import add_force_arguments, add_surface, extra_forces, integer, real, run_sweep_command

DEFAULT_CELLS = (16, 32)
DEFAULT_P0 = "3.5:4.0:0.025"
DEFAULT_REPLICAS = 12


def add_parser(subparsers):
    """Register ``rigidity`` on the ``spherevm`` subparsers."""
    r = subparsers.add_parser(
        "rigidity", help="sweep p0 and N: F(p0, N), p0* distributions and p0*(N) (Fig. 2 and 4)",
        description="Minimise REPLICAS random tilings at every (N, p0) with FIRE and T1s, classify every "
                    "inherent state as zero energy or rigid, and write F(p0, N), the distributions of p0* "
                    "and p0*(N) beside the regular-pentagon bound (CSV, and PNG with matplotlib) to --out. "
                    "Chunks are saved as they finish: rerun the same command to resume. The default sweep "
                    "takes under a minute on a 2-core laptop. See docs/rigidity.md.")
    g = r.add_argument_group("sweep")
    g.add_argument("--cells", "-N", type=integer(4), nargs="+", default=list(DEFAULT_CELLS), metavar="N",
                   help="system sizes, cells per tiling (default: %(default)s)")
    g.add_argument("--p0", nargs="+", default=[DEFAULT_P0], metavar="P0",
                   help="p0 values and/or START:STOP:STEP ranges, end included (default: %(default)s)")
    g.add_argument("--replicas", "-R", type=integer(1), default=DEFAULT_REPLICAS,
                   help="random tilings per (N, p0) (default: %(default)s)")
    g.add_argument("--kr", type=real(), default=0.0, help="area stiffness kA <A>/kP (default: %(default)s)")
    add_force_arguments(g)
    g.add_argument("--seed", type=integer(0), default=0, help="random seed (default: %(default)s)")
    add_surface(g)
    g.add_argument("--shared-tilings", action="store_true",
                   help="use the same tilings at every p0 (default: independent tilings per p0)")
    g = r.add_argument_group("minimiser")
    g.add_argument("--dt", type=real(strict=True), default=RigiditySweep.dt,
                   help="FIRE time step (default: %(default)s)")
    g.add_argument("--force-tol", type=real(), default=RigiditySweep.force_tol,
                   help="stop a replica when its largest vertex force is below this, in units of kP sqrt(<A>) "
                        "(default: %(default)s)")
    g.add_argument("--energy-tol", type=real(), default=RigiditySweep.energy_tol,
                   help="... or its energy per cell below this, in units of kP <A> (default: %(default)s)")
    g.add_argument("--max-steps", type=integer(1), default=RigiditySweep.max_steps,
                   help="step limit; replicas reaching it are reported as not converged (default: %(default)s)")
    g.add_argument("--t1", type=real(strict=True), default=RigiditySweep.t1_threshold, metavar="THRESHOLD",
                   help="T1 edge-length threshold in sqrt(<A>), new edges 3 x as long (default: %(default)s)")
    g.add_argument("--t1-reference", action="store_true",
                   help="the paper code's T1 rule instead: threshold 0.1, new edge twice the old length "
                        "(more floppy states near the transition: p0* lower by ~0.02 at N = 32)")
    g.add_argument("--max-flip-backs", type=integer(1), default=RigiditySweep.t1_max_flip_backs,
                   help="stop a replica as 't1_oscillation' after this many re-joins of one cell pair "
                        "(default: %(default)s)")
    g = r.add_argument_group("analysis")
    g.add_argument("--zero-tol", type=real(strict=True), default=None,
                   help="energy per cell below which a state counts as zero energy (default: 1e-12)")
    g.add_argument("--exclude-inverted", action="store_true",
                   help="leave tissues that end with inverted cells (signed area <= 0) out of F(p0), counted in "
                        "fraction.csv's n_other (docs/surfaces.md, Rigidity sweeps on tori)")
    g.add_argument("--sigma", type=real(strict=True), default=None,
                   help="Gaussian width for dF/dp0 (default: half the measured width of the transition, "
                        "at least half the p0 spacing)")
    g = r.add_argument_group("running")
    g.add_argument("--out", "-o", default="sweep", metavar="FOLDER",
                   help="output folder; an existing sweep folder is resumed (default: %(default)s)")
    g.add_argument("--device", choices=("cpu", "gpu", "auto"), default="auto",
                   help="auto takes the GPU when CuPy sees one (default: %(default)s)")
    g.add_argument("--workers", "-j", type=integer(1), default=None,
                   help="processes on the CPU (default: all cores)")
    g.add_argument("--batch-cells", type=integer(1), default=None,
                   help=f"cells per batched chunk (default: {CPU_BATCH_CELLS} on the CPU, {GPU_BATCH_CELLS} on a GPU)")
    g.add_argument("--scheduler", default=None, metavar="ADDRESS",
                   help="run the chunks on a Dask cluster (needs spherevm[cluster]): a scheduler address "
                        "such as tcp://host:8786, or 'local' for a LocalCluster on this machine")
    g.add_argument("--gpus", type=integer(1), default=None, metavar="N",
                   help="one Dask worker per GPU of this host, GPUs 0..N-1 (needs spherevm[cluster-cuda])")
    g.add_argument("--no-plots", action="store_true", help="write the CSV tables only")
    g.add_argument("--save-states", action="store_true",
                   help="also keep every chunk's minimised states (the inherent states) as GSD files in "
                        "OUT/states/; open one with spherevm.sweeps.load_state (docs/rigidity.md)")
    g.add_argument("--quiet", "-q", action="store_true", help="no progress bar or notes on standard error")
    r.set_defaults(func=run)
    return r


def sweep_from_args(args) -> RigiditySweep:
    """The RigiditySweep that ``spherevm rigidity`` arguments describe (ValueError on bad input)."""
    t1 = {"t1_threshold": args.t1, "t1_new_length": 3.0 * args.t1}
    if args.t1_reference:
        t1 = RigiditySweep.reference_t1()
    return RigiditySweep(cells=args.cells, p0=parse_p0_grid(args.p0), replicas=args.replicas, kr=args.kr,
                         seed=args.seed, shared_tilings=args.shared_tilings, dt=args.dt, force_tol=args.force_tol,
                         energy_tol=args.energy_tol, max_steps=args.max_steps, t1_max_flip_backs=args.max_flip_backs,
                         surface=getattr(args, "surface", "sphere"), forces=tuple(extra_forces(args)),
                         **t1)


def run(args) -> int:
    """The handler of ``spherevm rigidity``."""
    err = sys.stderr
    sweep = sweep_from_args(args)
    result = run_sweep_command(
        args, sweep, f"rigidity sweep on the {sweep.surface} of N = {list(sweep.cells)}, {len(sweep.p0)} p0 values "
                     f"({sweep.p0[0]:g}..{sweep.p0[-1]:g}), {sweep.replicas} replicas, kr = {sweep.kr:g}: "
                     f"{sweep.total_units} minimisations", "rigidity", "minimisations",
        batch_cells=args.batch_cells, save_states=args.save_states)
    tables = write_tables(args.out, result.records, zero_tol=args.zero_tol, plots=not args.no_plots,
                          sigma=args.sigma, surface=sweep.surface, exclude_inverted=args.exclude_inverted)
    print(format_p0star_table(tables["p0star"]))
    if not args.quiet:
        frac = tables["fractions"]
        n_max, n_osc = int(frac["n_max_steps"].sum()), int(frac["n_t1_oscillation"].sum())
        err.write(f"spherevm: {len(result.computed)} chunk(s) computed, {result.reused} found on disk, "
                  f"{result.elapsed:.1f} s; not converged: {n_max} max_steps, {n_osc} t1_oscillation "
                  f"(left out of F, counted in fraction.csv)\n")
        inverted = sum(int(c) > 0 for c in result.records["inverted_cells"])
        if inverted:
            how = ("left out of F (--exclude-inverted)" if args.exclude_inverted else
                   "classified by their energy as any other (--exclude-inverted leaves them out of F)")
            err.write(f"spherevm: note: {inverted} replica(s) end with inverted cells (signed area <= 0: "
                      f"inverted_cells in replicas.csv), {how}; see docs/surfaces.md, Rigidity sweeps on tori\n")
        if len(sweep.p0) < 2:
            err.write("spherevm: note: one p0 value: F(p0, N) is in fraction.csv, but p0* needs F at two or more "
                      "p0 values (give a range such as --p0 3.6:4.0:0.02)\n")
        elif not all(tables["p0star"]["bracketed"]):
            err.write("spherevm: note: for some N, F does not go from 0 to 1 inside the p0 grid; widen --p0\n")
        if tables["plot_note"]:
            err.write(f"spherevm: note: {tables['plot_note']}\n")
        err.write(f"spherevm: wrote {', '.join(os.path.basename(f) for f in tables['files'])} to {args.out}\n")
        if args.save_states:
            err.write(f"spherevm: the inherent states are in {os.path.join(args.out, STATE_DIR)} (one GSD file per "
                      "chunk; spherevm.sweeps.load_state opens one)\n")
    return 0
