"""Whether a T1 flip would fold the network, and which way round to place it (the rule
:class:`spherevm.plugins.updaters.T1` applies before flipping; the CUDA twin is
``plugins/updaters/t1_fold.cuh``)."""
from __future__ import annotations

import numpy as np

from . import simplicity
from .topology import t1_cells, t1_new_positions

CLEAN, INVERTED, FOLDS = 0, 1, 2    # fold levels of a placement, see t1_fold_level


def t1_placement(state, u, slot, new_length, untangle=False):
    """``(refused, turn)`` masks over the candidate flips. The usual placement
    (:func:`spherevm.topology.t1_new_positions`) if it is clean (:func:`t1_fold_level`), else the
    edge rotated the other way round (``turn``) if that is clean, else the usual one if it only
    keeps corners that were inverted already (an edge the dynamics pushed through zero length,
    which no placement cures), else (with ``untangle``, as ``T1(untangle=True)`` places its flips)
    the turned one if that only keeps such corners, else refused: a flip never folds the network.
    Where no corner is inverted the last two never arise."""
    new_length = np.broadcast_to(np.asarray(new_length, dtype=np.float64), np.shape(u))
    usual = t1_fold_level(state, u, slot, new_length)
    turned = np.full(len(u), CLEAN)
    again = np.flatnonzero(usual != CLEAN)
    if len(again):
        turned[again] = t1_fold_level(state, u[again], slot[again], new_length[again],
                                      turn=np.ones(len(again), dtype=bool))
    turn = (usual != CLEAN) & ((turned == CLEAN) | (untangle & (usual == FOLDS) & (turned == INVERTED)))
    return (usual == FOLDS) & ~turn, turn


def t1_fold_level(state, u, slot, new_length, turn=None):
    """Per candidate flip of the edges ``(u, vertex_neighbors[u, slot])`` to ``new_length``
    (``turn``: rotated the other way round), with its two vertices at their new places:

    * ``FOLDS`` (2): one of its four cells would have signed area <= 0, or their areas would not
      add up to what they did (a cell wrapping or overlapping another: the sum moves by a whole
      sphere or box), or a corner that was not inverted would be: the three edges at one of the
      six vertices whose edges change (the flipped pair and a, b, c, d) turning clockwise (two of
      the three turns between consecutive edges negative);
    * ``INVERTED`` (1): not that, but one of those corners stays inverted (it was before);
    * ``CLEAN`` (0): neither.

    Areas are what the constraint will measure: the fan about each cell's first vertex (after
    the flip: at its new place if it is u or v) over its edges that do not touch u or v in table
    order, then its new edges (:func:`spherevm.topology.t1_flip`'s rows), summed left to right.
    Exactly what ``t1_fold_level`` in plugins/updaters/t1_fold.cuh computes, in the same order."""
    dev = state.device
    vn, vc = dev.to_numpy(state.vertex_neighbors), dev.to_numpy(state.vertex_cells)
    table, sides = dev.to_numpy(state.cell_vertices), dev.to_numpy(state.cell_sides)
    pos = dev.to_numpy(state.positions)
    con = state.constraint
    size = con.size_np(state)[state.vertex_replica_np()[u]]
    v, a, b, c, d, C1, C2, C3, C4 = t1_cells(vn, vc, u, slot)
    px, py = t1_new_positions(state, pos, u, v, a, b, c, d, new_length, turn)
    n, width = len(u), table.shape[1]
    rows = table[np.stack([C1, C2, C3, C4], axis=1)]                       # (n, 4, width)
    k = sides[np.stack([C1, C2, C3, C4], axis=1)][..., None]
    col = np.arange(width)
    nxt = np.take_along_axis(rows, np.broadcast_to((col + 1) % k, rows.shape), axis=2)
    real = col < k
    p, q = pos[np.where(real, rows, 0)], pos[np.where(real, nxt, 0)]     # (n, 4, width, 3)
    tri = con.triangle_area(np.broadcast_to(pos[rows[:, :, :1]], p.shape), p, q, _per_row(size, 2))
    before = np.cumsum(np.where(real, tri, 0.0), axis=2)[:, :, -1]
    # after: old sides not touching u or v, then the chains (a X d), (c Y b), (b Y X a), (d X Y c)
    hit = (rows == u[:, None, None]) | (rows == v[:, None, None])
    keep = real & ~hit & ~((nxt == u[:, None, None]) | (nxt == v[:, None, None]))
    pa, pb, pc, pd = pos[a], pos[b], pos[c], pos[d]
    chain = np.stack([np.stack(e, axis=1) for e in ((pa, px, pd, pd), (pc, py, pb, pb), (pb, py, px, pa),
                                                     (pd, px, py, pc))], axis=1)   # (n, 4, 4, 3); 3 edges each
    p = np.concatenate([pos[np.where(keep, rows, 0)], chain[:, :, :3]], axis=2)
    q = np.concatenate([pos[np.where(keep, nxt, 0)], chain[:, :, 1:]], axis=2)
    keep = np.concatenate([keep, np.broadcast_to([True, True, False], (n, 4, 3))], axis=2)
    keep[:, 2:, width + 2] = True                                          # C3 and C4 have three new edges
    moved = np.stack([px, py, py, px], axis=1)                             # each row's first vertex after
    apex = np.where(hit[:, :, :1], moved, pos[rows[:, :, 0]])
    tri = con.triangle_area(np.broadcast_to(apex[:, :, None], p.shape), p, q, _per_row(size, 2))
    after = np.cumsum(np.where(keep, tri, 0.0), axis=2)[:, :, -1]
    half = 0.5 * con.total_area_np(size)
    folds = ~(after > 0).all(axis=1) | ~(np.abs(after.sum(axis=1) - before.sum(axis=1)) < half)
    # corners: X = v's new row (Y, d, a), Y = u's (X, b, c); a, d, b, c with u or v at its new place
    ring_now = pos[vn[np.stack([v, u, a, d, b, c], axis=1)]]                # (n, 6, 3 neighbours, 3)
    ring_new = ring_now.copy()
    ring_new[:, 0], ring_new[:, 1] = np.stack([py, pd, pa], axis=1), np.stack([px, pb, pc], axis=1)
    for i, (w, old, new) in enumerate(((a, u, px), (d, v, px), (b, u, py), (c, v, py)), start=2):
        ring_new[:, i] = np.where((vn[w] == old[:, None])[..., None], new[:, None], ring_now[:, i])
    centre_now = pos[np.stack([v, u, a, d, b, c], axis=1)]
    centre_new = np.concatenate([np.stack([px, py], axis=1), centre_now[:, 2:]], axis=1)
    inverted = _inverted(con, centre_new, ring_new, size)
    folds |= (inverted & ~_inverted(con, centre_now, ring_now, size)).any(axis=1)
    return np.where(folds, FOLDS, np.where(inverted.any(axis=1), INVERTED, CLEAN))


