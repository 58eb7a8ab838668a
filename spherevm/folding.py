"""Whether a T1 flip would fold the network (the rule :class:`spherevm.plugins.updaters.T1` applies
before flipping; the CUDA twin is ``plugins/updaters/t1_fold.cuh``)."""
from __future__ import annotations

import numpy as np

from .topology import t1_cells, t1_new_positions


def t1_folds(state, u, slot, new_length):
    """Which of the flips of the edges ``(u, vertex_neighbors[u, slot])`` (to ``new_length``) would
    fold the network: leave one of the four cells with signed area <= 0, or invert a corner that
    was not inverted: turn the three edges at one of the six vertices whose edges change (the
    flipped pair and a, b, c, d) clockwise (two of the three turns between consecutive edges
    negative). An edge the dynamics pushed through zero length already has inverted corners at
    its ends; flipping it is the cure, not a fold, so only new inversions count.

    Areas: what the constraint will measure after the flip, the fan about each cell's first vertex
    after the flip (at its new place if it is u or v), over the cell's edges that do not touch u or
    v in table order, then its new edges (:func:`t1_flip`'s rows); so a fan that would wrap (a big
    cell, A - 4 pi R^2) is refused too. Exactly what ``t1_would_fold`` in
    plugins/updaters/t1_fold.cuh computes, in the same order."""
    dev = state.device
    vn, vc = dev.to_numpy(state.vertex_neighbors), dev.to_numpy(state.vertex_cells)
    table, sides = dev.to_numpy(state.cell_vertices), dev.to_numpy(state.cell_sides)
    pos = dev.to_numpy(state.positions)
    con = state.constraint
    size = con.size_np(state)[state.vertex_replica_np()[u]]
    v, a, b, c, d, C1, C2, C3, C4 = t1_cells(vn, vc, u, slot)
    px, py = t1_new_positions(state, pos, u, v, a, b, c, d, new_length)
    n, width = len(u), table.shape[1]
    # areas of C1..C4 (axis 1): old sides not touching u or v, then the new chains (a X d), (c Y b),
    # (b Y X a), (d X Y c), all as one array of fan triangles summed left to right (cumsum)
    rows = table[np.stack([C1, C2, C3, C4], axis=1)]                       # (n, 4, width)
    k = sides[np.stack([C1, C2, C3, C4], axis=1)][..., None]
    col = np.arange(width)
    nxt = np.take_along_axis(rows, np.broadcast_to((col + 1) % k, rows.shape), axis=2)
    hit = (rows == u[:, None, None]) | (rows == v[:, None, None])
    keep = (col < k) & ~hit & ~((nxt == u[:, None, None]) | (nxt == v[:, None, None]))
    p, q = pos[np.where(keep, rows, 0)], pos[np.where(keep, nxt, 0)]      # (n, 4, width, 3)
    pa, pb, pc, pd = pos[a], pos[b], pos[c], pos[d]
    chain = np.stack([np.stack(e, axis=1) for e in ((pa, px, pd, pd), (pc, py, pb, pb), (pb, py, px, pa),
                                                     (pd, px, py, pc))], axis=1)   # (n, 4, 4, 3); 3 edges each
    p = np.concatenate([p, chain[:, :, :3]], axis=2)
    q = np.concatenate([q, chain[:, :, 1:]], axis=2)
    keep = np.concatenate([keep, np.broadcast_to([True, True, False], (n, 4, 3)),], axis=2)
    keep[:, 2:, width + 2] = True                                          # C3 and C4 have three new edges
    moved = np.stack([px, py, py, px], axis=1)                             # each row's first vertex after
    apex = np.where(hit[:, :, :1], moved, pos[rows[:, :, 0]])
    tri = con.triangle_area(np.broadcast_to(apex[:, :, None], p.shape), p, q, _per_row(size, 2))
    area = np.cumsum(np.where(keep, tri, 0.0), axis=2)[:, :, -1]
    bad = ~(area > 0).all(axis=1)
    # corners: X = v's new row (Y, d, a), Y = u's (X, b, c); a, d, b, c with u or v at its new place
    ring_now = pos[vn[np.stack([v, u, a, d, b, c], axis=1)]]                # (n, 6, 3 neighbours, 3)
    ring_new = ring_now.copy()
    ring_new[:, 0], ring_new[:, 1] = np.stack([py, pd, pa], axis=1), np.stack([px, pb, pc], axis=1)
    for i, (w, old, new) in enumerate(((a, u, px), (d, v, px), (b, u, py), (c, v, py)), start=2):
        ring_new[:, i] = np.where((vn[w] == old[:, None])[..., None], new[:, None], ring_now[:, i])
    centre_now = pos[np.stack([v, u, a, d, b, c], axis=1)]
    centre_new = np.concatenate([np.stack([px, py], axis=1), centre_now[:, 2:]], axis=1)
    bad |= (_inverted(con, centre_new, ring_new, size) & ~_inverted(con, centre_now, ring_now, size)).any(axis=1)
    return bad


def _per_row(size, axes):
    """Per-candidate surface sizes (a radius, or a box (Lx, Ly)) broadcast over ``axes`` more axes."""
    return size.reshape(size.shape[:1] + (1,) * axes + size.shape[1:])


def _inverted(con, w, ring, size):
    """Corners ``w`` (..., 3) whose edges to ``ring`` (..., 3, 3) turn clockwise: two of the three
    turns between consecutive edges negative about the outward normal."""
    normal = con.normal(w)
    e = con.unwrap(ring, w[..., None, :], _per_row(size, 2)) - w[..., None, :]
    cross = np.cross(e, np.roll(e, -1, axis=-2))
    turns = (np.einsum("...j,...kj->...k", normal, cross) < 0).sum(axis=-1)
    return turns >= 2
