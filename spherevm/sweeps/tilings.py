"""A sweep's tilings on the host: the seeds of a chunk's tilings, building them, and building the
next chunks' tilings in a process pool while the GPU minimises (:class:`TilingPrefetch`)."""
from __future__ import annotations

import os

import numpy as np

from .pools import ignore_interrupts, process_pool
from .spec import Chunk, RigiditySweep, tiling_seed


def chunk_seeds(sweep: RigiditySweep, chunk: Chunk):
    """The chunk's units ``(p0 index, replica)`` and their tiling seeds."""
    units = [sweep.unit(u) for u in range(chunk.start, chunk.stop)]
    return units, [tiling_seed(sweep.seed, chunk.n_cells, sweep.p0[k], r, sweep.shared_tilings) for k, r in units]


def build_tilings(surface: str, n_cells: int, seeds):
    """The random tilings of ``seeds`` on ``surface`` as one State."""
    from ..init import tilings_on
    return tilings_on(surface, n_cells, [(int(s), 0) for s in seeds])


def _tiling_arrays(surface: str, n_cells: int, seeds):
    """:func:`build_tilings` as plain arrays and the constraint (what a process pool can send back)."""
    state = build_tilings(surface, n_cells, seeds)
    return state.arrays_np(), state.constraint


#: a tiling worker's priority below the sweep's (``os.nice``): the processes driving the GPUs need
#: their host cores for every launch (docs/performance.md, "Several GPUs"); read at each sweep's start
TILING_NICENESS = 10


def _tiling_worker(niceness: int):
    """A tiling worker: one thread (the pool has a process per core already), ``niceness`` below the
    processes driving the GPUs, and Ctrl-C is the main process's business."""
    from ..constraints.corners import single_threaded
    single_threaded()
    if hasattr(os, "nice") and niceness:
        os.nice(niceness)
    ignore_interrupts()


#: cells of tilings a sweep may hold ahead of its GPUs, beyond its ``ahead`` chunks (about 150 bytes
#: a cell: 300 MB): chunks are submitted while those built or being built and not yet taken hold at
#: most this many, so the slack the pool gains on chunks that tile fast carries over to chunks whose
#: tilings cost more than their minimisation. A pool busy throughout gains no slack: on a paper-size
#: sweep of a 3:1 torus a limit of the whole sweep waited as long (docs/rigidity.md, Executors)
PREFETCH_CELLS = 2_000_000


class TilingPrefetch:
    """Builds the tilings of the next chunks in a process pool while the GPU minimises the current
    one: at least ``ahead`` chunks after the one asked for, and more while the tilings held stay
    within ``cells`` cells (:data:`PREFETCH_CELLS`). Each chunk's seeds are cut into one part per
    worker and the parts concatenated in order, which is the State that
    :func:`~spherevm.sweeps.execution.build_chunk_state` builds alone (tested); its workers run
    ``niceness`` (default :data:`TILING_NICENESS`) below this process."""

    def __init__(self, sweep: RigiditySweep, chunks, workers: int, ahead: int = 2, niceness: int | None = None,
                 cells: int = PREFETCH_CELLS):
        self.sweep, self.chunks, self.workers, self.ahead, self.cells = sweep, list(chunks), workers, ahead, cells
        nice = TILING_NICENESS if niceness is None else int(niceness)
        self.pool = process_pool(workers, initializer=_tiling_worker, initargs=(nice,))
        self.futures, self.seeds = {}, {}
        self._submit_from(0)

    @property
    def pending(self) -> list:
        """The ids of the chunks whose tilings are built or being built and not yet taken, in order."""
        return list(self.futures)

    def _submit_from(self, index):
        held = 0
        for k, c in enumerate(self.chunks[index:]):
            held += c.n_cells * c.size
            if k > self.ahead and held > self.cells:
                break
            if c.id not in self.futures:
                seeds = self.seeds[c.id] = chunk_seeds(self.sweep, c)[1]
                parts = np.array_split(np.array(seeds, dtype=np.int64), min(self.workers, len(seeds)))
                self.futures[c.id] = [self.pool.submit(_tiling_arrays, self.sweep.surface, c.n_cells, part.tolist())
                                      for part in parts if len(part)]

    def get(self, chunk) -> dict:
        """The chunk's ``state`` (waits for its parts) and tiling ``seeds``, keyword arguments of
        :func:`~spherevm.sweeps.execution.run_chunk`; the next chunks submitted."""
        from ..state import State
        self._submit_from(self.chunks.index(chunk))
        parts = [State(**arrays, constraint=constraint, validate=False)       # validated by the worker
                 for arrays, constraint in (f.result() for f in self.futures.pop(chunk.id))]
        return {"state": parts[0] if len(parts) == 1 else State.concatenate(parts), "seeds": self.seeds.pop(chunk.id)}

    def close(self):
        self.pool.shutdown(wait=False, cancel_futures=True)
