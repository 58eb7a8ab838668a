"""Initial States on the periodic plane: random Voronoi tilings, the honeycomb, and from polygons.

Re-exported by :mod:`spherevm.init` (``svm.init.random_planar_tiling``, ``svm.init.hexagonal_tiling``,
``svm.init.from_polygons(..., box=...)``).
"""
from __future__ import annotations

import numpy as np

from . import topology
from .constraints import PeriodicPlane
from .device import CPU, resolve
from .state import State
from .validation import check_cell_size, check_tiling_memory, integer

MAX_ATTEMPTS = 1000
#: the fewest cells a random periodic tiling may have. Trivalent cells on a torus average 6 sides and
#: a simple network (no cell bordering itself, no two cells sharing two edges through the periodic
#: images) needs >= 6 distinct neighbours for some cell, so N >= 7 (met only by the Heawood map, seven
#: hexagons all adjacent). Measured fraction of random Voronoi draws that are simple with every edge
#: shorter than half the box (300 each): N <= 7: 0, 8: 2%, 9: 6%, 10: 21%, 12: 48%, 16: 87%, 20: 97%;
#: other draws are redrawn, which conditions the small-N ensemble.
MIN_PLANAR_CELLS = 8
#: The fewest cells per replica with which :class:`~spherevm.plugins.updaters.T1` runs on a periodic
#: plane (docs/plane.md): an edge's minimum image is right only while it spans less than half the
#: box, sqrt(N)/2 sqrt(<A>), and the longest edges of random tilings and their relaxed states measure
#: 1.8-2.1 sqrt(<A>) at N = 12-24. Measured (32 replicas each, FIRE + T1 then hot Brownian with T1,
#: benchmarks/crossings.py): cells stopped closing at N = 10, 12 (T = 0.05, dt = 0.05) and 14
#: (T = 0.2, dt = 0.01), never at N >= 16 there; at T = 0.5 also at 16 and 20.
MIN_T1_PLANAR_CELLS = 16
#: from this many cells on, periodic_voronoi triangulates only the images within MARGIN_CELL_SIDES of
#: the box and puts its triangles in a canonical order (Qhull of 1.6-1.9 N points instead of 9 N: a
#: 1,024-cell tiling of a 3:1 torus in 15 ms instead of 32 on a 2-core VM); below it the result is
#: bitwise what it was before the margin existed (all 3 x 3 images in Qhull's order), so that the
#: published results of small periodic tilings keep reproducing
MARGIN_MIN_CELLS = 500
#: the margin in cell sides sqrt(<A>): the largest empty circle among 2e6 Poisson triangles has a
#: radius of about sqrt(ln(2e6) / pi) = 2.1 sides
MARGIN_CELL_SIDES = 4.0
_SHIFTS = np.array([(i, j) for j in (-1, 0, 1) for i in (-1, 0, 1)], dtype=np.float64)


def check_box(box, n_cells=None, name="box") -> np.ndarray:
    """``(Lx, Ly)`` as float64 from a pair or a side (square); the square of area ``n_cells`` if None.
    With ``n_cells`` the cells' size sqrt(Lx Ly / n_cells) must lie in ``CELL_SIZE_RANGE`` (1e-50..1e50)."""
    if box is None:
        side = float(np.sqrt(n_cells))
        return np.array([side, side])
    b = np.asarray(box, dtype=np.float64).reshape(-1)
    if b.size == 1:
        b = np.repeat(b, 2)
    if b.size != 2:
        raise ValueError(f"{name} must be a side L or a pair (Lx, Ly), got {box!r}")
    if not np.all(np.isfinite(b)) or np.any(b <= 0):
        raise ValueError(f"{name} must be positive and finite, got {box!r}")
    if n_cells is not None:
        check_cell_size(name, box, float(np.sqrt(b[0]) * np.sqrt(b[1] / n_cells)),
                        "the default box, the square of side sqrt(N), gives <A> = 1")
    return b


