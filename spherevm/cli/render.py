"""``spherevm render``: a PNG of a frame of a GSD trajectory, without OVITO (matplotlib)."""
from __future__ import annotations

from .arguments import add_frame_arguments, integer, real


def add_parser(subparsers):
    """Register ``render`` on the ``spherevm`` subparsers."""
    p = subparsers.add_parser("render", help="draw a frame's cells to a PNG with matplotlib",
                              description="Draw the cells of one replica of one frame of a spherevm GSD file, "
                                          "coloured by a per-cell quantity, with a colour bar (the far side of "
                                          "a sphere hidden; the plane drawn flat). See docs/visualisation.md.")
    add_frame_arguments(p, 0, "which replica (default 0)")
    p.add_argument("--out", required=True, help="output image (.png, .pdf, .svg)")
    p.add_argument("--size", type=real(strict=True), nargs=2, default=(6.0, 5.0), metavar=("W", "H"),
                   help="figure size in inches (default 6 5); at most 65535 pixels per side at --dpi")
    p.add_argument("--dpi", type=integer(10), default=100, help="dots per inch (default 100)")
    p.set_defaults(func=run)
    return p


def run(args) -> int:
    """The handler of ``spherevm render``."""
    from ..render import render_gsd
    render_gsd(args.file, args.out, frame=args.frame, quantity=args.quantity, cmap=args.cmap,
               replica=args.replica, size=tuple(args.size), dpi=args.dpi)
    print(f"wrote {args.out}")
    return 0
