"""Initial States: random tilings of the sphere (the paper's protocol), from polygons, regular
tilings, and from a GSD file."""
from __future__ import annotations

import numpy as np

from . import gsdio, topology
from .constraints import Sphere
from .device import CPU, resolve
from .init_surface import oriented_hull
from .state import State
from .validation import check_cell_size, check_tiling_memory, integer

REGULAR_TILINGS = ("dodecahedron", "truncated_icosahedron")
MAX_ATTEMPTS = 1000


def default_radius(n_cells: int) -> float:
    """sqrt(N / 4 pi): the radius at which the mean cell area <A> is 1."""
    return float(np.sqrt(n_cells / (4.0 * np.pi)))


def _check_radius(radius, n_cells):
    if radius is None:
        return default_radius(n_cells)
    r = float(radius)
    if not np.isfinite(r) or r <= 0:
        raise ValueError(f"radius must be positive and finite, got {radius}")
    check_cell_size("radius", radius, r * np.sqrt(4 * np.pi / n_cells),
                    "the default radius sqrt(N/4 pi) gives <A> = 1")
    return r


def dual_of_triangulation(points, triangles, radius, vertices="centroid"):
    """The trivalent tiling dual to a triangulated sphere (Voronoi-like, as in the paper).

    Each point becomes a cell; each triangle becomes a vertex at its centroid pushed onto the
    sphere (``vertices="centroid"``, the paper's choice) or at its circumcentre, the exact spherical
    Voronoi vertex (``"circumcenter"``). ``triangles`` must be counter-clockwise seen from outside.
    Returns local arrays
    ``(positions, cell_vertices, cell_sides, vertex_neighbors, vertex_cells)``.
    """
    tri = np.asarray(triangles, dtype=np.int64)
    pts = np.asarray(points, dtype=np.float64)
    p = pts[tri]
    if vertices == "centroid":
        direction = p.mean(axis=1)
    elif vertices == "circumcenter":
        direction = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    else:
        raise ValueError(f"vertices must be 'centroid' or 'circumcenter', got {vertices!r}")
    positions = radius * direction / np.linalg.norm(direction, axis=1)[:, None]
    return (positions,) + topology.dual_network(tri, len(pts))


def random_tiling(n_cells: int, replicas: int = 1, seed: int = 0, radius=None, vertices="centroid",
                  sort: bool = True, device=CPU, surface=None, size=None) -> State:
    """Random tilings of the sphere, the paper's initial condition (or of another surface: ``surface``).

    For each replica: ``n_cells`` points uniform on the sphere, their convex hull, and one vertex at
    the centroid of each hull facet pushed onto the sphere. Replica ``r`` uses the random stream
    ``(seed, r)``, so it does not depend on how many replicas are made. A draw with a cell larger
    than a hemisphere or folded (common for N < 16, below 1e-6 from N = 32) is redrawn from
    ``(seed, r, attempt)``: every tiling returned passes :meth:`State.validate`.

    Parameters
    ----------
    n_cells : int
        Cells per replica, >= 4.
    replicas : int
        Independent tilings, stored back to back.
    seed : int
    radius : float, optional
        Default ``sqrt(n_cells / 4 pi)``, so that <A> = 1.
    vertices : {"centroid", "circumcenter"}
        "circumcenter": vertices at the facet circumcentres, the exact spherical Voronoi tessellation.
    sort : bool
        Number cells and vertices along a Morton curve (:func:`spherevm.topology.morton_codes`), so
        that neighbours are close in memory (the GPU kernels gather several times faster).
    device : Device or str
    surface : ImplicitSurface, optional
        Tile this surface instead of the sphere (the torus, the ellipsoid, a periodic height field:
        :mod:`spherevm.init_surface`); ``radius`` and ``vertices`` do not apply.
    size : array (k,) or (replicas, k), optional
        With ``surface``: its parameters per replica; default its own, scaled so that <A> = 1.

    Returns
    -------
    State"""
    if surface is not None:
        if surface.missing(["tiling_points"]) or radius is not None:
            raise ValueError(f"surface must be one with random tilings (an ImplicitSurface: the torus, the ellipsoid, "
                             f"a periodic height field) and its parameters go in size, not radius; got {surface!r}"
                             f"{'' if radius is None else ' and radius'} (leave surface out for the sphere, use "
                             "random_planar_tiling for the plane)")
        from .init_surface import surface_tiling
        n = integer("n_cells", n_cells, minimum=4)
        keys = [(integer("seed", seed), r) for r in range(integer("replicas", replicas, minimum=1))]
        check_tiling_memory(f"random_tiling({n}, replicas={len(keys)})", n, len(keys), gpu=resolve(device).is_gpu)
        return surface_tiling(surface, n, keys, size=size, sort=sort, device=device)
    n = integer("n_cells", n_cells, minimum=4)
    replicas = integer("replicas", replicas, minimum=1)
    seed = integer("seed", seed)
    R = _check_radius(radius, n)
    check_tiling_memory(f"random_tiling({n}, replicas={replicas})", n, replicas, gpu=resolve(device).is_gpu)
    return _tilings(n, [(seed, r) for r in range(replicas)], R, vertices, sort, device)


