"""What the subcommands share: exit codes, :class:`CLIError`, and argparse types that wrap the
library's own checks (:mod:`spherevm.validation`), so a flag and its Python parameter accept the
same values and a bad value is reported as ``argument --flag: must be <range>, got '<text>'``."""
from __future__ import annotations

import argparse
import os
import sys
import warnings

import numpy as np

from .. import validation
from ..runs import CheckpointMismatchWarning

USAGE_ERROR = 2     # bad arguments or bad input
RUNTIME_ERROR = 1   # something failed while running


class CLIError(Exception):
    """A failure to report as one line, ``spherevm: error: <message>``, with an exit status."""

    def __init__(self, message, code=USAGE_ERROR):
        super().__init__(message)
        self.message = message
        self.code = code


def one_line(exc) -> str:
    """An exception's message on one line (its type name when it has none)."""
    text = " ".join(part.strip() for part in str(exc).splitlines() if part.strip())
    return text or type(exc).__name__


def _argument_type(convert, validate, **bounds):
    def parse(text):
        try:
            value = convert(text)
        except ValueError:
            value = text            # not a number: the validator rejects it, saying what is allowed
        try:
            return validate("value", value, **bounds)
        except validation.ParameterError as exc:
            raise argparse.ArgumentTypeError(f"must be {exc.allowed}, got {text!r}") from None
    return parse


def integer(minimum=0):
    """argparse type: an integer >= ``minimum`` (:func:`spherevm.validation.integer`)."""
    return _argument_type(int, validation.integer, minimum=minimum)


def real(strict=False, maximum=None):
    """argparse type: a finite number >= 0, > 0 with ``strict``, at most ``maximum`` if given
    (:func:`spherevm.validation.real`)."""
    return _argument_type(float, validation.real, strict=strict, maximum=maximum)


def shape_index():
    """argparse type of ``--p0``: a target shape index in [0, 100] (``validation.SHAPE_INDEX_MAX``)."""
    return real(maximum=validation.SHAPE_INDEX_MAX)


def check_out_path(path, flag="--out"):
    """Fail early (before any work, status 2) when the file ``path`` cannot be written; ``flag``
    names the argument in the message."""
    if not path:
        raise CLIError(f"argument {flag}: expected a file name, got ''")
    full = os.path.abspath(path)
    if os.path.isdir(full):
        raise CLIError(f"argument {flag}: {path!r} is a directory; give a file name such as "
                       f"{'run.csv' if flag == '--csv' else 'run.gsd'}")
    folder = os.path.dirname(full)
    if not os.path.isdir(folder):
        raise CLIError(f"argument {flag}: folder {folder!r} does not exist; create it first")
    if not os.access(folder, os.W_OK | os.X_OK) or (os.path.exists(full) and not os.access(full, os.W_OK)):
        raise CLIError(f"argument {flag}: cannot write {path!r} (permission denied)")
    existed = os.path.exists(full)
    try:   # os.access says yes for root on read-only or virtual file systems (/proc): try it
        with open(full, "ab"):
            pass
    except OSError as exc:
        raise CLIError(f"argument {flag}: cannot write {path!r} ({exc.strerror or exc})") from None
    if not existed:
        try:
            os.remove(full)
        except OSError:
            pass


def add_overwrite(group):
    """``--overwrite``: replace output files that exist (see :func:`check_existing`)."""
    group.add_argument("--overwrite", action="store_true",
                       help="replace output files that exist (without it they are refused); the --restart file "
                            "itself is never replaced: a run that writes to it appends")


def check_existing(path, flag, overwrite, restart=None):
    """Refuse (status 2) to write over the existing file ``path`` without ``--overwrite``; the file
    ``restart`` that the run reads is never refused nor replaced (the GSD writer appends to it)."""
    if path is None or not os.path.exists(path):
        return
    if restart is not None and os.path.exists(restart) and os.path.samefile(path, restart):
        return
    if not overwrite:
        raise CLIError(f"argument {flag}: {path!r} exists; give --overwrite to replace it, or another file name")


