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
from .init_plane import MIN_PLANAR_CELLS, periodic_voronoi
from .state import State

MAX_ATTEMPTS = 200
#: the fewest cells of a tiling of an implicit surface (smaller cells are not measured well by flat
#: facets, and small periodic networks are rarely simple)
MIN_SURFACE_CELLS = 16
#: the torus's tube must be at least this many cell sides around: (2 pi r)^2 / <A> >= 9, so
#: n_cells >= 9 R / r (measured: 20 tilings each at R/r = 3 all simple from 28 cells on)
MIN_CELLS_AROUND_TUBE = 3.0


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


def minimum_cells(surface, size) -> int:
    """The fewest cells this tiling builds on ``surface`` of parameters ``size`` (k,)."""
    if surface.name == "torus":
        return max(MIN_SURFACE_CELLS, int(np.ceil(MIN_CELLS_AROUND_TUBE ** 2 * size[0] / size[1])))
    return MIN_SURFACE_CELLS


def _rejection(rng, n, draw, density):
    """``n`` draws of ``draw(rng, m)`` accepted with probability ``density(sample)`` (<= 1)."""
    kept, count = [], 0
    while count < n:
        sample = draw(rng, 2 * n)
        sample = sample[rng.random(len(sample)) < density(sample)]
        kept.append(sample)
        count += len(sample)
    return np.concatenate(kept)[:n]


def _torus_points(rng, n, size):
    R, r = size
    angles = _rejection(rng, n, lambda g, m: g.random((m, 2)) * 2 * np.pi,
                        lambda a: (R + r * np.cos(a[:, 1])) / (R + r))
    return angles * np.array([R, r])            # (R phi, r theta)


def _torus_map(plane, size):
    R, r = size
    phi, theta = plane[:, 0] / R, plane[:, 1] / r
    rho = R + r * np.cos(theta)
    return np.stack([rho * np.cos(phi), rho * np.sin(phi), r * np.sin(theta)], axis=1)


def _ellipsoid_points(rng, n, size):
    from .constraints.ellipsoid import area_element
    a, b, c = size
    bound = max(a * b, c * max(a, b))
    uphi = _rejection(rng, n, lambda g, m: np.stack([2 * g.random(m) - 1, 2 * np.pi * g.random(m)], axis=1),
                      lambda s: area_element(s[:, 0], s[:, 1], a, b, c) / bound)
    u, phi = uphi.T
    s = np.sqrt(1 - u * u)
    return np.stack([a * s * np.cos(phi), b * s * np.sin(phi), c * u], axis=1)


def lift(surface, xy, size):
    """Points of a periodic height field above ``xy`` (n, 2): Newton steps in z alone from z = 0."""
    x = np.zeros((len(xy), 3))
    x[:, :2] = xy
    for _ in range(surface.max_iterations):
        f = surface.F(x, size)
        step = f / surface.grad_F(x, size)[:, 2]
        x[:, 2] -= step
        if np.all(np.abs(step) <= surface.tolerance * surface.length_scale(size)):
            return x
    raise RuntimeError(f"{surface!r}: lifting points onto the height field did not converge")


def _height_points(surface, rng, n, size):
    box = size[:2]

    def density(xy):
        g = surface.grad_F(lift(surface, xy, size), size)
        return np.sqrt((g * g).sum(axis=1)) / np.abs(g[:, 2])

    if hasattr(surface, "area_density_bound"):
        bound = surface.area_density_bound(size)
    else:                    # the largest area element on a fine grid, with a margin
        grid = (np.stack(np.meshgrid(np.arange(256), np.arange(256)), axis=-1).reshape(-1, 2) + 0.5) / 256 * box
        bound = 1.1 * float(density(grid).max())
    return _rejection(rng, n, lambda g, m: g.random((m, 2)) * box, lambda xy: density(xy) / bound)


def _network(surface, rng, n, size):
    """One draw: ``(positions, cell_vertices, cell_sides, vertex_neighbors, vertex_cells, points)``,
    or None if the network is not simple."""
    if surface.periodic:
        xy = _height_points(surface, rng, n, size)
        net = periodic_voronoi(xy, size[:2])
        if net is None:
            return None
        pos = lift(surface, net[0][:, :2], size)
        return (pos,) + net[1:] + (lift(surface, xy, size),)
    if surface.euler_characteristic == 0:          # the torus
        box = 2 * np.pi * np.asarray(size)
        plane = _torus_points(rng, n, size)
        net = periodic_voronoi(plane, box)
        if net is None:
            return None
        pos = surface.project_normal(_torus_map(net[0][:, :2], size), size)
        return (pos,) + net[1:] + (_torus_map(plane, size),)
    pts = _ellipsoid_points(rng, n, size)
    tri, inside = oriented_hull(pts / np.linalg.norm(pts, axis=1)[:, None])
    if not inside:
        return None
    pos = surface.project_normal(pts[tri].mean(axis=1), size)
    return (pos,) + topology.dual_network(tri, n) + (pts,)


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
        least = minimum_cells(surface, s)
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
        if surface.periodic:
            codes = (topology.morton_codes_2d(pos, size[:2]), topology.morton_codes_2d(points, size[:2]))
        else:
            codes = (topology.morton_codes(pos), topology.morton_codes(points))
        pos, table, sides, vn, vc = topology.renumber(pos, table, sides, vn, vc, *(np.argsort(c, kind="stable")
                                                                                  for c in codes))
    return State(pos, table, sides, vn, vc, [0, len(pos)], [0, len(sides)], size=size, constraint=surface,
                 validate=False)


__all__ = ["MIN_PLANAR_CELLS", "surface_tiling"]
