"""Pictures without OVITO: the cells of a State drawn with matplotlib, coloured per cell.

On a sphere each cell is a ``Poly3DCollection`` polygon whose edges are geodesics (each cut into a
few segments on the surface), seen by an orthographic camera: the cells are clipped to the
hemisphere facing it, so the picture is a solid ball with a round rim. On the periodic plane the
box is outlined and filled by the cells and their periodic images (a cell that crosses an edge
shows on both sides), with the images around the box faded. A colour bar names the quantity::

    from spherevm.render import render_gsd
    render_gsd("run.gsd", "snapshot.png", frame=-1)

or ``spherevm render run.gsd --out snapshot.png``.
"""
from __future__ import annotations

import numpy as np

from .export import cell_values, check_replica, colors, fan_triangles
from .gsdio import Reader
from .validation import check_memory, positive

#: matplotlib's Agg canvas takes fewer than 2^16 pixels along each side
MAX_PIXELS_PER_SIDE = 2 ** 16 - 1
#: host memory per pixel of the picture: the RGBA canvas (4 B), rounded up (measured peak of
#: :func:`render_gsd` at 4e6 and 3.6e7 pixels: 4 B per pixel above matplotlib's own ~70 MB)
BYTES_PER_PIXEL = 8

LABELS = {"shape_index": "shape index  P / sqrt(A)", "area": "cell area", "perimeter": "cell perimeter",
          "energy": "cell energy"}


def view_direction(elev: float, azim: float) -> np.ndarray:
    """Unit vector from the origin towards a matplotlib 3D camera at (elev, azim) degrees."""
    e, a = np.radians(elev), np.radians(azim)
    return np.array([np.cos(e) * np.cos(a), np.cos(e) * np.sin(a), np.sin(e)])


def cell_polygons(state, cells, segments: int = 4):
    """Boundary polygons of ``cells``: a list of ``(k * segments, 3)`` arrays, one per cell of
    ``k`` sides (edges cut into ``segments`` pieces and put back on the surface,
    :meth:`~spherevm.constraints.Constraint.draw_points`; unwrapped about the cell's first vertex
    on the periodic plane)."""
    _, a, b, cell_of = fan_triangles(state, cells)
    t = (np.arange(segments) / segments)[None, :, None]
    pts = (1 - t) * a[:, None] + t * b[:, None]                  # (edges, segments, 3)
    size = state.constraint.size_np(state)[state.cell_replica_np()[cell_of]]
    pts = np.asarray(state.constraint.draw_points(pts, size[:, None]))
    bounds = np.concatenate([[0], np.cumsum(np.bincount(np.searchsorted(cells, cell_of), minlength=len(cells)))])
    polys = [pts[bounds[i]:bounds[i + 1]].reshape(-1, 3) for i in range(len(cells))]
    return polys


STEP = np.radians(3.0)      # the longest piece of a cell's edge or of the rim drawn straight on a sphere


def refine(poly, radius, step: float = STEP):
    """The spherical polygon ``poly`` (k, 3) with points added on the sphere of ``radius`` so that
    neighbours are at most ``step`` radians apart (straight pieces that look round)."""
    nxt = np.roll(poly, -1, axis=0)
    angle = np.arccos(np.clip(np.einsum("ij,ij->i", poly, nxt) / radius ** 2, -1.0, 1.0))
    pieces = np.maximum(1, np.ceil(angle / step).astype(np.int64))
    if (pieces == 1).all():
        return poly
    i = np.repeat(np.arange(len(poly)), pieces)
    t = (np.arange(len(i)) - np.repeat(np.cumsum(pieces) - pieces, pieces)) / pieces[i]
    pts = (1 - t)[:, None] * poly[i] + t[:, None] * nxt[i]
    return radius * pts / np.linalg.norm(pts, axis=1, keepdims=True)


def clip_to_front(poly, view, radius, rim_step: float = STEP):
    """The part of the spherical polygon ``poly`` (k, 3) on the hemisphere facing ``view`` (a unit
    vector), or None where none is: edges are cut where they cross the rim (the great circle
    perpendicular to ``view``) and the cut ends joined along the rim in steps of at most
    ``rim_step`` radians, so the clipped cells fill the disc an orthographic camera sees."""
    d = poly @ view
    inside = d >= 0
    if inside.all():
        return poly
    if not inside.any():
        return None
    start = int(np.argmax(inside))                      # walk from a point in front
    p, d, inside = np.roll(poly, -start, axis=0), np.roll(d, -start), np.roll(inside, -start)
    out, leave = [], None
    for i in range(len(p)):
        j = (i + 1) % len(p)
        if inside[i]:
            out.append(p[i])
        if inside[i] == inside[j]:
            continue
        cut = p[i] + d[i] / (d[i] - d[j]) * (p[j] - p[i])
        cut *= radius / np.linalg.norm(cut)
        if not inside[i]:                               # back in front: the rim from where it left
            angle = np.arccos(np.clip(leave @ cut / radius ** 2, -1.0, 1.0))
            s = np.linspace(0.0, 1.0, int(np.ceil(angle / rim_step)) + 1)[1:-1, None]
            arc = (1 - s) * leave + s * cut
            out.extend(radius * arc / np.linalg.norm(arc, axis=1, keepdims=True))
        out.append(cut)
        leave = cut
    return np.array(out)