def check_in_path(path, flag):
    """Fail early (status 2) when the file ``path`` cannot be read."""
    if not path or not os.path.isfile(path):
        what = "is a directory" if path and os.path.isdir(path) else "does not exist"
        raise CLIError(f"argument {flag}: {path!r} {what}; give an existing spherevm GSD file")
    if not os.access(path, os.R_OK):
        raise CLIError(f"argument {flag}: cannot read {path!r} (permission denied)")


# ---------------------------------------------------------------------------------------- frames
CELL_QUANTITIES = ("shape_index", "area", "perimeter", "energy")


def add_frame_arguments(parser, replica_default, replica_help):
    """What ``export`` and ``render`` share: the GSD file, ``--frame``, ``--quantity``, ``--cmap``
    and ``--replica`` (its default and help differ: all replicas or one)."""
    parser.add_argument("file", help="a GSD trajectory written by spherevm")
    parser.add_argument("--frame", type=int, default=-1, help="frame index, negative from the end (default -1)")
    parser.add_argument("--quantity", default="shape_index", choices=CELL_QUANTITIES,
                        help="per-cell quantity that colours the cells (default shape_index)")
    parser.add_argument("--cmap", default="viridis", help="matplotlib colour map (default viridis)")
    parser.add_argument("--replica", type=integer(0), default=replica_default, help=replica_help)


