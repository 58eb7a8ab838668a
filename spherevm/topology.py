"""Trivalent cell networks: building them from polygons, checking them, listing edges.

Conventions (all indices global over the replicas of a State):

* ``vertex_neighbors[v] = (n0, n1, n2)`` counter-clockwise seen from outside the surface;
* ``vertex_cells[v, k]`` is the cell lying between the edges ``v -> n_k`` and ``v -> n_{k+1}``; in
  that cell's counter-clockwise vertex list ``n_k`` follows ``v`` and ``n_{k+1}`` precedes it;
* ``cell_vertices[c]`` lists the cell's vertices counter-clockwise, padded with -1 up to
  ``max_sides``; ``cell_sides[c]`` counts them.

So the ``(n_vertices, 3)`` arrays list every cell corner exactly once: corner ``(v, k)`` lies in cell
``vertex_cells[v, k]`` and owns that cell's edge ``v -> vertex_neighbors[v, k]``.
"""
from __future__ import annotations

import numpy as np

from . import simplicity


def pad_cells(cells, min_width: int = 0):
    """List of vertex lists -> (padded int32 table, sides)."""
    sides = np.array([len(c) for c in cells], dtype=np.int32)
    width = max(int(sides.max()) if len(sides) else 0, min_width)
    table = np.full((len(cells), width), -1, dtype=np.int32)
    mask = np.arange(width)[None, :] < sides[:, None]
    table[mask] = np.concatenate([np.asarray(c, dtype=np.int64) for c in cells]) if len(cells) else []
    return table, sides


def cell_corners(cell_vertices, cell_sides):
    """Every corner of the padded table: (cell, vertex, next vertex, previous vertex), flat."""
    cv = np.asarray(cell_vertices)
    sides = np.asarray(cell_sides)
    n_cells, width = cv.shape
    col = np.arange(width)[None, :]
    valid = col < sides[:, None]
    nxt_col = (col + 1) % sides[:, None]
    prv_col = (col - 1) % sides[:, None]
    rows = np.broadcast_to(np.arange(n_cells)[:, None], cv.shape)
    cell = rows[valid]
    vert = cv[valid]
    nxt = cv[rows, nxt_col][valid]
    prv = cv[rows, prv_col][valid]
    return cell, vert, nxt, prv


def build_vertex_tables(cell_vertices, cell_sides, n_vertices: int):
    """Derive ``vertex_neighbors`` and ``vertex_cells`` from counter-clockwise cells.

    Raises ValueError naming the first vertex that is not trivalent or whose corners do not close
    into one fan (a sign of a clockwise or inconsistent cell).
    """
    cell, vert, nxt, prv = cell_corners(cell_vertices, cell_sides)
    if len(vert) and (vert.min() < 0 or vert.max() >= n_vertices):
        bad = int(np.flatnonzero((vert < 0) | (vert >= n_vertices))[0])
        raise ValueError(f"cell {int(cell[bad])} refers to vertex {int(vert[bad])}, outside 0..{n_vertices - 1}")
    counts = np.bincount(vert, minlength=n_vertices)
    if np.any(counts != 3):
        v = int(np.flatnonzero(counts != 3)[0])
        raise ValueError(f"network is not trivalent: vertex {v} is a corner of {int(counts[v])} cells "
                         "(every vertex must belong to exactly 3 cells)")
    order = np.argsort(vert, kind="stable")
    c3 = cell[order].reshape(n_vertices, 3)
    nx3 = nxt[order].reshape(n_vertices, 3)
    pv3 = prv[order].reshape(n_vertices, 3)
    # Put the three corners in counter-clockwise order: corner j follows corner i when prev_i == next_j.
    swap = pv3[:, 0] != nx3[:, 1]
    for arr in (c3, nx3, pv3):
        arr[swap, 1], arr[swap, 2] = arr[swap, 2].copy(), arr[swap, 1].copy()
    closed = (pv3[:, 0] == nx3[:, 1]) & (pv3[:, 1] == nx3[:, 2]) & (pv3[:, 2] == nx3[:, 0])
    if not np.all(closed):
        v = int(np.flatnonzero(~closed)[0])
        raise ValueError(f"the cells around vertex {v} (cells {sorted(set(c3[v].tolist()))}) do not close "
                         "into a fan: some cell is listed clockwise or shares an edge wrongly")
    return nx3.astype(np.int32), c3.astype(np.int32)