def check_surface_spec(surface: str) -> str:
    """``surface`` if it names a surface with random tilings: "sphere", "plane", or an implicit
    surface's spec such as ``"torus:R=3,r=1"`` (:func:`spherevm.constraints.registry.surface`);
    else ValueError naming it."""
    if surface not in ("sphere", "plane"):
        from .constraints.registry import surface as named
        if named(surface).missing(["tiling_points"]):
            raise ValueError(f"surface {surface!r} has no random tilings; use sphere, plane or an implicit surface")
    return surface


def tilings_on(surface: str, n_cells: int, keys, device=CPU) -> State:
    """Random tilings (<A> = 1) of the random streams ``keys`` (``(seed, replica)`` pairs, one per
    replica) on the surface ``surface`` names (:func:`check_surface_spec`): the tilings of
    :func:`random_tiling` on "sphere", of :func:`random_planar_tiling` on "plane", of
    :mod:`spherevm.init_surface` on an implicit surface (the command line's ``--surface``)."""
    n = integer("n_cells", n_cells, minimum=4)
    check_tiling_memory(f"tilings of {n} cells on the {surface} ({len(keys)} replicas)", n, len(keys),
                        gpu=resolve(device).is_gpu)
    if surface == "sphere":
        return _tilings(n, keys, _check_radius(None, n), "centroid", True, device)
    if surface == "plane":
        from .init_plane import _planar_tilings, check_box
        return _planar_tilings(integer("n_cells", n, minimum=MIN_PLANAR_CELLS), keys, check_box(None, n), True,
                               device)
    from .constraints.registry import surface as named
    from .init_surface import surface_tiling
    return surface_tiling(named(check_surface_spec(surface)), n, keys, device=device)


def random_tilings(n_cells: int, seeds, radius=None, vertices="centroid", sort: bool = True, device=CPU) -> State:
    """One random tiling per seed, as an ensemble: replica ``i`` equals
    ``random_tiling(n_cells, seed=seeds[i])``, built with one convex hull per tiling and one
    vectorised pass for everything else.

    Parameters
    ----------
    n_cells : int
    seeds : sequence of int or tuple
    radius, vertices, sort, device
        As in :func:`random_tiling`.

    Returns
    -------
    State"""
    n = int(n_cells)
    if n != n_cells or n < 4:
        raise ValueError(f"n_cells must be an integer >= 4, got {n_cells}")
    seeds = [int(x) for x in seeds]
    if not seeds or min(seeds) < 0:
        raise ValueError("seeds must be a non-empty list of non-negative integers")
    R = _check_radius(radius, n)
    check_tiling_memory(f"random_tilings({n}, {len(seeds)} seeds)", n, len(seeds), gpu=resolve(device).is_gpu)
    return _tilings(n, [(x, 0) for x in seeds], R, vertices, sort, device)


def _draw_hull(n, key, attempt):
    """Points of stream ``key`` (+ attempt) and their hull; None if the origin lies outside it."""
    rng = np.random.default_rng(list(key) + ([attempt] if attempt else []))
    pts = rng.normal(size=(n, 3))
    pts /= np.linalg.norm(pts, axis=1)[:, None]
    tri, origin_inside = oriented_hull(pts)
    return (pts, tri) if origin_inside else None


