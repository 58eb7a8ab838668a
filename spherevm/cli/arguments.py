"""What the subcommands share: exit codes, :class:`CLIError`, and argparse types that wrap the
library's own checks (:mod:`spherevm.validation`), so a flag and its Python parameter accept the
same values and a bad value is reported as ``argument --flag: must be <range>, got '<text>'``."""
from __future__ import annotations

import argparse
import os

from .. import validation

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


def real(strict=False):
    """argparse type: a finite number >= 0, > 0 with ``strict`` (:func:`spherevm.validation.real`)."""
    return _argument_type(float, validation.real, strict=strict)


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
SURFACES = ("sphere", "plane")


def add_surface(group, what="tilings"):
    """``--surface {sphere,plane}``: random tilings of the sphere (radius sqrt(N/4 pi)) or of the
    periodic plane (square box of side sqrt(N)); <A> = 1 on both."""
    group.add_argument("--surface", choices=SURFACES, default="sphere",
                       help=f"{what} on the sphere (radius sqrt(N/4 pi)) or the periodic plane (square box of side "
                            "sqrt(N), N >= 8) (default: %(default)s)")


def force_spec(text):
    """argparse type of ``--force NAME:k=v,k=v``: ``(NAME, {k: v})``, numbers as float."""
    name, _, rest = str(text).partition(":")
    name = name.strip()
    if not name:
        raise argparse.ArgumentTypeError(f"expected NAME or NAME:key=value,key=value, got {text!r}")
    params = {}
    for item in filter(None, (p.strip() for p in rest.split(","))):
        key, eq, value = item.partition("=")
        if not eq or not key.strip():
            raise argparse.ArgumentTypeError(f"force {name!r}: expected key=value, got {item!r}")
        try:
            params[key.strip()] = float(value)
        except ValueError:
            params[key.strip()] = value.strip()
    return name, params


def add_force_arguments(group):
    """``--force NAME:k=v,...`` (repeatable) and ``--bending B``: forces added to the vertex model."""
    group.add_argument("--force", dest="forces", type=force_spec, action="append", default=[],
                       metavar="NAME:K=V,...", help="add the registered force NAME (see 'spherevm plugins') "
                       "with these constructor parameters; repeatable")
    group.add_argument("--bending", type=real(), default=None, metavar="B",
                       help="bending between neighbouring cells, B in units of kP <A> (same as --force bending:B=B)")


def extra_forces(args) -> list:
    """The ``(name, params)`` pairs of ``--force`` and ``--bending``, checked by each plugin's own
    constructor (CLIError naming the plugin and parameter, status 2)."""
    from .. import plugins
    specs = list(getattr(args, "forces", None) or [])
    if getattr(args, "bending", None) is not None:
        specs.append(("bending", {"B": args.bending}))
    for name, params in specs:
        try:
            plugins.build_force(name, params)
        except (ValueError, TypeError) as exc:
            raise CLIError(f"argument --force: {one_line(exc)}") from exc
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