def dual_network(tri, n_pts):
    """The trivalent network dual to counter-clockwise triangles ``tri`` of ``n_pts`` points (each
    directed edge once): ``(cell_vertices, cell_sides, vertex_neighbors, vertex_cells)``."""
    tri = np.asarray(tri, dtype=np.int64)      # the edge keys reach n_pts**2: int32 keys collide from 65,536 points
    n_tri = len(tri)
    # neighbour across the directed edge (i, j) of triangle t is the triangle holding (j, i)
    key = tri * n_pts + np.roll(tri, -1, axis=1)          # edge (t[k], t[k+1]) sits in slot k
    rev = np.roll(tri, -1, axis=1) * n_pts + tri
    order = np.argsort(key.reshape(-1))
    sorted_keys = key.reshape(-1)[order]
    across = order[np.searchsorted(sorted_keys, rev.reshape(-1))] // 3
    across = across.reshape(n_tri, 3)
    # cells around triangle t=(i, j, k) counter-clockwise are (i, j, k); cell i lies between the
    # neighbours across (k, i) and (i, j)
    vertex_cells = tri.astype(np.int32)
    vertex_neighbors = np.roll(across, 1, axis=1).astype(np.int32)
    table, sides = cell_table(vertex_neighbors, vertex_cells, n_pts)
    return table, sides, vertex_neighbors, vertex_cells


def edges(vertex_neighbors):
    """Unique undirected edges ``(E, 2)`` with ``u < v``, in order of ``u`` then of ``v``'s slot."""
    vn = np.asarray(vertex_neighbors)
    u = np.repeat(np.arange(len(vn)), 3)
    v = vn.reshape(-1)
    keep = u < v
    return np.stack([u[keep], v[keep]], axis=1).astype(np.int32)