def _tilings(n, keys, R, vertices, sort, device):
    """Build the tilings of the given streams: a convex hull each, then one batched dual."""
    attempts = np.zeros(len(keys), dtype=int)
    hulls = [None] * len(keys)
    todo = list(range(len(keys)))
    while todo:
        for i in todo:  # initialisation only, not a per-step path: one Qhull call per tiling
            while True:
                if attempts[i] >= MAX_ATTEMPTS:
                    raise RuntimeError(f"no valid random tiling of {n} cells in {MAX_ATTEMPTS} draws (stream "
                                       f"{keys[i]}); use more cells or vertices='circumcenter'")
                hulls[i] = _draw_hull(n, keys[i], attempts[i])
                if hulls[i] is not None:
                    break
                attempts[i] += 1
        state = _batched_dual(n, hulls, R, vertices, sort)
        area = state.constraint.cell_areas_np(state)
        half = 0.5 * state.constraint.total_area_np(R)            # a cell over a hemisphere is refused too
        folded = np.unique(state.cell_replica_np()[(area <= 0) | (area > half)])   # a very obtuse facet
        attempts[folded] += 1
        todo = folded.tolist()
    state = state.to(device) if device is not CPU else state
    state.validate(orientation=False)   # every cell's area was just found positive (the loop above)
    return state


def _batched_dual(n, hulls, R, vertices, sort):
    """The dual tilings of several hulls at once, stored back to back as replicas."""
    n_tri = 2 * n - 4
    pts = np.concatenate([h[0] for h in hulls])
    tri = np.concatenate([h[1] + k * n for k, h in enumerate(hulls)])
    pos, table, sides, vn, vc = dual_of_triangulation(pts, tri, R, vertices)
    reps = len(hulls)
    if sort:   # Morton order inside each replica; replicas stay back to back
        vrep = np.repeat(np.arange(reps), n_tri)
        crep = np.repeat(np.arange(reps), n)
        vorder = np.lexsort((topology.morton_codes(pos), vrep))
        corder = np.lexsort((topology.morton_codes(pts), crep))
        pos, table, sides, vn, vc = topology.renumber(pos, table, sides, vn, vc, vorder, corder)
    return State(pos, table, sides, vn, vc, np.arange(reps + 1) * n_tri, np.arange(reps + 1) * n, R,
                 constraint=Sphere(), validate=False)


def from_polygons(vertices, cells, radius=None, device=CPU, validate=True, box=None) -> State:
    """A single-replica State from vertex positions and counter-clockwise cell vertex lists.

    Parameters
    ----------
    vertices : array (V, 3)
        Projected onto the sphere of the given radius; on the plane (V, 2) or (V, 3) with z = 0,
        inside ``[0, Lx) x [0, Ly)``.
    cells : list of lists of int
        Each cell's vertices, counter-clockwise seen from outside (from +z on the plane, edges the
        minimum images, see :mod:`spherevm.init_plane`). The network must be trivalent.
    radius : float, optional
        The sphere's radius.
    device : Device or str
    validate : bool
        Check the network.
    box : (Lx, Ly), optional
        Instead of a radius: the State lives on a :class:`~spherevm.constraints.PeriodicPlane`.

    Returns
    -------
    State"""
    if box is not None or radius is None:
        if radius is not None:
            raise ValueError("give radius (a sphere) or box (a periodic plane), not both")
        if box is None:
            raise ValueError("from_polygons needs radius (a sphere) or box (a periodic plane)")
        from .init_plane import planar_from_polygons
        return planar_from_polygons(vertices, cells, box, device=device, validate=validate)
    R = float(radius)
    if not np.isfinite(R) or R <= 0:
        raise ValueError(f"radius must be positive and finite, got {radius}")
    pos = np.asarray(vertices, dtype=np.float64)
    if pos.ndim != 2 or pos.shape[1] != 3:
        raise ValueError(f"vertices must have shape (n_vertices, 3), got {pos.shape}")
    if not np.isfinite(pos).all():
        raise ValueError(f"vertices must be finite: vertex {int(np.flatnonzero(~np.isfinite(pos).all(1))[0])} is not")
    norms = np.linalg.norm(pos, axis=1)
    if np.any(norms == 0):
        raise ValueError(f"vertex {int(np.flatnonzero(norms == 0)[0])} is at the sphere's centre")
    pos = R * pos / norms[:, None]
    cells = [list(map(int, c)) for c in cells]
    short = [i for i, c in enumerate(cells) if len(c) < 3]
    if short:
        raise ValueError(f"cell {short[0]} has {len(cells[short[0]])} vertices; cells need at least 3")
    table, sides = topology.pad_cells(cells)
    vn, vc = topology.build_vertex_tables(table, sides, len(pos))
    return State(pos, table, sides, vn, vc, [0, len(pos)], [0, len(cells)], R, constraint=Sphere(),
                 device=device, validate=validate)


