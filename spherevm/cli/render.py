"""``spherevm render``: a PNG of a frame of a GSD trajectory, without OVITO (matplotlib)."""
from __future__ import annotations

from .arguments import integer


def add_parser(subparsers):
    """Register ``render`` on the ``spherevm`` subparsers."""
    p = subparsers.add_parser("render", help="draw a frame's cells to a PNG with matplotlib",
                              description="Draw the cells of one replica of one frame of a spherevm GSD file, "
                                          "coloured by a per-cell quantity, with a colour bar (the far side of "
                                          "a sphere hidden; the plane drawn flat). See docs/visualisation.md.")
    p.add_argument("file", help="a GSD trajectory written by spherevm")
    p.add_argument("--frame", type=int, default=-1, help="frame index, negative from the end (default -1)")
    p.add_argument("--out", required=True, help="output image (.png, .pdf, .svg)")
    p.add_argument("--quantity", default="shape_index", choices=("shape_index", "area", "perimeter", "energy"),
                   help="per-cell quantity that colours the cells (default shape_index)")
    p.add_argument("--cmap", default="viridis", help="matplotlib colour map (default viridis)")
    p.add_argument("--replica", type=integer(0), default=0, help="which replica (default 0)")
    p.add_argument("--size", type=float, nargs=2, default=(6.0, 5.0), metavar=("W", "H"),
                   help="figure size in inches (default 6 5)")
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