def check(state, tol: float = 1e-9, orientation: bool = True, cover: bool = True, simple: bool = True):
    """Validate a State; raise ValueError naming the first offending cell or vertex.

    Checks: finite positions on the surface, trivalent network with reciprocal neighbours, cell
    table and vertex tables consistent (so every edge is shared by exactly two cells, once in each
    direction), replica layout, V - E + F = 2 per replica, then :func:`spherevm.simplicity.check`:
    cells closed under the minimum image (a periodic plane), the cells covering the surface once
    (their areas add up to its area, none over a hemisphere), simple (no edge crossing another of
    its cell) and counter-clockwise (positive area) cells. ``orientation=False`` skips the last two:
    at kA = 0 the energy does not care about area, and minimisation may legitimately fold a cell
    over; ``simple=False`` skips the crossing test alone. ``cover=False`` skips all of them, for
    networks that are not physical states (random walks of T1 tests on tiny spheres).
    """
    pos = state.device.to_numpy(state.positions)
    vn = state.device.to_numpy(state.vertex_neighbors)
    vc = state.device.to_numpy(state.vertex_cells)
    cv = state.device.to_numpy(state.cell_vertices)
    sides = state.device.to_numpy(state.cell_sides)
    nv, nc = len(pos), len(sides)
    if pos.shape != (nv, 3) or vn.shape != (nv, 3) or vc.shape != (nv, 3):
        raise ValueError("positions, vertex_neighbors and vertex_cells must all have shape (n_vertices, 3)")
    if cv.ndim != 2 or cv.shape[0] != nc:
        raise ValueError("cell_vertices must have shape (n_cells, max_sides)")
    bad = ~np.isfinite(pos).all(axis=1)
    if bad.any():
        raise ValueError(f"positions must be finite: vertex {int(np.flatnonzero(bad)[0])} is {pos[bad][0]}")
    if np.any(sides < 3) or np.any(sides > cv.shape[1]):
        c = int(np.flatnonzero((sides < 3) | (sides > cv.shape[1]))[0])
        raise ValueError(f"cell {c} has {int(sides[c])} sides; cells need 3 <= sides <= max_sides={cv.shape[1]}")
    for name, arr, hi in (("vertex_neighbors", vn, nv), ("vertex_cells", vc, nc)):
        if arr.min(initial=0) < 0 or arr.max(initial=0) >= hi:
            v = int(np.flatnonzero(((arr < 0) | (arr >= hi)).any(axis=1))[0])
            raise ValueError(f"{name} of vertex {v} is {arr[v].tolist()}, outside 0..{hi - 1}")
    # replica layout: every edge and every corner stays inside its replica
    vrep, crep = state.vertex_replica_np(), state.cell_replica_np()
    cross = (vrep[vn] != vrep[:, None]).any(axis=1) | (crep[vc] != vrep[:, None]).any(axis=1)
    if cross.any():
        raise ValueError(f"vertex {int(np.flatnonzero(cross)[0])} is connected to another replica")
    # derive the vertex tables from the cells and compare (trivalence, fans, two cells per edge)
    ref_vn, ref_vc = build_vertex_tables(cv, sides, nv)
    # the stored tables may start their cyclic order at any slot: rotate to compare
    same = np.zeros(nv, dtype=bool)
    for shift in range(3):
        rn, rc = np.roll(ref_vn, shift, axis=1), np.roll(ref_vc, shift, axis=1)
        same |= (rn == vn).all(axis=1) & (rc == vc).all(axis=1)
    if not same.all():
        v = int(np.flatnonzero(~same)[0])
        raise ValueError(f"vertex {v}: vertex_neighbors {vn[v].tolist()} / vertex_cells {vc[v].tolist()} "
                         f"disagree with the cell table (expected {ref_vn[v].tolist()} / {ref_vc[v].tolist()})")
    back = (vn[vn] == np.arange(nv)[:, None, None]).any(axis=2)
    if not back.all():
        v = int(np.flatnonzero(~back.all(axis=1))[0])
        raise ValueError(f"vertex {v} lists neighbours {vn[v].tolist()} that do not list it back")
    # on the surface
    con = state.constraint
    size = con.size_np(state)[vrep]
    dist = con.distance_to_surface(pos, size)
    off = np.abs(dist) > tol * con.length_scale(size)
    if off.any():
        v = int(np.flatnonzero(off)[0])
        raise ValueError(f"vertex {v} is off the surface by {dist[v]:.3g} (allowed {tol:g} R); "
                         "project positions with the constraint first")
    outside = getattr(con, "outside_box", None)
    if outside is not None and outside(pos, size).any():
        v = int(np.flatnonzero(outside(pos, size))[0])
        raise ValueError(f"vertex {v} at {pos[v, :2].tolist()} lies outside its periodic box "
                         f"{size[v].tolist()}: wrap positions into [0, Lx) x [0, Ly) (constraint.project_normal)")
    # Euler characteristic per replica: V - E + F with E = 3V/2
    nvr = np.diff(state.vertex_start)
    ncr = np.diff(state.cell_start)
    chi = nvr - 3 * nvr // 2 + ncr
    want = getattr(con, "euler_characteristic", 2)
    if np.any(nvr % 2) or np.any(chi != want):
        r = int(np.flatnonzero((chi != want) | (nvr % 2 == 1))[0])
        raise ValueError(f"replica {r} has Euler characteristic V - E + F = {int(chi[r])}, {con!r} needs {want}")
    if cover and not con.missing(("cell_geometry",)):
        simplicity.check(state, orientation=orientation, simple=simple)