def _icosahedron():
    import trimesh
    ico = trimesh.creation.icosahedron()
    v = np.asarray(ico.vertices, dtype=np.float64)
    return v / np.linalg.norm(v, axis=1)[:, None], np.asarray(ico.faces, dtype=np.int64)


def _ccw_cells(points, groups):
    """Order each group of vertex indices counter-clockwise about its centre, seen from outside."""
    cells = []
    for g in groups:
        g = np.asarray(g)
        c = points[g].mean(axis=0)
        n = c / np.linalg.norm(c)
        e1 = points[g[0]] - c
        e1 -= e1.dot(n) * n
        e2 = np.cross(n, e1)
        d = points[g] - c
        cells.append(g[np.argsort(np.arctan2(d @ e2, d @ e1))].tolist())
    return cells


def regular_tiling(name: str, radius=None, device=CPU) -> State:
    """A regular (Platonic or Archimedean) tiling of the sphere.

    Parameters
    ----------
    name : {"dodecahedron", "truncated_icosahedron"}
        12 regular pentagons (20 vertices), or 12 regular pentagons and 20 regular hexagons (60
        vertices, all edges equal), the football.
    radius : float, optional
        Default ``sqrt(N / 4 pi)``.
    device : Device or str

    Returns
    -------
    State"""
    if name not in REGULAR_TILINGS:
        raise ValueError(f"name must be one of {REGULAR_TILINGS}, got {name!r}")
    ico_v, ico_f = _icosahedron()
    if name == "dodecahedron":
        verts = ico_v[ico_f].mean(axis=1)
        groups = [np.flatnonzero((ico_f == i).any(axis=1)) for i in range(len(ico_v))]
    else:  # cut each icosahedron edge in thirds: regular pentagons and hexagons
        edges = np.unique(np.sort(np.concatenate([ico_f[:, [0, 1]], ico_f[:, [1, 2]], ico_f[:, [2, 0]]]), axis=1),
                          axis=0)
        near = {}
        verts = []
        for i, j in edges:
            for a, b in ((i, j), (j, i)):
                near[(a, b)] = len(verts)
                verts.append(ico_v[a] + (ico_v[b] - ico_v[a]) / 3.0)
        verts = np.array(verts)
        groups = [[near[(i, j)] for (a, j) in near if a == i] for i in range(len(ico_v))]
        groups += [[near[(i, j)], near[(j, i)], near[(j, k)], near[(k, j)], near[(k, i)], near[(i, k)]]
                   for i, j, k in ico_f]
    n_cells = len(groups)
    R = _check_radius(radius, n_cells)
    verts = verts / np.linalg.norm(verts, axis=1)[:, None]
    return from_polygons(verts, _ccw_cells(verts, groups), R, device=device)


from .init_plane import MIN_PLANAR_CELLS, hexagonal_tiling, random_planar_tiling, random_planar_tilings  # noqa: E402,F401  (re-exported)


def from_gsd(path, frame: int = -1, device=CPU, validate: bool = True, orientation: bool = False) -> State:
    """The State of a frame of a spherevm GSD file, restored exactly: bitwise positions, identical
    topology (see :func:`spherevm.gsdio.read_state`).

    Parameters
    ----------
    path : str or path
    frame : int
        Frame index, negative from the end.
    device : Device or str
    validate : bool
        Check the stored network, naming the file, frame and first bad entry.
    orientation : bool
        Also require positive cell areas (off by default: at kA = 0 a valid run may fold a cell).

    Returns
    -------
    State"""
    return gsdio.read_state(path, frame=frame, device=device, validate=validate, orientation=orientation)
