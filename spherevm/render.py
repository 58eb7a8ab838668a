"""Pictures without OVITO: the cells of a State drawn with matplotlib, coloured per cell.

On a sphere each cell is a ``Poly3DCollection`` polygon whose edges are geodesics (each cut into a
few segments on the surface); cells on the far side (outward normal at the cell centre pointing
away from the viewer) are left out, so the picture shows one hemisphere as a solid ball. On the
periodic plane the cells are drawn flat, unwrapped across the box edges. A colour bar names the
quantity::

    from spherevm.render import render_gsd
    render_gsd("run.gsd", "snapshot.png", frame=-1)

or ``spherevm render run.gsd --out snapshot.png``.
"""
from __future__ import annotations

import numpy as np

from .constraints import PeriodicPlane
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
    """Boundary polygons of ``cells``: a list of ``(k * segments, 3)`` arrays (edges cut into
    ``segments`` pieces and put back on the surface), and the centre of each cell."""
    centre, a, b, cell_of = fan_triangles(state, cells)
    t = (np.arange(segments) / segments)[None, :, None]
    pts = (1 - t) * a[:, None] + t * b[:, None]                  # (edges, segments, 3)
    plane = isinstance(state.constraint, PeriodicPlane)
    if not plane:
        radius = state.constraint.size_np(state)[state.cell_replica_np()[cell_of]]
        pts = np.asarray(state.constraint.project_normal(pts, radius[:, None]))
        centre = np.asarray(state.constraint.project_normal(centre, radius))
    bounds = np.concatenate([[0], np.cumsum(np.bincount(np.searchsorted(cells, cell_of), minlength=len(cells)))])
    polys = [pts[bounds[i]:bounds[i + 1]].reshape(-1, 3) for i in range(len(cells))]
    return polys, centre[bounds[:-1]]


def draw(ax, state, values=None, quantity: str = "shape_index", cmap: str = "viridis", replica: int = 0,
         elev: float = 20.0, azim: float = 30.0, vmin=None, vmax=None, segments: int = 4):
    """Draw one replica of ``state`` on ``ax`` (a 3D axes on a sphere, a 2D one on the plane).

    Returns a ``ScalarMappable`` for ``fig.colorbar``."""
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
    polys, centres = cell_polygons(state, cells, segments)
    if isinstance(state.constraint, PeriodicPlane):
        from matplotlib.collections import PolyCollection
        ax.add_collection(PolyCollection([p[:, :2] for p in polys], facecolors=face, edgecolors="k", linewidths=0.5))
        lx, ly = state.constraint.size_np(state)[int(replica)]
        ax.set_xlim(-0.1 * lx, 1.1 * lx)
        ax.set_ylim(-0.1 * ly, 1.1 * ly)
        ax.set_aspect("equal")
    else:
        from mpl_toolkits.mplot3d.art3d import Poly3DCollection
        front = (centres @ view_direction(elev, azim)) > 0            # outward normal towards the viewer
        # autolim=False: the limits are the sphere's, set below; matplotlib (3.10+) would otherwise
        # scale the view on its np.empty padding of ragged polygons, garbage on some runs
        ax.add_collection3d(Poly3DCollection([p for p, f in zip(polys, front) if f], facecolors=face[front],
                                             edgecolors="k", linewidths=0.4), autolim=False)
        r = float(state.constraint.size_np(state)[int(replica)])
        for set_lim in (ax.set_xlim, ax.set_ylim, ax.set_zlim):
            set_lim(-r, r)
        ax.set_box_aspect((1, 1, 1), zoom=1.35)
        ax.view_init(elev=elev, azim=azim)
        ax.set_axis_off()
    mappable = ScalarMappable(norm=matplotlib.colors.Normalize(lo, hi), cmap=cmap)
    mappable.set_array(vals[ok])
    return mappable


def new_axes(fig, state, *position):
    """An axes for :func:`draw`: 3D on a sphere, 2D on the plane."""
    plane = isinstance(state.constraint, PeriodicPlane)
    return fig.add_subplot(*position) if plane else fig.add_subplot(*position, projection="3d")


def render_state(state, out, values=None, quantity: str = "shape_index", size=(6.0, 5.0), dpi: int = 100,
                 title=None, **options):
    """Write a PNG (or any format matplotlib writes) of one replica of ``state`` with a colour bar.

    ``size`` (width, height) in inches and ``dpi`` must be positive and give fewer than 2^16 pixels
    along each side (matplotlib's limit); a picture whose canvas (``BYTES_PER_PIXEL`` = 8 bytes per
    pixel) would not fit in the host memory available now is refused at once (ValueError)."""
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
    """Render a frame of a spherevm GSD file (exact per-cell values from the file) to ``out``."""
    with Reader(path) as reader:
        state = reader.state(frame)
        stored = reader.cell_values(frame)
        step = reader.step(frame)
    values = cell_values(state, quantity, stored)
    options.setdefault("title", f"{path}  frame {frame}  (step {step})")
    return render_state(state, out, values=values, quantity=quantity, **options)