def cell_table(vertex_neighbors, vertex_cells, n_cells: int, min_width: int = 0):
    """Padded counter-clockwise cell table and side counts from the vertex tables.

    Walks every cell at once by its successor map (inside cell ``vertex_cells[v, k]`` vertex
    ``vertex_neighbors[v, k]`` follows ``v``): ``max_sides`` vectorised steps, no loop over cells.
    """
    vn = np.asarray(vertex_neighbors).reshape(-1)
    vc = np.asarray(vertex_cells).reshape(-1)
    n_v = len(vn) // 3
    corner_v = np.repeat(np.arange(n_v, dtype=np.int64), 3)
    sides = np.bincount(vc, minlength=n_cells).astype(np.int32)
    if np.any(sides < 1):
        raise ValueError(f"cell {int(np.flatnonzero(sides < 1)[0])} has no vertex")
    keys = vc.astype(np.int64) * n_v + corner_v
    order = np.argsort(keys)
    skeys, snext = keys[order], vn[order]
    first = np.empty(n_cells, dtype=np.int64)
    first[vc[::-1]] = corner_v[::-1]
    width = max(int(sides.max()), min_width)
    table = np.full((n_cells, width), -1, dtype=np.int32)
    cur = first
    cells = np.arange(n_cells, dtype=np.int64)
    for col in range(width):  # max_sides steps, each vectorised over all cells
        live = col < sides
        table[live, col] = cur[live]
        cur = snext[np.searchsorted(skeys, cells * n_v + cur)]
    return table, sides


# ---------------------------------------------------------------------- T1 neighbour exchange
def t1_cells(vertex_neighbors, vertex_cells, u, slot):
    """The four cells and four outer neighbours around the edges ``(u, vertex_neighbors[u, slot])``.

    Returns ``v, a, b, c, d, C1, C2, C3, C4`` (arrays): ``C1`` holds the edge as ``u -> v``
    (counter-clockwise), ``C2`` as ``v -> u``; ``C3`` and ``C4`` are the third cells at ``u`` and
    ``v``. ``a, b`` are u's other neighbours (``a`` on the ``C1`` side), ``c, d`` v's (``d`` on the
    ``C1`` side): counter-clockwise, ``C1 = (.., a, u, v, d, ..)`` and ``C2 = (.., c, v, u, b, ..)``.
    """
    vn, vc = vertex_neighbors, vertex_cells
    k1, k2 = (slot + 1) % 3, (slot + 2) % 3
    v = vn[u, slot]
    a, b = vn[u, k1], vn[u, k2]
    C1, C3, C2 = vc[u, slot], vc[u, k1], vc[u, k2]
    j = (vn[v] == u[:, None]).argmax(axis=1)
    c, d = vn[v, (j + 1) % 3], vn[v, (j + 2) % 3]
    C4 = vc[v, (j + 1) % 3]
    return v, a, b, c, d, C1, C2, C3, C4


def _remove_from_rows(table, sides, rows, vert):
    width = table.shape[1]
    sub = table[rows]
    p = (sub == vert[:, None]).argmax(axis=1)
    j = np.arange(width)[None, :]
    src = np.minimum(j + (j >= p[:, None]), width - 1)
    new = np.take_along_axis(sub, src, axis=1)
    new[j >= (sides[rows] - 1)[:, None]] = -1
    table[rows] = new
    sides[rows] -= 1


def _split_in_rows(table, sides, rows, vert, first, second):
    """Replace ``vert`` in each row by the pair ``first, second`` (the row must have room)."""
    width = table.shape[1]
    sub = table[rows]
    p = (sub == vert[:, None]).argmax(axis=1)
    j = np.arange(width)[None, :]
    src = np.maximum(j - (j > p[:, None]), 0)
    new = np.take_along_axis(sub, src, axis=1)
    r = np.arange(len(rows))
    new[r, p] = first
    new[r, p + 1] = second
    new[j >= (sides[rows] + 1)[:, None]] = -1
    table[rows] = new
    sides[rows] += 1


