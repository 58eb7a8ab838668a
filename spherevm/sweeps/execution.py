"""Running a sweep: one chunk as a batched minimisation (:func:`run_chunk`), the executors, and
:func:`run_sweep`, which runs the missing chunks, saves each as it finishes and reports progress."""
from __future__ import annotations

import concurrent.futures as cf
import math
import os
import time
from dataclasses import dataclass, field

import numpy as np

from ..progress import bar as progress_bar
from ..validation import check_run_memory, integer
from .pools import ignore_interrupts, process_pool
from .spec import Chunk, RigiditySweep, Sweep
from .states import chunk_state_gsd, save_chunk_state, state_path
from .store import CHUNK_DIR, merge_records, open_sweep_folder, scan_chunks, sorted_records, write_columns
from .tables import summarize_records
from .tilings import TilingPrefetch, build_tilings, chunk_seeds

#: cells per batch on the CPU: the NumPy cost per cell and step is flat from ~500 cells up (and
#: rises slowly beyond ~2000, out of cache), while a smaller batch wastes fewer steps waiting for
#: its slowest replica (docs/rigidity.md, "Chunking").
CPU_BATCH_CELLS = 512
#: cells per batch on a GPU: large, so each kernel launch serves many replicas; ~0.3 GB.
GPU_BATCH_CELLS = 1 << 18


#: a GPU sweep with at least this many cells to compute builds its tilings in a process pool, ahead
#: of the GPU (one tiling per replica on the host is otherwise the bottleneck: 0.02-0.06 s each at
#: N = 1024, against ~1 ms of GPU time per replica)
PREFETCH_MIN_CELLS = 100_000
#: the prefetching pool's processes at most: each chunk is cut into one part per process, and this
#: process gathers the parts of every chunk for every GPU (docs/performance.md, "Several GPUs")
MAX_TILING_PROCESSES = 32


# ---------------------------------------------------------------------------------------- one chunk
def build_chunk_state(sweep: RigiditySweep, chunk: Chunk, state=None, seeds=None):
    """The batched State of a chunk (``state`` and ``seeds`` if they were made elsewhere, as
    :class:`TilingPrefetch` does) and its per-replica (p0, p0_index, replica, tiling_seed)."""
    units = [sweep.unit(u) for u in range(chunk.start, chunk.stop)]
    if seeds is None:
        seeds = chunk_seeds(sweep, chunk)[1]
    if state is None:   # shared tilings: a repeated seed gives the same tiling
        state = build_tilings(sweep.surface, chunk.n_cells, seeds)
    p0 = np.array([sweep.p0[k] for k, _ in units])
    return state, p0, [k for k, _ in units], [r for _, r in units], list(seeds)