def _per_row(size, axes):
    """Per-candidate surface sizes (a radius, or a box (Lx, Ly)) broadcast over ``axes`` more axes."""
    return size.reshape(size.shape[:1] + (1,) * axes + size.shape[1:])


def _inverted(con, w, ring, size):
    """Corners ``w`` (..., 3) whose edges to ``ring`` (..., 3, 3) turn clockwise: two of the three
    turns between consecutive edges negative about the outward normal."""
    normal = con.normal(w, _per_row(size, 1))
    e = con.unwrap(ring, w[..., None, :], _per_row(size, 2)) - w[..., None, :]
    cross = np.cross(e, np.roll(e, -1, axis=-2))
    turns = (np.einsum("...j,...kj->...k", normal, cross) < 0).sum(axis=-1)
    return turns >= 2


def inverted_edges(state):
    """Edges ``(u, slot)`` (``u < vertex_neighbors[u, slot]``) turned past zero length: with
    ``C1 = (.., a, u, v, d, ..)`` and ``C2 = (.., c, v, u, b, ..)`` the cells on its sides
    (:func:`spherevm.topology.t1_cells`), the edges ``a u`` and ``v d`` cross, or ``c v`` and ``u b``:
    the bow tie such an edge makes of its cells (the crossings hot dynamics make; a T1 flip of
    the edge undoes them). Vectorised over the edges, on the host."""
    con = state.constraint
    if not simplicity.measurable(con):
        return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64)
    to_np = state.device.to_numpy
    vn, vc, pos = to_np(state.vertex_neighbors), to_np(state.vertex_cells), to_np(state.positions)
    corner = np.flatnonzero((np.arange(len(vn))[:, None] < vn).reshape(-1))
    u, slot = corner // 3, corner % 3
    v, a, b, c, d = t1_cells(vn, vc, u, slot)[:5]
    size = con.size_np(state)[state.vertex_replica_np()[u]]      # each end's image nearest u
    pu = simplicity.points(state, pos[u])
    pa, pb, pc, pd, pv = (simplicity.points(state, pos[w], pos[u], size) for w in (a, b, c, d, v))
    # in a triangle the two edges share a vertex (a = d, or b = c) and never cross
    bow = ((a != d) & simplicity.arcs_cross(pa, pu, pv, pd)) | ((b != c) & simplicity.arcs_cross(pc, pv, pu, pb))
    return u[bow], slot[bow]
