"""Simple tilings: every cell a simple polygon (no edge crossing another edge of the same cell), each
closed under the minimum image on a periodic plane, with positive area, and the cells covering the
surface exactly once (docs/validation.md).

Why these checks are enough to rule out overlapping cells without comparing cells pairwise: the
cells, glued along their shared edges, map a closed surface onto the sphere (or the periodic box).
Where every cell is simple and counter-clockwise (signed area > 0), a point inside no edge is
covered once, with the sign +1, by every cell that covers it, so the number of cells covering it
is the map's degree: the cells' areas summed over the surface's area. A sum equal to the surface's
area (degree 1) means every point is covered exactly once. So crossings between cells need no
search: a vertex pushed into a neighbour leaves some cell crossed, inverted or the sum wrong.

All tests here are vectorised NumPy over the corners and the pairs of edges of every cell (no
loop over cells); the tables live on the host. The closed-cell test also runs on the device
(:func:`flag_open_cells`), where the run's checks look at it every check.
"""
from __future__ import annotations

import numpy as np

def _pairs(width: int):
    """Every pair ``(i, j)`` of edges of a ``width``-gon that share no vertex, ordered by ``j`` and
    then by decreasing ``i``: those of an ``s``-gon are the first ``s (s - 3) / 2`` rows."""
    return np.array([(i, j) for j in range(2, width) for i in range(j - 2, -1, -1)], dtype=np.int64).reshape(-1, 2)


def measurable(constraint) -> bool:
    """Whether the crossing tests know this surface: it gives
    :meth:`~spherevm.constraints.Constraint.orientation_points` (the sphere's arcs, the plane's
    minimum images)."""
    return not constraint.missing(["orientation_points"])


def points(state, positions, reference=None, size=None):
    """Points as 3-vectors whose triple products give orientations
    (:meth:`~spherevm.constraints.Constraint.orientation_points`: unit vectors on the sphere,
    ``(x, y, 1)`` on the plane, unwrapped to the images nearest ``reference`` where given)."""
    return state.constraint.orientation_points(positions, reference, size)


def arcs_cross(a, b, c, d):
    """Mask: the arc (great-circle arc or segment, in :func:`_points` coordinates) ``a b`` crosses
    ``c d`` properly, the ends of each strictly on both sides of the other's great circle or line;
    on the sphere also the crossing point of the arcs, not of their antipodes (``(a x b) . d`` and
    ``(c x d) . a`` of one sign). Arrays ``(n, 3)``."""
    def triple(x, y, z):            # (x cross y) . z, column by column
        return ((x[:, 1] * y[:, 2] - x[:, 2] * y[:, 1]) * z[:, 0] + (x[:, 2] * y[:, 0] - x[:, 0] * y[:, 2]) * z[:, 1]
                + (x[:, 0] * y[:, 1] - x[:, 1] * y[:, 0]) * z[:, 2])
    s1, s2, s3, s4 = triple(a, b, c), triple(a, b, d), triple(c, d, a), triple(c, d, b)
    return (s1 * s2 < 0) & (s3 * s4 < 0) & (s2 * s3 > 0)


def self_crossings(state):
    """The crossing edge pairs inside cells: ``(cell, i, j)`` arrays, edge ``i`` (from slot i to slot
    i + 1 of ``cell_vertices[cell]``) crossing edge ``j > i`` of the same cell (:func:`arcs_cross`).
    Edges that share a vertex are not compared. ``None`` on a surface this cannot measure (one
    without a sphere's arcs or the plane's minimum images)."""
    if not measurable(state.constraint):
        return None

    def build():
        sides = state.device.to_numpy(state.cell_sides).astype(np.int64)
        count = sides * (sides - 3) // 2
        cell = np.repeat(np.arange(len(sides)), count)
        k = np.arange(len(cell)) - np.repeat(np.cumsum(count) - count, count)
        pair = _pairs(int(sides.max(initial=3)))[k]
        first = (np.cumsum(sides) - sides)[cell]
        return sides, cell, pair[:, 0], pair[:, 1], first + pair[:, 0], first + pair[:, 1]

    sides, cell, i, j, ci, cj = state.cached(("simplicity", "pairs"), build, topology=True)
    start, stop = state.constraint.edge_points(state, sides)
    cross = arcs_cross(start[ci], stop[ci], start[cj], stop[cj])
    return cell[cross], i[cross], j[cross]


def open_cells(state):
    """Cells whose edges do not add up to zero, with the slot of the edge that jumped
    (:meth:`~spherevm.constraints.Constraint.open_cells`: a periodic surface's; else none)."""
    return state.constraint.open_cells(state)


def faults(state, areas=None):
    """The cells that are not simple: those that cross themselves, open cells (periodic surfaces)
    and cells of signed area <= 0 (cell index arrays, sorted), and per replica whether the areas
    fail to add up to the surface's (bool); a dict. ``areas``: the cells' signed areas if already
    measured."""
    found = self_crossings(state)
    con = state.constraint
    areas = con.tiling_areas_np(state) if areas is None else areas
    total = np.bincount(state.cell_replica_np(), weights=areas, minlength=state.n_replicas)
    surface = con.total_area_np(con.size_np(state))
    return dict(crossed=np.zeros(0, dtype=np.int64) if found is None else np.unique(found[0]),
                open=np.unique(open_cells(state)[0]), inverted=np.flatnonzero(areas <= 0),
                uncovered=np.abs(total - surface) > con.cover_tolerance * surface)