def t1_new_positions(state, pos, u, v, a, b, c, d, new_length, turn=None):
    """Where a T1 flip of the edges ``(u, v)`` puts its two vertices: ``(on the C1 side, on the C2
    side)``, rotating each edge by 90 degrees about the surface normal at its midpoint, the two
    points ``new_length`` apart symmetrically about it (``pos``: host positions; a..d as from
    :func:`t1_cells`). ``turn`` (a mask): rotate those edges the other way, the C1-side vertex to
    the other side (where the usual way would fold the network, :func:`spherevm.folding.t1_placement`).
    The CUDA twin is ``Surface::t1_positions`` (geometry/surface.cuh)."""
    con = state.constraint
    size = con.size_np(state)[state.vertex_replica_np()[u]]       # each edge's surface size
    pu = pos[u]
    pv, pa, pb, pc, pd = (con.unwrap(pos[w], pu, size) for w in (v, a, b, c, d))  # nearest images
    mid = con.project_normal(0.5 * (pu + pv), size)
    normal = con.normal(mid, size)
    along = con.project_tangent(mid, pv - pu, size)
    norm = np.linalg.norm(along, axis=1)
    # a zero-length edge has no direction: fall back to the direction between the cells' sides
    across_c1 = con.project_tangent(mid, 0.5 * (pa + pd) - 0.5 * (pb + pc), size)
    tiny = norm <= 1e-12 * con.length_scale(size)
    perp = np.cross(normal, along / np.where(tiny, 1.0, norm)[:, None])
    perp[tiny] = across_c1[tiny]
    if turn is not None:
        perp[np.asarray(turn, dtype=bool)] *= -1.0
    perp /= np.linalg.norm(perp, axis=1)[:, None]
    half = 0.5 * np.broadcast_to(np.asarray(new_length, dtype=np.float64), u.shape)
    return con.geodesic_offset(mid, perp, half, size), con.geodesic_offset(mid, -perp, half, size)


def t1_flip(state, u, slot, new_length, sense: int = 1, turn=None):
    """Flip the edges ``(u[i], vertex_neighbors[u[i], slot[i]])`` of ``state`` in place.

    The caller guarantees the flips touch disjoint cells and that ``C1``, ``C2`` keep >= 3 sides.
    Each edge is rotated by +90 degrees (``sense=1``, counter-clockwise seen from outside) or -90
    degrees about the surface normal at its midpoint: ``C1`` and ``C2`` (which shared it) lose a
    side, ``C3`` and ``C4`` (at its ends) gain one and now share it. The two vertices are placed
    symmetrically about the midpoint at geodesic separation ``new_length`` (``turn``: see
    :func:`t1_new_positions`). Flipping again with the
    opposite sense restores the original network. Tables stay on the host (NumPy) here; the
    State's arrays are updated in place, widening ``cell_vertices`` when a cell needs more room.
    Returns the array of vertices moved (``u`` and ``v`` of every flip).
    """
    dev = state.device
    u = np.asarray(u, dtype=np.int64)
    slot = np.asarray(slot, dtype=np.int64)
    vn = dev.to_numpy(state.vertex_neighbors).copy()
    vc = dev.to_numpy(state.vertex_cells).copy()
    table = dev.to_numpy(state.cell_vertices).copy()
    sides = dev.to_numpy(state.cell_sides).copy()
    pos = dev.to_numpy(state.positions).copy()
    v, a, b, c, d, C1, C2, C3, C4 = t1_cells(vn, vc, u, slot)
    X, Y = (v, u) if sense > 0 else (u, v)   # X ends up on the C1 side, Y on the C2 side
    # vertex tables (counter-clockwise): X = (Y, d, a) in cells (C4, C1, C3); Y = (X, b, c) in (C3, C2, C4)
    vn[X] = np.stack([Y, d, a], axis=1)
    vc[X] = np.stack([C4, C1, C3], axis=1)
    vn[Y] = np.stack([X, b, c], axis=1)
    vc[Y] = np.stack([C3, C2, C4], axis=1)
    for outer, old, new in ((a, u, X), (d, v, X), (b, u, Y), (c, v, Y)):
        hit = vn[outer] == old[:, None]
        rows = np.where(hit.any(axis=1))[0]
        vn[outer[rows], hit[rows].argmax(axis=1)] = new[rows]
    # cell table: C1 drops Y, C2 drops X, C3 turns u into (Y, X), C4 turns v into (X, Y)
    need = int(max(sides[C3].max(initial=0), sides[C4].max(initial=0))) + 1
    if need > table.shape[1]:
        table = np.concatenate([table, np.full((len(table), need - table.shape[1]), -1, np.int32)], axis=1)
    _remove_from_rows(table, sides, C1, Y)
    _remove_from_rows(table, sides, C2, X)
    _split_in_rows(table, sides, C3, u, Y, X)
    _split_in_rows(table, sides, C4, v, X, Y)
    pos[X], pos[Y] = t1_new_positions(state, pos, u, v, a, b, c, d, new_length, turn)
    xp = dev.xp
    state.vertex_neighbors = xp.asarray(vn)
    state.vertex_cells = xp.asarray(vc)
    state.cell_vertices = xp.asarray(table)
    state.cell_sides = xp.asarray(sides)
    state.positions = xp.asarray(pos)
    state.topology_version += 1
    return np.concatenate([u, v])


