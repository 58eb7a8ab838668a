"""``spherevm export``: a frame of a GSD trajectory as a coloured cell mesh (.ply, .obj, .glb)."""
from __future__ import annotations

from .arguments import add_frame_arguments, integer


def add_parser(subparsers):
    """Register ``export`` on the ``spherevm`` subparsers."""
    p = subparsers.add_parser("export", help="write a frame's cells as a coloured mesh (.ply/.obj/.glb)",
                              description="Triangulate the cells of one frame of a spherevm GSD file (fans from "
                                          "each cell's centre, edges drawn curved on the surface) and write a "
                                          "mesh coloured by a per-cell quantity. See docs/visualisation.md.")
    add_frame_arguments(p, None, "one replica only (default: all, side by side)")
    p.add_argument("--to", required=True, metavar="OUT", help="output mesh: .ply, .obj or .glb")
    p.add_argument("--subdivisions", type=integer(1), default=3,
                   help="each fan triangle cut into n^2 on the surface (default 3)")
    p.set_defaults(func=run)
    return p


def run(args) -> int:
    """The handler of ``spherevm export``."""
    from ..export import export_gsd
    mesh = export_gsd(args.file, args.to, frame=args.frame, quantity=args.quantity, cmap=args.cmap,
                      replica=args.replica, subdivisions=args.subdivisions)
    print(f"wrote {args.to}: {len(mesh.faces)} triangles, {len(mesh.vertices)} vertices")
    return 0