# ---------------------------------------------------------------------------------------- surface
def surface_spec(text: str) -> str:
    """An argparse type: a ``--surface`` spec (:func:`spherevm.init.check_surface_spec`)."""
    from ..init import check_surface_spec
    try:
        return check_surface_spec(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


#: the ``--surface`` of a file's constraint (by its ``name``), for ``--restart``
SURFACE_OF_CONSTRAINT = {"sphere": "sphere", "periodic_plane": "plane"}


def add_surface(group, what="tilings", restart=False):
    """``--surface SPEC``: random tilings of the sphere (radius sqrt(N/4 pi)), of the periodic plane
    (square box of side sqrt(N)) or of an implicit surface (``torus:R=3,r=1``, ``ellipsoid:a=1,b=1,c=2``,
    ``bump:height=1,width=1,box=10`` or a registered one, its shape scaled); <A> = 1 on all.
    ``restart``: the command has ``--restart``, whose file decides (the default is then None, see
    :func:`settle_restart`)."""
    default = "sphere; with --restart, the file's" if restart else "sphere"
    group.add_argument("--surface", type=surface_spec, default=None if restart else "sphere", metavar="SURFACE",
                       help=f"{what} on the sphere (radius sqrt(N/4 pi)), the periodic plane (square box of side "
                            "sqrt(N), N >= 8) or an implicit surface scaled to <A> = 1: torus:R=3,r=1, "
                            f"ellipsoid:a=1,b=1.5,c=2, bump:height=1,width=1,box=10 (default: {default})")


# ---------------------------------------------------------------------------------------- restart
#: what ``minimize`` and ``dynamics`` take when neither the command line nor a --restart file says
SYSTEM_DEFAULTS = {"cells": 64, "replicas": 4, "seed": 0, "surface": "sphere"}
SEED_WARNING = r".*the checkpoint was written by a Simulation with seed"


def add_system_arguments(group, replicas_help, seed_help, many=False):
    """``--cells``, ``--replicas`` and ``--seed`` of a command with ``--restart``: None unless given
    (:func:`settle_restart` fills them in from :data:`SYSTEM_DEFAULTS` or the file). ``many``:
    ``--cells`` takes one or more sizes (a list)."""
    def default(name):
        return f"(default: {SYSTEM_DEFAULTS[name]}; with --restart, the file's)"
    group.add_argument("--cells", "-N", type=integer(4), default=None, metavar="N", nargs="+" if many else None,
                       help=f"cells per replica, >= 4 {default('cells')}")
    group.add_argument("--replicas", "-R", type=integer(1), default=None, metavar="R",
                       help=f"{replicas_help} {default('replicas')}")
    group.add_argument("--seed", type=integer(0), default=None, help=f"{seed_help} {default('seed')}")


def _same_surface(spec, constraint) -> bool:
    """Whether the ``--surface`` spec names the file's surface (its shape; the file's size wins)."""
    from ..constraints.registry import surface
    return repr(surface(spec)) == repr(constraint)


def settle_restart(args):
    """Fill in ``--cells``, ``--replicas``, ``--surface`` and ``--seed`` (None when not given):
    :data:`SYSTEM_DEFAULTS` without ``--restart``; with it, the file's tissue and seed. A
    ``--cells``, ``--replicas`` or ``--surface`` that contradicts the file is refused (CLIError
    naming both flags); a ``--seed`` other than the file's wins, with a one-line note (none under
    ``--quiet``) instead of the library's warning."""
    given = {name: getattr(args, name) for name in SYSTEM_DEFAULTS}
    if args.restart is None:
        for name, value in SYSTEM_DEFAULTS.items():
            setattr(args, name, value if given[name] is None else given[name])
        return
    from ..gsdio import Reader
    with Reader(args.restart) as reader:
        state = reader.state(-1, validate=False)
        saved = reader.checkpoint(-1)["simulation"].get("seed")
    counts = np.unique(state.cells_per_replica)
    surface = SURFACE_OF_CONSTRAINT.get(state.constraint.name, repr(state.constraint))
    found = {"cells": int(counts[0]) if len(counts) == 1 else counts.tolist(), "replicas": state.n_replicas,
             "surface": surface}
    what = {"cells": f"{found['cells']} cells per replica", "replicas": f"{found['replicas']} replica(s)",
            "surface": f"a tissue on the {surface}"}
    for name, text in what.items():
        if given[name] is not None and given[name] != found[name] and not (
                name == "surface" and _same_surface(given[name], state.constraint)):
            raise CLIError(f"argument --{name}: {given[name]}, but --restart {args.restart!r} holds {text}; leave "
                           f"--{name} out with --restart")
        setattr(args, name, found[name])
    saved = None if saved is None else int(saved[0])
    # a command continues another's file by design (dynamics from a minimize file: FIRE's saved state
    # stays unused; minimize from a dynamics file: FIRE starts afresh), so the mismatch is no news here
    warnings.filterwarnings("ignore", category=CheckpointMismatchWarning)
    args.seed = given["seed"] if given["seed"] is not None else (saved or 0)
    if saved is not None and args.seed != saved:
        warnings.filterwarnings("ignore", message=SEED_WARNING)      # said here, on one line
        if not args.quiet:
            sys.stderr.write(f"spherevm: note: --seed {args.seed} replaces the seed {saved} of the run in "
                             f"{args.restart}: the random numbers from here on differ from that run's\n")


def force_spec(text):
    """argparse type of ``--force NAME:k=v,k=v``: ``(NAME, {k: v})``, numbers as float."""
    name, _, rest = str(text).partition(":")
    name = name.strip()
    if not name:
        raise argparse.ArgumentTypeError(f"expected NAME or NAME:key=value,key=value, got {text!r}")
    params = {}
    for item in filter(None, (p.strip() for p in rest.split(","))):
        key, eq, value = item.partition("=")
        key = key.strip()
        if not eq or not key:
            raise argparse.ArgumentTypeError(f"force {name!r}: expected key=value, got {item!r}")
        if key in params:
            raise argparse.ArgumentTypeError(f"force {name!r}: parameter {key} is given twice in {text!r}; give it "
                                             "once")
        try:
            params[key] = float(value)
        except ValueError:
            params[key] = value.strip()
    return name, params


def add_force_arguments(group, many=False):
    """``--force NAME:k=v,...`` (repeatable) and ``--bending B``: forces added to the vertex model.
    ``many``: ``--bending`` takes one or more values (a list)."""
    group.add_argument("--force", dest="forces", type=force_spec, action="append", default=[],
                       metavar="NAME:K=V,...", help="add the registered force NAME (see 'spherevm plugins') "
                       "with these constructor parameters; repeatable")
    group.add_argument("--bending", type=real(), default=None, metavar="B", nargs="+" if many else None,
                       help="bending between neighbouring cells, B in units of kP <A> (same as --force bending:B=B)")


def extra_forces(args) -> list:
    """The ``(name, params)`` pairs of ``--force`` and ``--bending``, checked by each plugin's own
    constructor (CLIError naming the plugin and parameter, status 2)."""
    from .. import plugins
    specs = list(getattr(args, "forces", None) or [])
    flags = [f"--force {name}" for name, _ in specs]
    if getattr(args, "bending", None) is not None:
        specs.append(("bending", {"B": args.bending}))
        flags.append(f"--bending {args.bending:g}")
    seen = {}
    for (name, params), flag in zip(specs, flags):
        try:
            cls = plugins.load(name)
            plugins.build_force(name, params)
        except (ValueError, TypeError) as exc:
            raise CLIError(f"argument --force: {one_line(exc)}") from exc
        if cls in seen:     # two of one force add up: B=1 and B=2 would silently be B=3
            raise CLIError(f"argument {flag.split()[0]}: {flag} and {seen[cls]} add the same force twice; "
                           "give each force once")
        seen[cls] = flag
    return specs


def build_forces(specs) -> list:
    """Force instances for ``(name, params)`` pairs (after :func:`extra_forces` checked them)."""
    from .. import plugins
    return [plugins.build_force(name, params) for name, params in specs]


def gsd_frames(path):
    """``(frames, step of the last frame)`` of the GSD file ``path``, or ``(None, None)`` if it
    cannot be read (absent, or not a GSD file)."""
    try:
        import gsd.hoomd
        with gsd.hoomd.open(path, "r") as traj:
            return len(traj), (int(traj[-1].configuration.step) if len(traj) else None)
    except Exception:
        return None, None


def resume_hint(command, path) -> str:
    """The tail of the Ctrl-C line of ``spherevm <command>`` that was writing the GSD file ``path``:
    what it holds and the ``--restart`` that continues from its last frame ("" if it holds none)."""
    frames, step = gsd_frames(path) if path is not None else (None, None)
    if not frames:
        return ""
    return (f"; {path} holds {frames} frame{'s' * (frames != 1)}, the last at step {step}: continue from it with "
            f"'spherevm {command} --restart {path}' and the other options as before")


# ---------------------------------------------------------------------------------------- sweeps
def run_sweep_command(args, sweep, what: str, label: str, units: str, **options):
    """What the sweep commands (``rigidity``, ``dynamics`` as a sweep) share: the ``--out`` folder
    checked before any work, the Dask client of ``--scheduler`` or ``--gpus``, a note of ``what``
    runs where (unless ``--quiet``), the progress bar (``label``, counting ``units``) and
    :func:`spherevm.sweeps.run_sweep` with ``options``.

    Returns
    -------
    spherevm.sweeps.SweepResult"""
    from ..sweeps import TextProgress, cluster, open_sweep_folder, run_sweep
    err = sys.stderr
    open_sweep_folder(sweep, args.out, create=False)        # a bad folder or a mismatch fails before any work
    client = None
    if args.scheduler or args.gpus:
        client = cluster.client(scheduler=args.scheduler, gpus=args.gpus, workers=args.workers)
    try:
        if not args.quiet:
            where = (f"{args.gpus} GPU worker(s)" if args.gpus else f"Dask cluster {args.scheduler}") if client \
                else f"device {args.device}"
            err.write(f"spherevm: {what} on {where}, writing {args.out}\n")
            err.flush()
        bar = TextProgress(err, label=label, enabled=None, units=units) if not args.quiet else None
        try:
            return run_sweep(sweep, args.out, executor=client, device="gpu" if args.gpus else args.device,
                             workers=args.workers, progress=bar, **options)
        finally:
            if bar is not None:
                bar.close()
    finally:
        if client is not None:
            client.close()