# ---------------------------------------------------------------------- spatial order
def _spread_bits(x):
    """Insert two zero bits between the low 21 bits of x (uint64), for 3-D Morton codes."""
    x = x & np.uint64(0x1FFFFF)
    for shift, mask in ((32, 0x1F00000000FFFF), (16, 0x1F0000FF0000FF), (8, 0x100F00F00F00F00F),
                        (4, 0x10C30C30C30C30C3), (2, 0x1249249249249249)):
        x = (x | (x << np.uint64(shift))) & np.uint64(mask)
    return x


def morton_codes_2d(points, box, bits: int = 16):
    """2-D Z-order codes of points in the box ``[0, Lx) x [0, Ly)`` (``box`` per point or one), uint64."""
    p = np.asarray(points, dtype=np.float64)[:, :2] / np.asarray(box, dtype=np.float64)
    q = np.clip(np.floor(p * 2 ** bits), 0, 2 ** bits - 1).astype(np.uint64)
    return _spread_bits(q[:, 0]) | (_spread_bits(q[:, 1]) << np.uint64(1))


def repeated_adjacency(vertex_neighbors, vertex_cells):
    """The first edge ``(u, v)`` whose two cells are one cell or already share another edge, or None.

    A simple network has neither (on a sphere it cannot happen above a few cells; on a small
    periodic box a cell can meet itself or a neighbour across two of its edges through the images).
    """
    vn, vc = np.asarray(vertex_neighbors), np.asarray(vertex_cells)
    u = np.repeat(np.arange(len(vn)), 3)
    keep = u < vn.reshape(-1)
    left, right = vc.reshape(-1)[keep], np.roll(vc, 1, axis=1).reshape(-1)[keep]
    key = np.minimum(left, right).astype(np.int64) * (int(vc.max(initial=0)) + 1) + np.maximum(left, right)
    unique, count = np.unique(key, return_counts=True)
    bad = (left == right) | (count[np.searchsorted(unique, key)] > 1)
    if not bad.any():
        return None
    i = int(np.flatnonzero(bad)[0])
    return int(u[keep][i]), int(vn.reshape(-1)[keep][i])


def morton_codes(points, bits: int = 16):
    """3-D Z-order (Morton) codes of the points' directions (any scale), uint64.

    Sorting cells and vertices by them puts neighbours close in memory, so the gathers of the force
    kernels hit cache lines that their neighbours also use.
    """
    p = np.asarray(points, dtype=np.float64)
    u = p / np.linalg.norm(p, axis=1)[:, None]
    q = np.clip(((u + 1.0) * 0.5 * (2 ** bits - 1)).round(), 0, 2 ** bits - 1).astype(np.uint64)
    return _spread_bits(q[:, 0]) | (_spread_bits(q[:, 1]) << np.uint64(1)) | (_spread_bits(q[:, 2]) << np.uint64(2))


def renumber(positions, cell_vertices, cell_sides, vertex_neighbors, vertex_cells, vertex_order, cell_order):
    """Relabel one replica's vertices and cells: new vertex i is old ``vertex_order[i]``, likewise cells."""
    inv_v = np.empty(len(vertex_order), dtype=np.int64)
    inv_v[vertex_order] = np.arange(len(vertex_order))
    inv_c = np.empty(len(cell_order), dtype=np.int64)
    inv_c[cell_order] = np.arange(len(cell_order))
    table = cell_vertices[cell_order]
    table = np.where(table >= 0, inv_v[np.maximum(table, 0)], -1).astype(np.int32)
    return (positions[vertex_order], table, cell_sides[cell_order],
            inv_v[vertex_neighbors[vertex_order]].astype(np.int32), inv_c[vertex_cells[vertex_order]].astype(np.int32))