def run_chunk(parameters: dict, n_cells: int, start: int, stop: int, device="cpu", state=None,
              save_states=False, timing=False, seeds=None) -> dict:
    """Minimise one chunk; returns its per-replica records (a dict of lists, :data:`RECORD_COLUMNS`),
    with ``save_states`` also its minimised State as the bytes of a GSD file (key ``"state_gsd"``,
    :func:`spherevm.sweeps.states.chunk_state_gsd`), with ``timing`` also when its stages ended
    (key ``"timing"``: ``started``, ``built`` (tilings), ``minimized`` and ``ended`` as ``time.time()``,
    and the worker's ``pid``).

    A plain module-level function of plain arguments, so any executor (process pool, Dask) can run
    it (``state``, ``seeds``: the chunk's tilings and their seeds when made elsewhere). The vertex
    model is given per cell:
    ``kA = kr kP / <A>``, ``kP = 1``, ``A0 = <A>``, ``P0 = p0 sqrt(<A>)``, with each replica's own p0.
    """
    from ..plugins import build_force
    from ..plugins.forces import VertexModel
    from ..plugins.integrators import FIRE
    from ..plugins.updaters import T1
    from ..simplicity import inverted_counts
    from ..simulation import Simulation

    t0, started = time.perf_counter(), time.time()
    sweep = RigiditySweep.from_parameters(parameters)
    chunk = Chunk(int(n_cells), int(start), int(stop))
    state, p0, p0_index, replica, seeds = build_chunk_state(sweep, chunk, state, seeds)
    built = time.time()
    mean_area = state.mean_cell_area                     # per replica (1 at the default radius)
    cell_rep = state.cell_replica_np()
    area = mean_area[cell_rep]
    sim = Simulation(device=device, seed=sweep.seed)
    sim.state = state
    sim.operations.forces.append(VertexModel(kA=sweep.kr / area, kP=1.0, A0=area,
                                             P0=p0[cell_rep] * np.sqrt(area)))
    sim.operations.forces.extend(build_force(name, dict(params)) for name, params in sweep.forces)
    # with a length factor, T1 ignores new_length
    sim.operations.updaters.append(T1(threshold=sweep.t1_threshold, new_length=sweep.t1_new_length,
                                      length_factor=sweep.t1_length_factor, max_flip_backs=sweep.t1_max_flip_backs))
    sim.operations.integrator = FIRE(dt=sweep.dt)
    res = sim.minimize(force_tol=sweep.force_tol, energy_tol=sweep.energy_tol, max_steps=sweep.max_steps,
                       check_every=sweep.check_every)
    flips = np.asarray(sim.log("t1_total_flips"))          # the loggable syncs the GPU counters
    inverted = inverted_counts(sim.state)
    elapsed, minimized = time.perf_counter() - t0, time.time()
    n = chunk.size
    extra = {"state_gsd": chunk_state_gsd(sim, p0, p0_index, replica)} if save_states else {}
    if timing:
        extra["timing"] = {"pid": os.getpid(), "started": started, "built": built, "minimized": minimized,
                           "ended": time.time()}
    return {**extra, "n_cells": [chunk.n_cells] * n, "p0": p0.tolist(), "p0_index": list(p0_index), "replica": list(replica),
            "tiling_seed": list(seeds), "energy_per_cell": [float(e) for e in res.energy_per_cell],
            "max_force": [float(f) for f in res.max_force],
            "mean_shape_index": [float(q) for q in res.mean_shape_index],
            "steps": [int(s) for s in res.steps], "reason": [str(r) for r in res.reason],
            "t1_flips": [int(f) for f in flips], "inverted_cells": [int(c) for c in inverted],
            "chunk": [chunk.id] * n, "chunk_seconds": [round(elapsed, 4)] * n}


# ---------------------------------------------------------------------------------------- executors
class InProcessExecutor(cf.Executor):
    """Runs each call at submission, in this process (for the GPU, tests and debugging)."""

    def __init__(self):
        self._shutdown = False

    def submit(self, fn, /, *args, **kwargs):
        if self._shutdown:
            raise RuntimeError("cannot schedule new futures after shutdown")
        future = cf.Future()
        try:
            result = fn(*args, **kwargs)
        except BaseException as exc:  # noqa: BLE001 - handed to the caller through the future
            if isinstance(exc, (KeyboardInterrupt, SystemExit)):
                raise
            future.set_exception(exc)
        else:
            future.set_result(result)
        return future

    def shutdown(self, wait=True, *, cancel_futures=False):
        self._shutdown = True


def default_executor(device="auto", workers=None):
    """``(executor, device_name, owned)``: in-process on a GPU, a process pool on the CPU."""
    from ..device import resolve
    dev = resolve(device)
    if dev.is_gpu:
        return InProcessExecutor(), dev.name, True
    n = (os.cpu_count() or 1) if workers is None else integer("workers", workers, 1)
    if n <= 1:
        return InProcessExecutor(), dev.name, True
    return process_pool(n, initializer=ignore_interrupts), dev.name, True


def executor_slots(executor) -> int:
    """How many chunks ``executor`` runs at once: a Dask client's worker threads, a pool's workers."""
    client = getattr(executor, "_client", executor)          # a Client, or the executor it gives
    if hasattr(client, "nthreads"):
        return max(1, sum(client.nthreads().values()))
    return max(1, int(getattr(executor, "_max_workers", 1)))


def _stop_now(executor):
    """Shut an owned executor down without waiting for the chunks still running: a process pool's
    workers are terminated, else Ctrl-C would wait for each to finish its chunk (minutes)."""
    processes = list((getattr(executor, "_processes", None) or {}).values())
    executor.shutdown(wait=False, cancel_futures=True)
    for p in processes:
        p.terminate()
    for p in processes:
        p.join(timeout=5)


