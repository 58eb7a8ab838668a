"""Random tilings of implicit surfaces (:class:`~spherevm.constraints.ImplicitSurface`): the torus,
the ellipsoid, periodic height fields (the Gaussian bump, a user's own), through
``svm.init.random_tiling(n_cells, replicas, seed, surface=...)``.

Per replica: ``n_cells`` points uniform by area (rejection sampling against the area element of a
parametrisation), a triangulation with the surface's Euler characteristic, and its dual: one cell per
point, one vertex per triangle at the triangle's centroid moved onto the surface (closest point):

* closed genus-0 surfaces (the ellipsoid): the convex hull of the points' directions, as on the sphere;
* the torus: the periodic Delaunay triangulation of the angles (phi, theta) drawn in the rectangle
  ``2 pi R x 2 pi r`` (lengths along the outer equator and around the tube), vertices at its
  Voronoi vertices mapped onto the torus;
* periodic height fields: the plane's periodic Voronoi tessellation of (x, y), lifted onto the surface.

By default each replica's surface is its shape (the constraint's parameters) scaled by one factor,
so that the mean cell area is 1: every parameter is a length (R and r; a, b, c; Lx, Ly, height and
width), so the area scales as the factor squared.
"""
from __future__ import annotations

import numpy as np
from scipy.spatial import ConvexHull

from . import topology
from .device import CPU
from .init_plane import periodic_voronoi
from .state import State

MAX_ATTEMPTS = 200


def scaled_sizes(surface, n_cells, replicas, size=None) -> np.ndarray:
    """The parameters of each replica ``(replicas, k)``: ``size`` (one row or one per replica) if
    given, else the surface's shape scaled to mean cell area 1."""
    if size is not None:
        s = surface.check_size(size)
        if len(s) not in (1, replicas):
            raise ValueError(f"size must give one row or one per replica ({replicas}), got {len(s)}")
        return np.broadcast_to(s, (replicas, s.shape[1])).copy()
    shape = np.asarray(surface.shape, dtype=np.float64)
    scale = np.sqrt(n_cells / float(surface.total_area_np(shape)))
    return np.tile(scale * shape, (replicas, 1))


def _network(surface, rng, n, size):
    """One draw: ``(positions, cell_vertices, cell_sides, vertex_neighbors, vertex_cells, points)``,
    or None if the network is not simple (or the hull does not hold the origin)."""
    points, plane, box = surface.tiling_points(rng, n, size)
    if plane is not None:
        net = periodic_voronoi(plane, box)
        if net is None:
            return None
        return (surface.project_normal(surface.from_plane(net[0][:, :2], size), size),) + net[1:] + (points,)
    tri, inside = oriented_hull(points / np.linalg.norm(points, axis=1)[:, None])
    if not inside:
        return None
    return (surface.project_normal(points[tri].mean(axis=1), size),) + topology.dual_network(tri, n) + (points,)


def oriented_hull(points):
    """Counter-clockwise hull triangles, and whether the origin lies strictly inside the hull."""
    hull = ConvexHull(points)
    tri = hull.simplices.copy()
    p = points[tri]
    # qhull's facet equations give the outward normals, also when the origin lies outside the hull
    outward = np.einsum("ij,ij->i", np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), hull.equations[:, :3]) > 0
    tri[~outward] = tri[~outward][:, [0, 2, 1]]
    return tri, bool(np.all(hull.equations[:, 3] < 0))


def surface_tiling(surface, n_cells: int, keys, size=None, sort: bool = True, device=CPU) -> State:
    """The tilings of the random streams ``keys`` (one ``(seed, replica)`` each) on ``surface``, one
    replica each (see the module docstring); a draw whose network is not simple or has a folded cell
    is redrawn from ``(seed, replica, attempt)``."""
    sizes = scaled_sizes(surface, n_cells, len(keys), size)
    states = []
    for key, s in zip(keys, sizes):
        least = surface.minimum_cells(s)
        if n_cells < least:
            raise ValueError(f"n_cells must be at least {least} to tile {surface!r} with parameters "
                             f"{dict(zip(surface.size_names, s.round(6).tolist()))}, got {n_cells}")
        for attempt in range(MAX_ATTEMPTS):
            rng = np.random.default_rng(list(key) + ([attempt] if attempt else []))
            net = _network(surface, rng, n_cells, s)
            if net is None:
                continue
            state = _state(surface, net, s, sort)
            try:
                state.validate()
                break
            except ValueError:
                continue
        else:
            raise ValueError(f"no valid tiling of {surface!r} with {n_cells} cells in {MAX_ATTEMPTS} draws (stream "
                             f"{key}); use more cells")
        states.append(state)
    state = states[0] if len(states) == 1 else State.concatenate(states)
    return state.to(device) if device is not CPU else state


def _state(surface, net, size, sort):
    pos, table, sides, vn, vc, points = net
    if sort:
        codes = (topology.morton_codes(pos - pos.mean(axis=0)), topology.morton_codes(points - points.mean(axis=0)))
        pos, table, sides, vn, vc = topology.renumber(pos, table, sides, vn, vc, *(np.argsort(c, kind="stable")
                                                                                  for c in codes))
    return State(pos, table, sides, vn, vc, [0, len(pos)], [0, len(sides)], size=size, constraint=surface,
                 validate=False)


__all__ = ["oriented_hull", "scaled_sizes", "surface_tiling"]
