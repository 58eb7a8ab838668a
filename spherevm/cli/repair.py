"""``spherevm repair``: copy the complete frames of a damaged or cut-short GSD file to a new file."""
from __future__ import annotations

import os

from .arguments import CLIError, add_overwrite, check_existing, check_in_path, check_out_path


def add_parser(subparsers):
    """Register ``repair`` on the ``spherevm`` subparsers."""
    p = subparsers.add_parser("repair", help="copy the complete frames of a damaged GSD file to a new file",
                              description="Read a GSD file that is cut short or damaged (gsd refuses it as a "
                                          "whole) up to its last complete frame and write those frames, chunk for "
                                          "chunk, to a new file. FILE itself is never changed. See "
                                          "docs/file-format.md, 'Damaged files'.")
    p.add_argument("file", metavar="FILE", help="the damaged GSD file")
    p.add_argument("--out", "-o", default=None, metavar="NEW.gsd",
                   help="the new file (default: FILE with .repaired.gsd in place of .gsd)")
    add_overwrite(p)
    p.set_defaults(func=run)
    return p


def run(args) -> int:
    """The handler of ``spherevm repair``."""
    import warnings

    from .. import gsdio, gsdrecover
    check_in_path(args.file, "FILE")
    out = args.out or os.path.splitext(args.file)[0] + ".repaired.gsd"
    check_out_path(out)
    if os.path.exists(out) and os.path.samefile(out, args.file):
        raise CLIError(f"argument --out: {out!r} is FILE itself; repair never changes the file it reads: give "
                       "another file name")
    check_existing(out, "--out", args.overwrite)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", gsdio.DamagedFileWarning)
        reader = gsdio.Reader(args.file)
    with reader:
        n = len(reader)
        part = f"{out}.part{os.getpid()}"
        try:
            gsdrecover.copy_frames(reader.file, n, part)
            os.replace(part, out)
        finally:
            if os.path.exists(part):
                os.remove(part)
    state = "damaged or cut short" if reader.recovered else "not damaged"
    print(f"{args.file}: {state}; wrote its {n} complete frame(s) to {out}")
    return 0