def _check_sweep_memory(sweep, batch_cells, device_name, workers):
    """Refuse (InsufficientMemory) a sweep whose largest chunk, in every worker at once, cannot fit
    on this machine, before the folder or any worker is made."""
    largest = max(sweep.cells)
    chunks = sweep.plan(batch_cells)
    chunk = max(c.size * c.n_cells for c in chunks)
    copies = min(workers, len(chunks))
    check_run_memory(f"the sweep ({copies} worker(s), chunks of up to {chunk} cells)", chunk, largest,
                     gpu=device_name == "gpu", copies=copies,
                     advice="use smaller systems (cells), fewer workers or a smaller batch_cells")


# ---------------------------------------------------------------------------------------- progress
@dataclass
class SweepProgress:
    """What a progress callback receives after every finished chunk (and once at the start)."""
    chunks_done: int
    chunks_total: int
    units_done: int        # minimisations (tissues) finished, including those found on disk
    units_total: int
    units_reused: int      # found on disk at the start
    elapsed: float
    last_chunk: str = ""
    cells_done: int = 0    # the same counts weighted by N (the cost of a minimisation grows with N)
    cells_total: int = 0
    cells_reused: int = 0

    @property
    def eta(self) -> float:
        """Seconds left, extrapolated from the cells minimised so far in this run (NaN at first)."""
        new = self.cells_done - self.cells_reused
        left = self.cells_total - self.cells_done
        return math.nan if new <= 0 else self.elapsed * left / new


class TextProgress:
    """The sweep's progress bar (tqdm) on a stream (standard error by default): the share of the
    work done (cells, since a minimisation's cost grows with N), chunks and minimisations done,
    those found on disk, elapsed time and ETA; a widget in a notebook. ``enabled``: True (the
    default) draws it, None only on a terminal or in a notebook (silent in a log or a pipe), False
    never (see :func:`spherevm.progress.bar`)."""

    def __init__(self, stream=None, label="rigidity", enabled=True, units="minimisations"):
        self.stream, self.label, self.enabled, self.units = stream, label, enabled, units
        self.bar = None

    def __call__(self, p: SweepProgress):
        if self.bar is None:
            self.bar = progress_bar(p.cells_total, self.label, " cells", self.stream, self.enabled,
                                    initial=p.cells_done, smoothing=0,
                                    bar_format="{desc}: {percentage:5.1f}%|{bar}| [{elapsed}<{remaining}{postfix}]")
        reused = f" ({p.units_reused} on disk)" if p.units_reused else ""
        self.bar.set_postfix_str(f"chunks {p.chunks_done}/{p.chunks_total}  "
                                 f"{self.units} {p.units_done}/{p.units_total}{reused}", refresh=False)
        self.bar.update(p.cells_done - self.bar.n)
        if p.chunks_done == p.chunks_total:
            self.bar.refresh()

    def close(self):
        if self.bar is not None:
            self.bar.close()
            self.bar = None


# ---------------------------------------------------------------------------------------- the sweep
@dataclass
class SweepResult:
    """What :func:`run_sweep` returns."""
    sweep: Sweep
    out: str
    records: dict                      # per-replica columns (NumPy), sorted by sweep.columns.sort
    computed: list = field(default_factory=list)   # chunk ids computed in this call
    reused: int = 0                    # chunk files found finished on disk
    recomputed_bad: list = field(default_factory=list)  # unreadable chunk files that were recomputed
    elapsed: float = 0.0
    executor: str = ""
    #: with ``timeline=True``, one dict per computed chunk: its ``chunk`` id, ``n_cells``, ``size`` and
    #: when (``time.time()``) the sweep began waiting for its tilings (``asked``), had them and submitted
    #: it (``submitted``), the worker started, built, minimised and ended it (:func:`run_chunk`'s
    #: ``timing``, with the worker's ``pid``), and the sweep had its result (``received``) and wrote it
    #: (``written``); ``started`` is when the sweep began
    timeline: list = field(default_factory=list)
    started: float = 0.0

    def summarize(self, zero_tol=None, **kwargs):
        """``(fractions, p0star, density)`` tables, see :func:`spherevm.analysis.rigidity.summarize`."""
        return summarize_records(self.records, zero_tol=zero_tol, **{"surface": self.sweep.surface, **kwargs})


def _drop_chunks_without_states(sweep, path, done, parts):
    """Mark the units of finished chunks that have no state file as missing (and remove those
    chunk files, which the new chunks replace); return the records kept."""
    kept = []
    for rec in parts:
        cid = rec["chunk"][0]
        if os.path.isfile(state_path(path, cid)):
            kept.append(rec)
            continue
        n = rec["n_cells"][0]
        done[n][np.asarray(rec["p0_index"]) * sweep.replicas + np.asarray(rec["replica"])] = False
        os.remove(os.path.join(path, CHUNK_DIR, cid + ".csv"))
    return kept