def _draw_box(ax, state, polys, face, replica, elev, azim):
    """The cells of one replica on the periodic plane: the box outlined, the cells and their
    periodic images filling it (so cells that cross an edge show on both sides), and the images
    around it faded."""
    from matplotlib.collections import PolyCollection
    from matplotlib.patches import Rectangle
    lx, ly = state.constraint.size_np(state)[int(replica)]
    flat = [p[:, :2] for p in polys]
    shifts = [(i * lx, j * ly) for i in (-1, 0, 1) for j in (-1, 0, 1)]
    tiles = [p + s for s in shifts for p in flat]
    colours = np.tile(face, (len(shifts), 1))
    ax.add_collection(PolyCollection(tiles, facecolors=colours, edgecolors="k", linewidths=0.5, alpha=0.35))
    inside = PolyCollection(tiles, facecolors=colours, edgecolors="k", linewidths=0.5)
    ax.add_collection(inside)
    inside.set_clip_path(Rectangle((0, 0), lx, ly, transform=ax.transData))
    ax.add_patch(Rectangle((0, 0), lx, ly, fill=False, edgecolor="k", linewidth=1.5))
    ax.set_xlim(-0.1 * lx, 1.1 * lx)
    ax.set_ylim(-0.1 * ly, 1.1 * ly)
    ax.set_aspect("equal")


def _draw_ball(ax, state, polys, face, replica, elev, azim):
    """The hemisphere of one replica's sphere that faces the camera, seen orthographically: cells
    clipped at the rim, so its outline is the sphere's circle."""
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection
    r = float(state.constraint.size_np(state)[int(replica)])
    view = view_direction(elev, azim)
    clipped = [clip_to_front(refine(p, r), view, r) for p in polys]
    front = np.array([c is not None for c in clipped], dtype=bool)
    # autolim=False: the limits are the sphere's, set below; matplotlib (3.10+) would otherwise
    # scale the view on its np.empty padding of ragged polygons, garbage on some runs
    ax.add_collection3d(Poly3DCollection([c for c in clipped if c is not None], facecolors=face[front],
                                         edgecolors="k", linewidths=0.4), autolim=False)
    for set_lim in (ax.set_xlim, ax.set_ylim, ax.set_zlim):
        set_lim(-r, r)
    ax.set_proj_type("ortho")
    ax.set_box_aspect((1, 1, 1), zoom=1.35)
    ax.view_init(elev=elev, azim=azim)
    ax.set_axis_off()


def _draw_mesh(ax, state, polys, face, replica, elev, azim):
    """The cells of one replica as 3D polygons (matplotlib sorts them by depth), seen
    orthographically from (``elev``, ``azim``), the axes spanning them with equal scales."""
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection
    ax.add_collection3d(Poly3DCollection(polys, facecolors=face, edgecolors="k", linewidths=0.4), autolim=False)
    pts = np.concatenate(polys)
    centre, half = 0.5 * (pts.max(axis=0) + pts.min(axis=0)), 0.5 * (pts.max(axis=0) - pts.min(axis=0)).max()
    for set_lim, c in zip((ax.set_xlim, ax.set_ylim, ax.set_zlim), centre):
        set_lim(c - half, c + half)
    ax.set_proj_type("ortho")
    ax.set_box_aspect((1, 1, 1), zoom=1.2)
    ax.view_init(elev=elev, azim=azim)
    ax.set_axis_off()


#: the drawing of each :attr:`~spherevm.constraints.Constraint.drawing`
DRAWINGS = {"mesh": _draw_mesh, "ball": _draw_ball, "box": _draw_box}


