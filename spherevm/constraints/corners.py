"""The NumPy path's corner passes: slot-major corner tables, cut into blocks that run on all cores.

Corner (v, k) lies in cell ``vertex_cells[v, k]``, where the boundary runs counter-clockwise from
v to ``n_k = vertex_neighbors[v, k]``; the edge (v, n_k) borders cells k and k-1. Corner arrays
are slot-major, shape (3 components, 3 slots, vertices of the block): a vertex quantity
broadcasts over the slot axis and the sum over a vertex's corners adds three contiguous rows.
The sphere's metric (:mod:`spherevm.constraints.sphere`) and the bending force share the tables
and the blocks.
"""
from __future__ import annotations

import os

import numpy as np

_POOL = None
#: threads for large NumPy states (None: one per CPU core); a process pool's workers set 1, so that
#: its processes do not each start a thread per core (:func:`single_threaded`)
THREADS = None
PARALLEL_MIN_VERTICES = 16384   # below this, one thread; blocks hold at least half as many items
BLOCK_VERTICES = 16384          # per block: its per-corner vectors (3 x 3 x 16384 doubles, 1.2 MB) stay in cache


def blocks(state, n, size=BLOCK_VERTICES):
    """Contiguous ranges over ``n`` items (vertices, cells, pairs) for large NumPy states: at least
    one per CPU core (NumPy releases the GIL inside its loops, so blocks run on all cores at once)
    and at most ``size`` items, so that a block's temporaries stay in cache (measured, 65,536 cells
    on 2 cores: 28-30 ms in blocks of 16,384 vertices, 32-35 ms in blocks of 32,768 or 65,536; a
    pass whose blocks each add into whole-length sums takes ``size=n``: one block per core). One
    range on the GPU and for small states."""
    workers = THREADS or os.cpu_count() or 1
    if state.device.is_gpu or n < PARALLEL_MIN_VERTICES:
        return [(0, n)]
    count = max(min(workers, n // (PARALLEL_MIN_VERTICES // 2)), -(-n // size))
    edges = np.linspace(0, n, count + 1).astype(int)
    return [(int(a), int(b)) for a, b in zip(edges[:-1], edges[1:])]


def in_parallel(fn, items, threads=True):
    """``[fn(item) for item in items]``, on a thread pool when there are several items (and
    ``threads``: a small state's passes run in turn, a pool's hand-over costing tens of us)."""
    global _POOL
    if len(items) == 1 or not threads or THREADS == 1:
        return [fn(item) for item in items]
    if _POOL is None:
        from concurrent.futures import ThreadPoolExecutor
        _POOL = ThreadPoolExecutor(max_workers=THREADS or os.cpu_count(), thread_name_prefix="spherevm")
    return [f.result() for f in [_POOL.submit(fn, item) for item in items]]


def single_threaded():
    """From now on this process computes large NumPy states in one thread (for a pool's workers:
    one process per core, each with a thread per core, would starve the process driving the GPU)."""
    global THREADS
    THREADS = 1


def corner_index(state):
    """Per vertex block (:func:`blocks`), the slot-major corner tables: ``lo``, ``hi``; ``next``,
    the next vertex; ``cells``, the corner's cell; ``both``, the corner's cell then the cell before
    it (slot k - 1); ``apex``, the cell's first vertex (its fan apex); ``components``, the corner's
    cell plus ``n_cells`` times each Cartesian component (one ``bincount`` sums (3, corners)
    vectors per cell). Cached per State and topology version (T1 flips bump it)."""
    return state.cached((corner_index,), lambda: _build(state), topology=True)


def _build(state):
    xp = state.device.xp
    vn, vc = state.vertex_neighbors.astype(np.intp), state.vertex_cells.astype(np.intp)
    first = state.cell_vertices[:, 0].astype(np.intp)
    offsets = state.n_cells * xp.arange(3)[:, None]
    result = []
    for lo, hi in blocks(state, state.n_vertices):
        cells = xp.ascontiguousarray(vc[lo:hi].T).reshape(-1)
        before = xp.ascontiguousarray(xp.roll(vc[lo:hi], 1, axis=1).T).reshape(-1)
        result.append(dict(lo=lo, hi=hi, next=xp.ascontiguousarray(vn[lo:hi].T).reshape(-1),
                           cells=cells, apex=first[cells], both=xp.concatenate((cells, before)),
                           components=(cells[None] + offsets).reshape(-1)))
    return result