def run_sweep(sweep: Sweep, out, executor=None, device="auto", workers=None, batch_cells=None,
              progress=None, save_states=False, prefetch=None, timeline=False) -> SweepResult:
    """Run (or resume) a sweep, writing each chunk to ``<out>/chunks/`` as it finishes.

    Everything is validated before the folder is created; a folder holding a sweep with other
    parameters raises ValueError. A chunk that fails stops the sweep (RuntimeError naming the
    chunk); the chunks finished before it stay on disk and a rerun resumes from them.

    Parameters
    ----------
    sweep : RigiditySweep or DynamicsSweep
        Any :class:`~spherevm.sweeps.spec.Sweep`: it plans the chunks, names the function that
        computes one and the columns of its records.
    out : str or path
        The output folder.
    executor : concurrent.futures.Executor or distributed.Client, optional
        None picks :func:`default_executor` (in-process on a GPU, a process pool of ``workers``
        processes on the CPU).
    device : {"cpu", "gpu", "auto"}
        Where each chunk is minimised (with your own executor it is resolved on the worker).
    workers : int, optional
        Processes (default: the CPU count; when tilings are prefetched, the CPU count less one per
        GPU worker, at most :data:`MAX_TILING_PROCESSES`).
    batch_cells : int, optional
        Cells per chunk (default :data:`CPU_BATCH_CELLS` or :data:`GPU_BATCH_CELLS`); it changes how
        the work is cut, never the results.
    progress : callable, optional
        Called with a :class:`SweepProgress` after every chunk.
    save_states : bool
        Also keep each chunk's minimised States in ``<out>/states/<chunk id>.gsd``
        (:func:`spherevm.sweeps.load_state`).
    prefetch : bool, optional
        Build the tilings in a process pool on this machine ahead of the workers
        (:class:`TilingPrefetch`); the results are the same. None: for GPU sweeps of at least
        :data:`PREFETCH_MIN_CELLS` cells on a machine of three or more cores.
    timeline : bool
        Record when each chunk's stages began and ended (:attr:`SweepResult.timeline`;
        ``benchmarks/sweep_timeline.py`` draws it).

    Returns
    -------
    SweepResult"""
    if not isinstance(sweep, Sweep):
        raise TypeError(f"sweep must be a RigiditySweep or a DynamicsSweep, got {type(sweep).__name__}")
    from ..device import DEVICE_NAMES, Device
    if not isinstance(device, Device) and (not isinstance(device, str) or device.lower() not in DEVICE_NAMES):
        raise ValueError(f"device must be one of {DEVICE_NAMES}, got {device!r}")
    if workers is not None:
        integer("workers", workers, 1)
    if batch_cells is not None:
        integer("batch_cells", batch_cells, 1)
    if progress is not None and not callable(progress):
        raise TypeError("progress must be callable")
    open_sweep_folder(sweep, out, create=False)          # bad folder or mismatch: errors before anything is made

    if prefetch is not None and not isinstance(prefetch, bool):
        raise TypeError(f"prefetch must be True, False or None, got {prefetch!r}")
    for flag, name, allowed in ((prefetch, "prefetch", sweep.prefetch_tilings),
                                (save_states, "save_states", sweep.keeps_states)):
        if flag and not allowed:
            raise ValueError(f"{name}=True is for rigidity sweeps; a {sweep.KIND} sweep does without")
    run = sweep.chunk_function or run_chunk

    owned = False
    if executor is None:
        executor, device_name, owned = default_executor(device, workers)
    else:
        if hasattr(executor, "get_executor") and not isinstance(executor, cf.Executor):
            executor = executor.get_executor()          # a dask.distributed Client
        if not hasattr(executor, "submit"):
            raise TypeError(f"executor must be a concurrent.futures.Executor, got {type(executor).__name__}")
        device_name = device.name if isinstance(device, Device) else device.lower()
    if batch_cells is None:
        batch_cells = GPU_BATCH_CELLS if device_name == "gpu" else CPU_BATCH_CELLS
    if owned:
        try:
            _check_sweep_memory(sweep, batch_cells, device_name, getattr(executor, "_max_workers", 1))
        except BaseException:
            executor.shutdown(wait=False, cancel_futures=True)
            raise
    tilings = None
    try:
        path = open_sweep_folder(sweep, out, create=True)
        done, parts, bad = scan_chunks(sweep, path, clean=True)
        if save_states:
            parts = _drop_chunks_without_states(sweep, path, done, parts)
        chunks = sweep.plan(batch_cells, done)
        reused_units = int(sum(d.sum() for d in done.values()))
        reused_cells = int(sum(n * d.sum() for n, d in done.items()))
        t0 = time.perf_counter()
        state = SweepProgress(chunks_done=0, chunks_total=len(chunks), units_done=reused_units,
                              units_total=sweep.total_units, units_reused=reused_units, elapsed=0.0,
                              cells_done=reused_cells, cells_total=sweep.units_per_size * sum(sweep.cells),
                              cells_reused=reused_cells)
        if progress is not None:
            progress(state)
        params = sweep.parameters()
        # the call stays the same without these options
        options = {**({"save_states": True} if save_states else {}), **({"timing": True} if timeline else {})}
        events, started = {}, time.time()
        in_process = isinstance(executor, InProcessExecutor)
        slots = executor_slots(executor)
        todo = sorted(chunks, key=lambda c: -c.n_cells * c.size)        # largest N first
        cpus = os.cpu_count() or 1
        if prefetch is None:
            prefetch = (sweep.prefetch_tilings and device_name == "gpu" and cpus > 2 and len(todo) > 1
                        and sum(c.n_cells * c.size for c in todo) >= PREFETCH_MIN_CELLS)
        # bounded submission: in-process runs at submit (each chunk written before the next starts);
        # with prefetched tilings two chunks per worker (the pool just ahead); else all at once
        limit = 1 if in_process else 2 * slots if prefetch else len(todo)
        tilers = min(max(1, cpus - slots), MAX_TILING_PROCESSES) if workers is None else workers
        tilings = TilingPrefetch(sweep, todo, tilers, ahead=limit + 1) if prefetch else None
        pending = {}
        computed = []
        folder = os.path.join(path, CHUNK_DIR)
        while todo or pending:
            while todo and len(pending) < limit:
                c = todo.pop(0)
                asked = time.time()
                built = {} if tilings is None else tilings.get(c)
                events[c.id] = {"chunk": c.id, "n_cells": c.n_cells, "size": c.size, "asked": asked,
                                "submitted": time.time()}
                pending[executor.submit(run, params, c.n_cells, c.start, c.stop, device_name, **built,
                                        **options)] = c
            finished, _ = cf.wait(list(pending), return_when=cf.FIRST_COMPLETED)
            for fut in finished:
                c = pending.pop(fut)
                exc = fut.exception()
                if exc is not None:
                    for other in pending:
                        other.cancel()
                    raise RuntimeError(f"chunk {c.id} ({c.size} tilings of N = {c.n_cells}) failed: "
                                       f"{type(exc).__name__}: {exc}; finished chunks are kept in {folder}, "
                                       "rerun to resume") from exc
                rec = fut.result()
                events[c.id].update(rec.pop("timing", {}), received=time.time())
                if save_states:                 # the state first: a chunk file then implies its state
                    save_chunk_state(path, c.id, rec.pop("state_gsd"))
                sweep.write_extras(path, c, rec)
                write_columns(os.path.join(folder, c.id + ".csv"), rec, sweep.columns.names)
                events[c.id]["written"] = time.time()
                parts.append(rec)
                computed.append(c.id)
                state.chunks_done += 1
                state.units_done += c.size
                state.cells_done += c.size * c.n_cells
                state.elapsed = time.perf_counter() - t0
                state.last_chunk = c.id
                if progress is not None:
                    progress(state)
    except BaseException:
        # a failed chunk or Ctrl-C: do not wait for the chunks still running (finished ones are on disk)
        if owned:
            owned = False
            _stop_now(executor)
        raise
    finally:
        if tilings is not None:
            tilings.close()
        if owned:
            executor.shutdown(wait=True)
    records = sorted_records(merge_records(parts, sweep.columns), sweep.columns)
    return SweepResult(sweep=sweep, out=path, records=records, computed=computed,
                       reused=len(parts) - len(computed), recomputed_bad=[b for b, _ in bad],
                       elapsed=time.perf_counter() - t0, executor=type(executor).__name__,
                       timeline=[events[c] for c in computed] if timeline else [], started=started)