def inverted_counts(state, areas=None):
    """Per replica: the cells of signed area <= 0 (the surface's tiling areas, as :func:`faults`
    judges them; ``areas`` if already measured), an int array."""
    areas = state.constraint.tiling_areas_np(state) if areas is None else areas
    return np.bincount(state.cell_replica_np()[areas <= 0], minlength=state.n_replicas)


def counts(state, areas=None):
    """Per replica: cells that cross themselves, open cells (periodic plane), cells of signed area
    <= 0, and whether the areas fail to add up to the surface's (1 or 0); a dict of int arrays
    (:func:`faults` counted). ``areas``: the cells' signed areas if already measured."""
    crep, n = state.cell_replica_np(), state.n_replicas
    found = faults(state, areas)
    out = {k: np.bincount(crep[found[k]], minlength=n) for k in ("crossed", "open", "inverted")}
    return dict(out, uncovered=found["uncovered"].astype(np.int64))


def closed_on_device(state) -> bool:
    """Whether :func:`flag_open_cells` tests the cells on the device (a GPU State on a surface whose
    kernels flag open cells: :func:`spherevm.constraints.kernels.flags_open_cells`); elsewhere the
    caller runs :func:`check_closed`, which costs nothing on a surface without images."""
    from .constraints.kernels import flags_open_cells
    return flags_open_cells(state)


def flag_open_cells(state, word):
    """Where :func:`closed_on_device`, set ``word`` (a one-element uint64 device array, such as the
    replica summary's last) to 1 if a cell is open (:func:`open_cells`), on the device: the run's
    checks read it with the rest of the summary and call :func:`check_closed` only then."""
    if closed_on_device(state) and state.n_cells:
        from .constraints.kernels import flag_open_cells as launch_flag
        launch_flag(state, word)


def check_closed(state):
    """Raise ValueError naming the replica, the cell and the edge if a cell does not close under the
    minimum image (a periodic plane): that edge reached half the box at this step."""
    cells, slot = open_cells(state)
    if len(cells):
        cv, sides = state.device.to_numpy(state.cell_vertices), state.device.to_numpy(state.cell_sides)
        c, k = int(cells[0]), int(slot[0])
        r = int(state.cell_replica_np()[c])
        raise ValueError(f"replica {r}: edge {int(cv[c, k])} -> {int(cv[c, (k + 1) % sides[c]])} of cell {c} reached "
                         f"half the box {state.constraint.size_np(state)[r].tolist()}: its minimum image jumped and "
                         f"the cell no longer closes ({len(cells)} open cell(s)); the box is too small for its "
                         "cells, or the step too large")


def check_cover(state, areas):
    """The cells cover the surface exactly once: their areas add up to its area (the constraint
    explains a mismatch, :meth:`~spherevm.constraints.Constraint.cover_error`), and each is one the
    surface measures (:meth:`~spherevm.constraints.Constraint.check_cell_areas`: on a sphere none
    covers more than a hemisphere)."""
    con = state.constraint
    try:
        surface = con.total_area_np(con.size_np(state))
    except NotImplementedError:       # a surface that does not know its area: nothing to compare
        return
    crep = state.cell_replica_np()
    total = np.bincount(crep, weights=areas, minlength=state.n_replicas)
    wrong = np.flatnonzero(np.abs(total - surface) > con.cover_tolerance * surface)
    if len(wrong):
        r = int(wrong[0])
        raise ValueError(f"replica {r}: {con.cover_error(state, areas, r, total[r], surface[r])}")
    con.check_cell_areas(state, areas, surface)


def check_simple(state):
    """Raise ValueError naming the replica, the cell and its two crossing edges if a cell crosses itself."""
    found = self_crossings(state)
    if found is not None and len(found[0]):
        cv, sides = state.device.to_numpy(state.cell_vertices), state.device.to_numpy(state.cell_sides)
        c, i, j = (int(x[0]) for x in found)
        edge = lambda k: f"{int(cv[c, k])} -> {int(cv[c, (k + 1) % sides[c]])}"   # noqa: E731
        raise ValueError(f"replica {int(state.cell_replica_np()[c])}: cell {c} is not a simple polygon: its edges "
                         f"{edge(i)} and {edge(j)} cross ({len(np.unique(found[0]))} such cell(s) in all)")


def check_orientation(state, areas):
    """Raise ValueError naming the replica and the cell if a cell's signed area is <= 0."""
    neg = areas <= 0
    if neg.any():
        c = int(np.flatnonzero(neg)[0])
        raise ValueError(f"replica {int(state.cell_replica_np()[c])}: cell {c} has area {areas[c]:.3g} <= 0: it is "
                         "listed clockwise seen from outside (list cell vertices counter-clockwise) or it is "
                         f"folded ({int(neg.sum())} such cell(s) in all)")


def check(state, orientation: bool = True, simple: bool = True):
    """The tiling is simple, or ValueError naming the replica and the cells: every cell closed under
    the minimum image (:func:`check_closed`), the areas adding up to the surface's
    (:func:`check_cover`), and with ``orientation`` every cell simple (:func:`check_simple`; not
    with ``simple=False``) with signed area > 0 (:func:`check_orientation`); by the degree argument
    of this module's docstring, no two cells then overlap. Called by :func:`spherevm.topology.check` (``State.validate``)."""
    check_closed(state)
    areas = state.constraint.tiling_areas_np(state)
    check_cover(state, areas)
    if orientation:
        if simple:
            check_simple(state)
        check_orientation(state, areas)
