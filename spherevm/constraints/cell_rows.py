"""The NumPy path's passes over cells: each cell's entries (its vertices, its neighbour cells) as
columns of a dense table, so that per-cell sums are sums along the table's slot axis, not
``np.bincount`` over scattered entries (measured on the 2-core VM: a bincount costs about 1.5 ns
an entry, a take about 1, a sum along a slot axis about 0.4).

A table is ``(1 + width, rows)``: slot 0 holds the row's head (the cell itself, or its first
vertex), slots 1.. its entries in order, padded with the head. A cell whose entries do not fit
goes on in continuation rows after the block's cells (each starting ``overlap`` entries back, so a
pass over consecutive entries misses no pair), whose results :func:`fold` adds to their cell's.
The width is the one that makes the table smallest. Built per block of cells (cache-sized, one per
core at least: :func:`spherevm.constraints.corners.blocks`) and cached per topology by the caller.
"""
from __future__ import annotations

import numpy as np

from .corners import BLOCK_VERTICES, blocks

BLOCK_CELLS = BLOCK_VERTICES // 2   # a trivalent network has twice as many vertices as cells


def cell_blocks(state):
    """Contiguous ranges of cells for the cell passes (one range for small states)."""
    return blocks(state, state.n_cells, size=BLOCK_CELLS)


def _continuations(counts, width, overlap):
    """Per cell, how many rows beyond its first its ``counts`` entries need."""
    return -(-np.maximum(counts - width, 0) // (width - overlap))


def row_table(counts, entries, heads, overlap=0, odd=False):
    """The table of a block of cells: ``counts`` (nb,) entries per cell, ``entries`` all of them
    cell after cell, ``heads`` (nb,) each cell's head; ``odd``: an odd width. Returns a dict:
    ``table`` (1 + width, rows) int64, ``owner`` the cell (0..nb-1) of each continuation row (rows
    nb..), and ``fold_levels`` for :func:`fold`."""
    counts = np.asarray(counts, dtype=np.int64)
    nb = len(counts)
    widths = np.arange(overlap + 1, max(int(counts.max()), overlap + 1) + 2)
    widths = widths[widths % 2 == 1] if odd else widths[:-1]
    size = [(1 + w) * (nb + _continuations(counts, w, overlap).sum()) for w in widths]
    width = int(widths[int(np.argmin(size))])
    more = _continuations(counts, width, overlap)
    owner = np.repeat(np.arange(nb), more)
    row_cell = np.concatenate((np.arange(nb), owner))
    nth = np.arange(len(owner)) - np.repeat(np.cumsum(more) - more, more)    # 0 for a cell's first continuation
    first = np.concatenate((np.zeros(nb, np.int64), (width - overlap) * (1 + nth)))
    slot = first + np.arange(width)[:, None]                                # (width, rows): entry within its cell
    start = np.cumsum(counts) - counts
    inside = slot < counts[row_cell]
    body = np.where(inside, entries[np.where(inside, start[row_cell] + slot, 0)], heads[row_cell])
    table = np.concatenate((heads[row_cell][None], body)).astype(np.int64)
    # fold: each cell's k-th continuation rows form level k (at most one row per cell, so a
    # fancy-index add is safe); flat indices into a C-contiguous (c, rows) array, c = 4, 3, .. rows
    # first, so that the first c * m of them serve c rows
    levels = []
    for k in range(int(more.max(initial=0))):
        mine = np.flatnonzero(nth == k)
        src = (nb + mine + len(row_cell) * np.arange(4)[:, None]).reshape(-1)
        dst = (owner[mine] + len(row_cell) * np.arange(4)[:, None]).reshape(-1)
        levels.append((src, dst))
    return dict(table=np.ascontiguousarray(table), owner=owner, fold_levels=levels)


def fold(values, rows):
    """``values`` (c, rows) per row (c <= 4, C-contiguous; changed in place) -> (c, nb) per cell:
    each continuation row's values added to its cell's, level by level (three small NumPy calls a
    level, where a bincount into (c, nb) cost twice as much at 1,000 cells)."""
    c, flat = values.shape[0], values.reshape(-1)
    assert values.flags.c_contiguous
    for src, dst in rows["fold_levels"]:
        m = c * (len(src) // 4)
        flat[dst[:m]] += flat.take(src[:m])
    return values[:, :values.shape[1] - len(rows["owner"])]


def fan_rows(state):
    """Per block of cells (:func:`cell_blocks`), the table of its cells' vertices for the fans: rows
    of :func:`row_table` with head the first vertex ``x_0`` (the fan's apex), entries ``e_0 = x_1,
    e_1 = x_2, ...``, ``overlap=1`` (a fan's triangles are consecutive pairs of entries) and an odd
    width ``2h + 1``, so ``h`` quadrilaterals ``(x_0, e_2j, e_2j+1, e_2j+2)`` a row. Its slots are
    the ends of the quads' diagonals, ``e_1, e_3, .., e_2h-1, e_2, e_4, .., e_2h`` then ``x_0`` (h
    times), ``e_0, e_2, .., e_2h-2``: the two halves' difference is both diagonals in one NumPy call
    on slices (a broadcast ``x_0`` and strided operands took twice as long); ``c0``, ``c1`` the
    block's cells. Cached per topology."""
    def build():
        sides, cv = state.cell_sides.astype(np.int64), state.cell_vertices
        out = []
        for c0, c1 in cell_blocks(state):
            body = cv[c0:c1, 1:]
            entries = body[np.arange(body.shape[1]) < sides[c0:c1, None] - 1]   # cell after cell
            rows = row_table(sides[c0:c1] - 1, entries, cv[c0:c1, 0], overlap=1, odd=True)
            table = rows["table"]
            h = len(table) // 2 - 1
            ends, middles = table[1::2], table[2::2]
            order = (middles, ends[1:], np.repeat(table[:1], h, axis=0), ends[:-1])
            out.append(dict(rows, table=np.ascontiguousarray(np.concatenate(order)), c0=c0, c1=c1))
        return out
    return state.cached((fan_rows,), build, topology=True)