def draw(ax, state, values=None, quantity: str = "shape_index", cmap: str = "viridis", replica: int = 0,
         elev: float = 20.0, azim: float = 30.0, vmin=None, vmax=None, segments: int = 4):
    """Draw one replica of ``state`` on ``ax``: on a sphere (a 3D axes) the hemisphere facing the
    camera at (``elev``, ``azim``) degrees; on the plane (a 2D axes) the box, the cells and their
    periodic images.

    Returns
    -------
    A ``ScalarMappable`` for ``fig.colorbar``.
    """
    import matplotlib
    from matplotlib.cm import ScalarMappable
    values = cell_values(state, quantity) if values is None else np.asarray(values, dtype=np.float64)
    replica = check_replica(state, replica)
    cells = np.flatnonzero(state.cell_replica_np() == replica)
    vals = values[cells]
    ok = np.isfinite(vals)
    lo = vmin if vmin is not None else (vals[ok].min() if ok.any() else 0.0)
    hi = vmax if vmax is not None else (vals[ok].max() if ok.any() else 1.0)
    face = colors(vals, cmap, lo, hi) / 255.0
    polys = cell_polygons(state, cells, segments)
    DRAWINGS[state.constraint.drawing](ax, state, polys, face, replica, elev, azim)
    mappable = ScalarMappable(norm=matplotlib.colors.Normalize(lo, hi), cmap=cmap)
    mappable.set_array(vals[ok])
    return mappable


def new_axes(fig, state, *position):
    """An axes for :func:`draw`: 2D for a surface drawn as a periodic box (the plane), else 3D."""
    flat = DRAWINGS[state.constraint.drawing] is _draw_box
    return fig.add_subplot(*position) if flat else fig.add_subplot(*position, projection="3d")


def render_state(state, out, values=None, quantity: str = "shape_index", size=(6.0, 5.0), dpi: int = 100,
                 title=None, **options):
    """Write a picture (PNG, or any format matplotlib writes) of one replica of ``state`` with a
    colour bar.

    Parameters
    ----------
    state : State
    out : str or path
    values : array (n_cells,), optional
        Per-cell values; default the ``quantity`` computed from the State.
    quantity : str
        The colour bar's label, and what is computed without ``values``.
    size : (float, float)
        Figure size in inches; with ``dpi``, fewer than 2^16 pixels along each side (matplotlib's
        limit), and a canvas (``BYTES_PER_PIXEL`` = 8 bytes a pixel) that fits in the host memory
        available now (else ValueError at once).
    dpi : int
    title : str, optional
    **options
        :func:`draw`'s keywords (``replica``, ``cmap``, ...).

    Returns
    -------
    str or path
        ``out``."""
    check_picture(size, dpi)
    import matplotlib
    matplotlib.use("Agg", force=False) if matplotlib.get_backend().lower() != "agg" and not _interactive() else None
    import matplotlib.pyplot as plt
    fig = plt.figure(figsize=size, dpi=dpi)
    ax = new_axes(fig, state, 1, 1, 1)
    mappable = draw(ax, state, values=values, quantity=quantity, **options)
    fig.colorbar(mappable, ax=ax, shrink=0.7, label=LABELS.get(quantity, quantity))
    if title:
        ax.set_title(title)
    fig.savefig(out, dpi=dpi)
    plt.close(fig)
    return out


def check_picture(size, dpi):
    """Refuse (ValueError naming ``size`` or ``dpi``) a picture of no pixels, one past matplotlib's
    ``MAX_PIXELS_PER_SIDE`` or one whose canvas would not fit in memory."""
    if np.ndim(size) != 1 or len(size) != 2:
        raise ValueError(f"size must be (width, height) in inches, got {size!r}")
    inches = [positive("size", v) for v in size]
    dots = positive("dpi", dpi)
    pixels = [w * dots for w in inches]
    if max(pixels) > MAX_PIXELS_PER_SIDE:
        raise ValueError(f"size {tuple(inches)} inches at dpi {dots:g} is {pixels[0]:.0f} x {pixels[1]:.0f} pixels; "
                         f"matplotlib draws at most {MAX_PIXELS_PER_SIDE} pixels per side: lower dpi or size")
    check_memory(f"a picture of {pixels[0]:.0f} x {pixels[1]:.0f} pixels (size {tuple(inches)} at dpi {dots:g})",
                 host_bytes=pixels[0] * pixels[1] * BYTES_PER_PIXEL, advice="lower dpi or size")


def _interactive():
    import sys
    return hasattr(sys, "ps1")


def render_gsd(path, out, frame: int = -1, quantity: str = "shape_index", **options):
    """Render a frame of a spherevm GSD file, with the exact per-cell values stored in the file.

    Parameters
    ----------
    path : str or path
    out : str or path
    frame : int
        Negative from the end.
    quantity : {"shape_index", "area", "perimeter", "energy"}
    **options
        As in :func:`render_state`.

    Returns
    -------
    str or path
        ``out``."""
    with Reader(path) as reader:
        index = reader.index(frame)
        state = reader.state(index)
        stored = reader.cell_values(index)
        step = reader.step(index)
    values = cell_values(state, quantity, stored)
    replica = f"  replica {options.get('replica', 0)}" if state.n_replicas > 1 else ""
    options.setdefault("title", f"{path}  frame {index}  (step {step}){replica}")
    return render_state(state, out, values=values, quantity=quantity, **options)