def _circumcenters(p):
    """Circumcentres of triangles ``p`` (T, 3, 2)."""
    b, c = p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]
    d = 2.0 * (b[:, 0] * c[:, 1] - b[:, 1] * c[:, 0])
    b2, c2 = (b * b).sum(axis=1), (c * c).sum(axis=1)
    x = (c[:, 1] * b2 - b[:, 1] * c2) / d
    y = (b[:, 0] * c2 - c[:, 0] * b2) / d
    return p[:, 0] + np.stack([x, y], axis=1)


def _rotated(tri, first):
    """Triangles ``tri`` (T, 3) rotated to start at their corner ``first`` (T,)."""
    return np.take_along_axis(tri, (first[:, None] + np.arange(3)) % 3, axis=1)


def _points(pts, tri, box):
    """The corners (T, 3, 2) of triangles of image labels ``k n + i``: point i shifted by image k."""
    return pts[tri % len(pts)] + _SHIFTS[tri // len(pts)] * box


def periodic_voronoi(points, box, margin=True):
    """The Voronoi tessellation of ``points`` (n, 2) in the periodic ``box``, as a trivalent network.

    Delaunay triangulation of the 3 x 3 periodic images (the Voronoi diagram's dual); each periodic
    triangle is kept once, the image whose circumcentre (its Voronoi vertex) lies in the central box;
    point indices are taken modulo n, which identifies the vertices across images. From
    ``MARGIN_MIN_CELLS`` points on, only the images within ``MARGIN_CELL_SIDES`` cell sides of the box
    are triangulated (all of them with ``margin=False``, or where some kept triangle's empty
    circumcircle reaches past the margin), and the kept triangles are put in a canonical order (each
    starts at its lowest point index; sorted by their points, then images): the result does not
    depend on how Qhull lists its triangles, so the margin and the full images give the same bits.
    Returns local ``(positions, cell_vertices, cell_sides, vertex_neighbors, vertex_cells)``, or None
    if the result is not a simple trivalent network (small n: a cell meeting itself or a neighbour
    twice).
    """
    from scipy.spatial import Delaunay
    pts = np.asarray(points, dtype=np.float64)
    n = len(pts)
    images = (pts[None] + _SHIFTS[:, None] * box).reshape(-1, 2)
    label = np.arange(len(images))                 # image k of point i: k n + i
    canonical = n >= MARGIN_MIN_CELLS
    width = MARGIN_CELL_SIDES * np.sqrt(np.prod(box) / n) if canonical and margin else None
    if width is not None:      # only the images within `width` of the box
        near = ((images >= -width) & (images < box + width)).all(axis=1)
        images, label = images[near], label[near]
    try:
        tri = label[Delaunay(images).simplices]
    except RuntimeError as exc:     # QhullError: e.g. a box ~1e300 times longer than wide
        raise ValueError(f"qhull cannot triangulate {n} points in the box ({box[0]:g}, {box[1]:g}) "
                         f"({str(exc).strip().splitlines()[0]}); give a box a few cells wide in both "
                         "directions") from None
    if canonical:
        tri = _rotated(tri, np.argmin(tri, axis=1))         # each image from its lowest label
    p = _points(pts, tri, box)
    cc = _circumcenters(p)
    keep = ((cc >= 0) & (cc < box)).all(axis=1)
    tri, p, cc = tri[keep], p[keep], cc[keep]
    cw = ((p[:, 1, 0] - p[:, 0, 0]) * (p[:, 2, 1] - p[:, 0, 1])
          - (p[:, 1, 1] - p[:, 0, 1]) * (p[:, 2, 0] - p[:, 0, 0])) < 0
    tri[cw] = tri[cw][:, [0, 2, 1]]
    if canonical:
        tri = _rotated(tri, np.argmin(tri % n, axis=1))     # then from its lowest point, in order
        tri = tri[np.lexsort(tuple((tri // n).T[::-1]) + tuple((tri % n).T[::-1]))]
        p = _points(pts, tri, box)
        cc = _circumcenters(p)
    if width is not None and not np.all(np.hypot(*(cc - p[:, 0]).T) < width):
        return periodic_voronoi(pts, box, margin=False)    # an empty circle reaches past the margin
    t = tri % n
    if len(t) != 2 * n or np.any(t == np.roll(t, -1, axis=1)):
        return None
    key = t * n + np.roll(t, -1, axis=1)
    if len(np.unique(key)) != key.size or not np.array_equal(np.sort(key.reshape(-1)),
                                                            np.sort((np.roll(t, -1, axis=1) * n + t).reshape(-1))):
        return None
    table, sides, vn, vc = topology.dual_network(t, n)
    if topology.repeated_adjacency(vn, vc) is not None:
        return None
    pos = np.zeros((len(t), 3))
    pos[:, :2] = cc
    return pos, table, sides, vn, vc


def random_planar_tiling(n_cells: int, replicas: int = 1, seed: int = 0, box=None, sort: bool = True,
                         device=CPU) -> State:
    """Random Voronoi tilings of the periodic box, ``n_cells`` uniform random points each.

    Replica ``r`` uses the random stream ``(seed, r)`` (redrawn from ``(seed, r, attempt)`` when the
    Voronoi network is not simple or has an edge longer than half the box: common at small N or in a
    box only a few cells wide), so it does not depend on how many replicas are made.

    Parameters
    ----------
    n_cells : int
        Cells per replica, at least ``MIN_PLANAR_CELLS`` (8).
    replicas : int
    seed : int
    box : float or (Lx, Ly), optional
        Default: the square of area ``n_cells`` (<A> = 1).
    sort : bool
        Number cells and vertices along a 2-D Morton curve.
    device : Device or str

    Returns
    -------
    State"""
    n = integer("n_cells", n_cells, minimum=MIN_PLANAR_CELLS)
    replicas = integer("replicas", replicas, minimum=1)
    seed = integer("seed", seed)
    b = check_box(box, n)
    check_tiling_memory(f"random_planar_tiling({n}, replicas={replicas})", n, replicas, gpu=resolve(device).is_gpu)
    return _planar_tilings(n, [(seed, r) for r in range(replicas)], b, sort, device)


def random_planar_tilings(n_cells: int, seeds, box=None, sort: bool = True, device=CPU) -> State:
    """One random planar tiling per seed, as an ensemble: replica ``i`` equals
    ``random_planar_tiling(n_cells, seed=seeds[i], box=box)`` (sweeps give every (N, p0, replica)
    its own seed, as :func:`spherevm.init.random_tilings` does on the sphere)."""
    n = integer("n_cells", n_cells, minimum=MIN_PLANAR_CELLS)
    seeds = [int(x) for x in seeds]
    if not seeds or min(seeds) < 0:
        raise ValueError("seeds must be a non-empty list of non-negative integers")
    b = check_box(box, n)
    check_tiling_memory(f"random_planar_tilings({n}, {len(seeds)} seeds)", n, len(seeds), gpu=resolve(device).is_gpu)
    return _planar_tilings(n, [(x, 0) for x in seeds], b, sort, device)


def _planar_tilings(n, keys, b, sort, device):
    """The tilings of the random streams ``keys`` (one (seed, replica) pair each), as one State."""
    states = []
    for key in keys:    # initialisation only: one Delaunay triangulation per replica
        for attempt in range(MAX_ATTEMPTS):
            rng = np.random.default_rng(list(key) + ([attempt] if attempt else []))
            pts = rng.random((n, 2)) * b
            net = periodic_voronoi(pts, b)
            if net is None:
                continue
            try:       # edges must be shorter than half the box for their minimum images to be them
                State(*net, [0, 2 * n], [0, n], box=b, constraint=PeriodicPlane())
                break
            except ValueError:
                continue
        else:
            narrow = float(b.min() / np.sqrt(b.prod() / n))
            raise ValueError(f"box ({b[0]:g}, {b[1]:g}) gave no simple periodic Voronoi tiling of {n} cells in "
                             f"{MAX_ATTEMPTS} draws: its narrow side is {narrow:.3g} cells wide; give a box a few "
                             "cells wide in both directions")
        if sort:
            net = topology.renumber(*net, np.argsort(topology.morton_codes_2d(net[0], b), kind="stable"),
                                    np.argsort(topology.morton_codes_2d(pts, b), kind="stable"))
        states.append(State(*net, [0, 2 * n], [0, n], box=b, constraint=PeriodicPlane(), validate=False))
    state = states[0] if len(states) == 1 else State.concatenate(states)
    state.validate()
    return state.to(device) if device is not CPU else state


def hexagonal_tiling(nx: int, ny: int, device=CPU) -> State:
    """The regular honeycomb of ``nx x ny`` unit-area hexagons on the periodic plane.

    Pointy-top hexagons of side ``a = sqrt(2 / (3 sqrt 3))`` (area 1, perimeter ``sqrt(8 sqrt 3)``),
    rows offset by half a cell; box ``(nx sqrt(3) a, ny 3a/2)``.

    Parameters
    ----------
    nx, ny : int
        Hexagons per row and rows: ``nx >= 3``, ``ny >= 4`` and even (a simple network).
    device : Device or str

    Returns
    -------
    State"""
    nx = integer("nx", nx, minimum=3)
    ny = integer("ny", ny, minimum=4)
    if ny % 2:
        raise ValueError(f"ny must be even for the honeycomb to tile the periodic box, got {ny}")
    a = np.sqrt(2.0 / (3.0 * np.sqrt(3.0)))
    box = np.array([nx * np.sqrt(3.0) * a, ny * 1.5 * a])
    i, j = np.meshgrid(np.arange(nx), np.arange(ny), indexing="xy")
    i, j = i.reshape(-1), j.reshape(-1)
    # corners in integer units (sqrt(3) a / 2, a / 2) about the centre (2i + j % 2, 3j), counter-clockwise
    dx = np.array([1, 0, -1, -1, 0, 1])
    dy = np.array([1, 2, 1, -1, -2, -1])
    ix = (2 * i + j % 2)[:, None] + dx
    iy = (3 * j)[:, None] + dy
    ix, iy = ix % (2 * nx), iy % (3 * ny)
    key = ix * (3 * ny) + iy
    unique, cells = np.unique(key.reshape(-1), return_inverse=True)
    pos = np.stack([(unique // (3 * ny)) * (np.sqrt(3.0) * a / 2), (unique % (3 * ny)) * (a / 2)], axis=1)
    return planar_from_polygons(pos, cells.reshape(-1, 6), box, device=device)


def planar_from_polygons(vertices, cells, box, device=CPU, validate=True) -> State:
    """A single-replica State on the periodic plane (see :func:`spherevm.init.from_polygons`)."""
    b = check_box(box)
    pos = np.asarray(vertices, dtype=np.float64)
    if pos.ndim != 2 or pos.shape[1] not in (2, 3):
        raise ValueError(f"vertices must have shape (n_vertices, 2) or (n_vertices, 3), got {pos.shape}")
    if not np.isfinite(pos).all():
        raise ValueError(f"vertices must be finite: vertex {int(np.flatnonzero(~np.isfinite(pos).all(1))[0])} is not")
    if pos.shape[1] == 3 and np.any(pos[:, 2] != 0):
        raise ValueError(f"vertices must lie in the plane z = 0: vertex {int(np.flatnonzero(pos[:, 2])[0])} does not")
    out = ((pos[:, :2] < 0) | (pos[:, :2] >= b)).any(axis=1)
    if out.any():
        v = int(np.flatnonzero(out)[0])
        raise ValueError(f"vertices must lie in the box [0, {b[0]:g}) x [0, {b[1]:g}): vertex {v} is at "
                         f"{pos[v, :2].tolist()}")
    full = np.zeros((len(pos), 3))
    full[:, :2] = pos[:, :2]
    cells = [list(map(int, c)) for c in cells]
    short = [i for i, c in enumerate(cells) if len(c) < 3]
    if short:
        raise ValueError(f"cell {short[0]} has {len(cells[short[0]])} vertices; cells need at least 3")
    table, sides = topology.pad_cells(cells)
    vn, vc = topology.build_vertex_tables(table, sides, len(full))
    bad = topology.repeated_adjacency(vn, vc)
    if bad is not None:
        raise ValueError(f"cells: the edge {bad} joins a cell to itself or to a cell it already borders: the "
                         "network is not simple (the box is too small for these cells)")
    return State(full, table, sides, vn, vc, [0, len(full)], [0, len(cells)], box=b, constraint=PeriodicPlane(),
                 device=device, validate=validate)
