"""The ``spherevm`` command (also ``python -m spherevm``), one module per subcommand.

Subcommands::

    spherevm minimize [--cells N] [--replicas R] [--p0 P] [--kr K] [--seed S] [--out run.gsd] ...
    spherevm dynamics --cells N --p0 P --kr K --T T --dt DT --steps S [--out run.gsd] [--csv msd.csv]
    spherevm rigidity [--cells N ...] [--p0 START:STOP:STEP ...] [--replicas R] [--out FOLDER] ...
    spherevm info [--json]
    spherevm plugins
    spherevm repair FILE [--out NEW.gsd]

Bad arguments and bad input caught by the library end with one line on standard error,
``spherevm: error: ...``, and exit status 2; a failure while a minimisation runs gives status 1.
No traceback is shown unless ``--debug`` is given before the subcommand. Ctrl-C (SIGINT), also
during start-up (the subcommands and NumPy are imported inside :func:`main`), ends with the one
line ``spherevm: interrupted`` and exit status 130. See docs/cli.md.

The command line sits above the library: nothing in spherevm outside this package imports it.
"""
from __future__ import annotations

import importlib
import os
import sys
import warnings

PROG = "spherevm"
COMMAND_NAMES = ("minimize", "dynamics", "rigidity", "info", "plugins", "export", "render", "repair")
COMMANDS_METAVAR = "{" + ",".join(COMMAND_NAMES) + "}"
INTERRUPTED = 130   # 128 + SIGINT, as a shell reports it

__all__ = ["CLIError", "PROG", "RUNTIME_ERROR", "USAGE_ERROR", "build_parser", "main"]


def __getattr__(name):
    """The exit codes and CLIError of :mod:`.arguments`, imported on first use (it imports NumPy)."""
    if name in ("CLIError", "RUNTIME_ERROR", "USAGE_ERROR", "one_line"):
        return getattr(importlib.import_module(".arguments", __name__), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def build_parser():
    """The parser of the whole command line; each subcommand sets ``func``, its handler."""
    import argparse

    from .. import __version__
    from .arguments import USAGE_ERROR, CLIError

    class _Parser(argparse.ArgumentParser):
        """argparse, but a usage error becomes a CLIError (one line, no usage dump, no SystemExit), and
        no option is taken from a prefix of its name (``--cell`` is not ``--cells``)."""

        def __init__(self, *args, **kwargs):
            super().__init__(*args, **{**kwargs, "allow_abbrev": False})

        def error(self, message):
            if message.startswith(f"argument {COMMANDS_METAVAR}: invalid choice:"):
                message = "unknown command" + message.split("invalid choice", 1)[1]
            raise CLIError(message, USAGE_ERROR)

    parser = _Parser(prog=PROG, description="Vertex models of confluent tissue on a sphere.",
                     epilog="Run 'spherevm <command> --help' for a command's options. Docs: docs/cli.md")
    parser.add_argument("--version", action="version", version=f"spherevm {__version__}")
    parser.add_argument("--debug", action="store_true",
                        help="show the full traceback on errors instead of one line")
    sub = parser.add_subparsers(dest="command", metavar=COMMANDS_METAVAR, parser_class=_Parser)
    for name in COMMAND_NAMES:
        importlib.import_module(f".{name}", __name__).add_parser(sub)
    return parser


def _as_flag(args, exc) -> str:
    """The one-line message of ``exc``; a library ParameterError about a parameter that is also a
    flag of this command as argparse reports that flag (``argument --replica: must be ...``)."""
    from ..validation import ParameterError
    from .arguments import one_line
    if isinstance(exc, ParameterError) and hasattr(args, exc.name):
        return f"argument --{exc.name.replace('_', '-')}: must be {exc.allowed}, got {exc.value!r}"
    return one_line(exc)


def _report(message):
    sys.stderr.write(f"{PROG}: error: {message}\n")
    sys.stderr.flush()


def main(argv=None) -> int:
    """Run the command line ``argv`` (default ``sys.argv[1:]``); return the exit status (130
    after Ctrl-C, at any point, with one line on standard error)."""
    try:
        return _main(argv)
    except KeyboardInterrupt as stop:
        try:   # a command that was writing a GSD file adds how to continue from it (resume_hint)
            sys.stderr.write(f"\n{PROG}: interrupted{getattr(stop, 'resume_hint', '')}\n")
            sys.stderr.flush()
        except (OSError, ValueError, KeyboardInterrupt):
            pass
        return INTERRUPTED


def _main(argv):
    from .arguments import RUNTIME_ERROR, USAGE_ERROR, CLIError, one_line
    parser = build_parser()
    try:
        args = parser.parse_args(None if argv is None else [os.fspath(a) for a in argv])
    except CLIError as exc:
        _report(exc.message)
        return exc.code
    except SystemExit as exc:  # --help, --version
        return exc.code if isinstance(exc.code, int) else (0 if exc.code is None else USAGE_ERROR)
    if args.command is None:
        _report(f"no command given; choose one of: {', '.join(COMMAND_NAMES)} (see spherevm --help)")
        return USAGE_ERROR
    try:
        with warnings.catch_warnings():     # a filter a subcommand sets ends with it
            return int(args.func(args) or 0)
    except CLIError as exc:
        if args.debug:
            raise
        _report(exc.message)
        return exc.code
    except BrokenPipeError:  # e.g. `spherevm plugins | head -1`: the reader left, nothing to report
        try:
            os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        except (OSError, ValueError):
            pass
        return 0
    except (ValueError, TypeError, FileNotFoundError) as exc:
        if args.debug:
            raise
        _report(_as_flag(args, exc))
        return USAGE_ERROR
    except Exception as exc:
        if args.debug:
            raise
        _report(f"{type(exc).__name__}: {one_line(exc)} (rerun as 'spherevm --debug ...' for the traceback)")
        return RUNTIME_ERROR
