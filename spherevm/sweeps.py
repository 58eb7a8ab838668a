"""Parameter sweeps over any :class:`concurrent.futures.Executor`: the athermal rigidity transition.

A :class:`RigiditySweep` names the sizes N, the p0 grid, the replicas per point, kr, the seed and
the minimiser's stop criteria. :func:`run_sweep` splits it into chunks (batched ensembles: many
(p0, replica) tilings of one N in one State, so every step serves all of them), runs the chunks on
an executor and writes each one to ``<out>/chunks/`` as soon as it finishes; a rerun with the same
parameters finds the finished chunks and computes only what is missing. :func:`write_tables` then
turns the per-replica records into F(p0, N), the distributions of p0* and p0*(N) (CSV, and PNG
when matplotlib is installed), using :mod:`spherevm.analysis.rigidity`.

::

    import spherevm as svm
    sweep = svm.sweeps.RigiditySweep(cells=[16, 32], p0=np.arange(3.5, 4.001, 0.05), replicas=8)
    result = svm.sweeps.run_sweep(sweep, "sweep/")            # process pool on the CPU
    tables = svm.sweeps.write_tables("sweep/", result.records)
    print(tables["p0star"]["p0_star"])

Executors: by default the chunks run in this process when the device is a GPU (one big batch after
another) and on a :class:`~concurrent.futures.ProcessPoolExecutor` on the CPU. Any executor works,
for example a Dask cluster's (``client.get_executor()``, or pass the ``distributed.Client``
itself), which needs the optional ``cluster`` extra. Results do not depend on the executor or on
the chunking: every (N, p0, replica) tiling has its own seed and every replica is minimised
independently. See docs/rigidity.md.

The command ``spherevm rigidity`` (:func:`add_cli`) runs a sweep from the shell.
"""
from __future__ import annotations

import concurrent.futures as cf
import csv
import json
import math
import os
import sys
import time
import warnings
from dataclasses import asdict, dataclass, field, fields

import numpy as np

from .provenance import source_fingerprint

FORMAT = "spherevm-rigidity-sweep"
FORMAT_VERSION = 1
MANIFEST = "manifest.json"
CHUNK_DIR = "chunks"
#: cells per batch on the CPU: the NumPy cost per cell and step is flat from ~500 cells up (and
#: rises slowly beyond ~2000, out of cache), while a smaller batch wastes fewer steps waiting for
#: its slowest replica (docs/rigidity.md, "Chunking").
CPU_BATCH_CELLS = 512
#: cells per batch on a GPU: large, so each kernel launch serves many replicas; ~0.3 GB.
GPU_BATCH_CELLS = 1 << 18

RECORD_COLUMNS = ("n_cells", "p0", "p0_index", "replica", "tiling_seed", "energy_per_cell", "max_force",
                  "mean_shape_index", "steps", "reason", "t1_flips", "chunk", "chunk_seconds")
_INT_COLUMNS = {"n_cells", "p0_index", "replica", "tiling_seed", "steps", "t1_flips"}
_STR_COLUMNS = {"reason", "chunk"}


# ---------------------------------------------------------------------------------------- parameters
def _int(name, value, lo):
    try:
        ok = int(value) == value
    except (TypeError, ValueError):
        ok = False
    if not ok or isinstance(value, bool) or int(value) < lo:
        raise ValueError(f"{name} must be an integer >= {lo}, got {value!r}")
    return int(value)


def _pos(name, value, zero_ok=False):
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a finite number {'>= 0' if zero_ok else '> 0'}, got {value!r}") from None
    if not math.isfinite(v) or v < 0 or (v == 0 and not zero_ok):
        raise ValueError(f"{name} must be a finite number {'>= 0' if zero_ok else '> 0'}, got {value!r}")
    return v


@dataclass(frozen=True)
class RigiditySweep:
    """What to compute: every (N in ``cells``, p0 in ``p0``, replica < ``replicas``) minimised.

    * ``cells``: cells per tiling, each >= 4, no duplicates (sorted for you);
    * ``p0``: the target shape indices, non-empty, finite, > 0 and strictly increasing;
    * ``replicas``: random tilings per (N, p0), >= 1;
    * ``kr``: area stiffness kA <A> / kP (0: the paper's Fig. 2);
    * ``seed``: the tiling of (N, p0, replica) is drawn from ``seed`` and those three numbers only;
      ``shared_tilings=True`` uses the same tilings at every p0 (then F(p0) per tiling is a step).
    * minimiser: FIRE time step ``dt``; a replica stops when its largest vertex force is below
      ``force_tol``, its energy per cell below ``energy_tol`` (a zero-energy state), after
      ``max_steps`` steps, or when T1 flips oscillate (``t1_max_flip_backs`` re-joins of one pair);
      T1 exchanges of edges shorter than ``t1_threshold`` (new edges ``t1_new_length``), units
      sqrt(<A>); ``t1_length_factor`` instead makes a new edge that many times the old one (the
      paper code's rule is ``t1_threshold=0.1, t1_length_factor=2``, :meth:`reference_t1`).
      Defaults from docs/rigidity.md.

    The energy is ``E = sum_c kr/<A> (A_c - <A>)^2 + (P_c - p0 sqrt(<A>))^2`` per tiling (kP = 1), so
    that ``energy_per_cell`` is in units of kP <A>^2 (<A> = 1 at the default radius sqrt(N/4 pi)).
    """
    cells: tuple
    p0: tuple
    replicas: int
    kr: float = 0.0
    seed: int = 0
    shared_tilings: bool = False
    dt: float = 0.02
    force_tol: float = 1e-12
    energy_tol: float = 1e-16
    max_steps: int = 20000
    check_every: int = 10
    t1_threshold: float = 0.04
    t1_new_length: float = 0.12
    t1_max_flip_backs: int = 100
    t1_length_factor: float = None

    def __post_init__(self):
        set_ = object.__setattr__
        cells = self.cells
        if isinstance(cells, (int, np.integer)):
            cells = (cells,)
        try:
            cells = [_int("cells", c, 4) for c in cells]
        except TypeError:
            raise ValueError(f"cells must be a list of integers >= 4, got {self.cells!r}") from None
        if not cells:
            raise ValueError("cells must list at least one system size N >= 4, got an empty list")
        if len(set(cells)) != len(cells):
            raise ValueError(f"cells must not repeat a size, got {list(self.cells)}")
        set_(self, "cells", tuple(sorted(cells)))
        p0 = self.p0
        if isinstance(p0, (int, float, np.floating, np.integer)):
            p0 = (p0,)
        try:
            p0 = np.asarray([float(p) for p in p0], dtype=np.float64)
        except (TypeError, ValueError):
            raise ValueError(f"p0 must be a list of numbers, got {self.p0!r}") from None
        if len(p0) == 0:
            raise ValueError("p0 grid is empty: give at least one value (two or more to locate p0*)")
        if not np.all(np.isfinite(p0)) or np.any(p0 <= 0):
            raise ValueError(f"p0 values must be finite and > 0, got {p0.tolist()}")
        if np.any(np.diff(p0) <= 0):
            i = int(np.flatnonzero(np.diff(p0) <= 0)[0])
            raise ValueError(f"p0 grid must be strictly increasing: p0[{i}] = {p0[i]:g} is followed by "
                             f"p0[{i + 1}] = {p0[i + 1]:g}")
        if len(set(_p0_key(p) for p in p0)) != len(p0):
            raise ValueError("p0 values must differ by more than 1e-6")
        set_(self, "p0", tuple(float(p) for p in p0))
        set_(self, "replicas", _int("replicas", self.replicas, 1))
        set_(self, "kr", _pos("kr", self.kr, zero_ok=True))
        set_(self, "seed", _int("seed", self.seed, 0))
        set_(self, "shared_tilings", bool(self.shared_tilings))
        set_(self, "dt", _pos("dt", self.dt))
        set_(self, "force_tol", _pos("force_tol", self.force_tol, zero_ok=True))
        set_(self, "energy_tol", _pos("energy_tol", self.energy_tol, zero_ok=True))
        set_(self, "max_steps", _int("max_steps", self.max_steps, 1))
        set_(self, "check_every", _int("check_every", self.check_every, 1))
        set_(self, "t1_threshold", _pos("t1_threshold", self.t1_threshold))
        set_(self, "t1_new_length", _pos("t1_new_length", self.t1_new_length))
        if self.t1_length_factor is None and self.t1_new_length <= self.t1_threshold:
            raise ValueError(f"t1_new_length must be > t1_threshold = {self.t1_threshold}, got {self.t1_new_length}")
        set_(self, "t1_max_flip_backs", _int("t1_max_flip_backs", self.t1_max_flip_backs, 1))
        if self.t1_length_factor is not None:
            set_(self, "t1_length_factor", _pos("t1_length_factor", self.t1_length_factor))

    @staticmethod
    def reference_t1() -> dict:
        """The T1 rules of the paper's own code (``T1(preset="reference")``), as sweep parameters."""
        return {"t1_threshold": 0.1, "t1_length_factor": 2.0}

    def parameters(self) -> dict:
        """JSON-ready parameters (what the manifest stores and a resumed sweep must match)."""
        out = asdict(self)
        out["cells"], out["p0"] = list(self.cells), list(self.p0)
        return out

    @classmethod
    def from_parameters(cls, params: dict) -> "RigiditySweep":
        names = {f.name for f in fields(cls)}
        unknown = set(params) - names
        if unknown:
            raise ValueError(f"unknown sweep parameters {sorted(unknown)}")
        return cls(**params)

    @property
    def units_per_size(self) -> int:
        """(p0, replica) pairs per N."""
        return len(self.p0) * self.replicas

    @property
    def total_units(self) -> int:
        return len(self.cells) * self.units_per_size

    def unit(self, u: int):
        """``(p0_index, replica)`` of unit ``u`` (p0-major order)."""
        return divmod(int(u), self.replicas)


def _p0_key(p0: float) -> int:
    return int(round(float(p0) * 1e6))


def tiling_seed(seed: int, n_cells: int, p0: float, replica: int, shared: bool = False) -> int:
    """The seed of the random tiling of (N, p0, replica): a function of these numbers only, so the
    result of a replica does not depend on the chunking, the executor or the rest of the grid.
    With ``shared=True`` it does not depend on p0 either."""
    key = [int(seed), int(n_cells), int(replica)] if shared else [int(seed), int(n_cells), _p0_key(p0), int(replica)]
    a, b = np.random.SeedSequence(key).generate_state(2, dtype=np.uint32)
    return (int(a) << 31) ^ int(b)   # < 2^63


# ---------------------------------------------------------------------------------------- chunks
@dataclass(frozen=True)
class Chunk:
    """Units ``start:stop`` (p0-major (p0, replica) pairs) of size ``n_cells``: one batched ensemble."""
    n_cells: int
    start: int
    stop: int

    @property
    def id(self) -> str:
        return f"N{self.n_cells:05d}_u{self.start:06d}-{self.stop:06d}"

    @property
    def size(self) -> int:
        return self.stop - self.start


def plan_chunks(sweep: RigiditySweep, batch_cells: int, done=None) -> list:
    """Chunks covering every unit not in ``done`` (a dict N -> bool array over units).

    Each maximal run of missing units of one N is cut into chunks of ``max(1, batch_cells // N)``
    units, so a fresh sweep has ``ceil(P R N / batch_cells)`` chunks per N and a resumed one
    recomputes exactly the missing runs.
    """
    batch_cells = _int("batch_cells", batch_cells, 1)
    out = []
    for n in sweep.cells:
        per = max(1, batch_cells // n)
        missing = np.ones(sweep.units_per_size, dtype=bool)
        if done is not None and n in done:
            missing &= ~done[n]
        idx = np.flatnonzero(missing)
        if len(idx) == 0:
            continue
        breaks = np.flatnonzero(np.diff(idx) > 1) + 1
        for run in np.split(idx, breaks):
            a, b = int(run[0]), int(run[-1]) + 1
            for s in range(a, b, per):
                out.append(Chunk(n, s, min(s + per, b)))
    return out


def build_chunk_state(sweep: RigiditySweep, chunk: Chunk):
    """The batched State of a chunk and its per-replica (p0, p0_index, replica, tiling_seed)."""
    from .init import random_tilings
    units = [sweep.unit(u) for u in range(chunk.start, chunk.stop)]
    seeds = [tiling_seed(sweep.seed, chunk.n_cells, sweep.p0[k], r, sweep.shared_tilings) for k, r in units]
    state = random_tilings(chunk.n_cells, seeds)   # shared tilings: a repeated seed gives the same tiling
    p0 = np.array([sweep.p0[k] for k, _ in units])
    return state, p0, [k for k, _ in units], [r for _, r in units], seeds


def run_chunk(parameters: dict, n_cells: int, start: int, stop: int, device="cpu") -> dict:
    """Minimise one chunk; returns its per-replica records (a dict of lists, :data:`RECORD_COLUMNS`).

    A plain module-level function of plain arguments, so any executor (process pool, Dask) can run
    it. The vertex model is given per cell: ``kA = kr kP / <A>``, ``kP = 1``, ``A0 = <A>``,
    ``P0 = p0 sqrt(<A>)``, with each replica's own p0.
    """
    from .plugins.forces import VertexModel
    from .plugins.integrators import FIRE
    from .plugins.updaters import T1
    from .simulation import Simulation

    t0 = time.perf_counter()
    sweep = RigiditySweep.from_parameters(parameters)
    chunk = Chunk(int(n_cells), int(start), int(stop))
    state, p0, p0_index, replica, seeds = build_chunk_state(sweep, chunk)
    mean_area = state.mean_cell_area                     # per replica (1 at the default radius)
    cell_rep = state.cell_replica_np()
    area = mean_area[cell_rep]
    sim = Simulation(device=device, seed=sweep.seed)
    sim.state = state
    sim.operations.forces.append(VertexModel(kA=sweep.kr / area, kP=1.0, A0=area,
                                             P0=p0[cell_rep] * np.sqrt(area)))
    if sweep.t1_length_factor is not None:
        t1 = T1(threshold=sweep.t1_threshold, new_length=None, length_factor=sweep.t1_length_factor,
                max_flip_backs=sweep.t1_max_flip_backs)
    else:
        t1 = T1(threshold=sweep.t1_threshold, new_length=sweep.t1_new_length, max_flip_backs=sweep.t1_max_flip_backs)
    sim.operations.updaters.append(t1)
    sim.operations.integrator = FIRE(dt=sweep.dt)
    res = sim.minimize(force_tol=sweep.force_tol, energy_tol=sweep.energy_tol, max_steps=sweep.max_steps,
                       check_every=sweep.check_every)
    flips = np.asarray(sim.log("t1_total_flips"))          # the loggable syncs the GPU counters
    elapsed = time.perf_counter() - t0
    n = chunk.size
    return {"n_cells": [chunk.n_cells] * n, "p0": p0.tolist(), "p0_index": list(p0_index), "replica": list(replica),
            "tiling_seed": list(seeds), "energy_per_cell": [float(e) for e in res.energy_per_cell],
            "max_force": [float(f) for f in res.max_force],
            "mean_shape_index": [float(q) for q in res.mean_shape_index],
            "steps": [int(s) for s in res.steps], "reason": [str(r) for r in res.reason],
            "t1_flips": [int(f) for f in flips], "chunk": [chunk.id] * n,
            "chunk_seconds": [round(elapsed, 4)] * n}


# ---------------------------------------------------------------------------------------- files
def _format(value):
    if isinstance(value, float):
        return repr(value)
    return str(value)


def write_columns(path, columns: dict, order=None):
    """Write a dict of equal-length columns as CSV, atomically (a temporary file, then rename)."""
    order = list(order or columns)
    n = len(next(iter(columns.values()))) if columns else 0
    tmp = f"{path}.tmp{os.getpid()}"
    with open(tmp, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(order)
        for i in range(n):
            row = []
            for c in order:
                v = columns[c][i]
                if isinstance(v, (np.floating,)):
                    v = float(v)
                elif isinstance(v, (np.integer,)):
                    v = int(v)
                elif isinstance(v, np.bool_):
                    v = bool(v)
                row.append(_format(v))
            w.writerow(row)
    os.replace(tmp, path)


def read_records(path) -> dict:
    """Read a chunk (or replicas.csv) file back into typed columns (lists)."""
    with open(path, newline="") as fh:
        rows = list(csv.reader(fh))
    if not rows or tuple(rows[0]) != RECORD_COLUMNS:
        raise ValueError(f"{path}: not a sweep record file (header {rows[0] if rows else 'missing'})")
    out = {c: [] for c in RECORD_COLUMNS}
    for row in rows[1:]:
        if len(row) != len(RECORD_COLUMNS):
            raise ValueError(f"{path}: malformed row {row}")
        for c, v in zip(RECORD_COLUMNS, row):
            out[c].append(v if c in _STR_COLUMNS else int(v) if c in _INT_COLUMNS else float(v))
    return out


def _merge(parts) -> dict:
    out = {c: [] for c in RECORD_COLUMNS}
    for p in parts:
        for c in RECORD_COLUMNS:
            out[c].extend(p[c])
    return out


def _sorted_records(records: dict) -> dict:
    """Records as NumPy columns, sorted by (N, p0 index, replica)."""
    cols = {c: np.asarray(records[c]) for c in RECORD_COLUMNS}
    if len(cols["n_cells"]) == 0:
        return cols
    order = np.lexsort((cols["replica"], cols["p0_index"], cols["n_cells"]))
    return {c: v[order] for c, v in cols.items()}


def _check_out_folder(out):
    """Fail (ValueError) before anything is created when ``out`` cannot become a sweep folder."""
    if out is None or str(out) == "":
        raise ValueError("out must name a folder for the sweep's results, got an empty path")
    path = os.path.abspath(os.fspath(out))
    if os.path.exists(path):
        if not os.path.isdir(path):
            raise ValueError(f"output folder {out!r} exists and is not a folder")
        if not os.access(path, os.W_OK | os.X_OK):
            raise ValueError(f"output folder {out!r} is not writable (permission denied)")
        return path
    parent = os.path.dirname(path)
    while not os.path.exists(parent):
        up = os.path.dirname(parent)
        if up == parent:
            break
        parent = up
    if not os.path.isdir(parent):
        raise ValueError(f"cannot create output folder {out!r}: {parent!r} is not a folder")
    if not os.access(parent, os.W_OK | os.X_OK):
        raise ValueError(f"cannot create output folder {out!r}: {parent!r} is not writable (permission denied)")
    return path


def _manifest_mismatch(old: dict, new: dict):
    diffs = []
    for key in sorted(set(old) | set(new)):
        a, b = old.get(key, "<missing>"), new.get(key, "<missing>")
        if a != b:
            diffs.append(f"{key}: {a!r} in the folder, {b!r} requested")
    return diffs


def open_sweep_folder(sweep: RigiditySweep, out, create: bool = True) -> str:
    """Check ``out`` against ``sweep`` (ValueError on a mismatch) and write its manifest.

    A new or empty folder gets ``manifest.json``; a folder with a manifest must hold the same
    parameters (else the differences are listed); any other non-empty folder is refused.
    """
    path = _check_out_folder(out)
    manifest_path = os.path.join(path, MANIFEST)
    params = sweep.parameters()
    if os.path.isdir(path) and os.listdir(path):
        if not os.path.exists(manifest_path):
            raise ValueError(f"output folder {out!r} is not empty and holds no {MANIFEST}: not a rigidity sweep "
                             "folder; choose a new or empty folder")
        try:
            with open(manifest_path) as fh:
                manifest = json.load(fh)
        except (OSError, json.JSONDecodeError) as exc:
            raise ValueError(f"cannot read {manifest_path}: {exc}") from None
        if manifest.get("format") != FORMAT:
            raise ValueError(f"{manifest_path} is not a {FORMAT} manifest")
        if manifest.get("version") != FORMAT_VERSION:
            raise ValueError(f"{manifest_path} has format version {manifest.get('version')}, "
                             f"this spherevm writes {FORMAT_VERSION}")
        diffs = _manifest_mismatch(manifest.get("parameters", {}), params)
        if diffs:
            raise ValueError(f"output folder {out!r} holds a sweep with different parameters ("
                             + "; ".join(diffs) + "); use another folder, or the folder's parameters to resume it")
        started_with = manifest.get("code")
        if started_with is not None and started_with != source_fingerprint():
            warnings.warn(f"{out!r} was started by spherevm code {started_with}, this is {source_fingerprint()}: "
                          "the records of both will be mixed (individual minimisations may differ in their "
                          "last digits or, near the transition, in their outcome)", stacklevel=2)
        return path
    if not create:
        return path
    from . import __version__
    os.makedirs(os.path.join(path, CHUNK_DIR), exist_ok=True)
    manifest = {"format": FORMAT, "version": FORMAT_VERSION, "spherevm": __version__, "code": source_fingerprint(),
                "created": time.strftime("%Y-%m-%dT%H:%M:%S%z"), "parameters": params,
                "layout": {"chunks": f"{CHUNK_DIR}/N<cells>_u<first unit>-<end unit>.csv, one row per replica; "
                                     "unit u = p0_index * replicas + replica"}}
    tmp = manifest_path + f".tmp{os.getpid()}"
    with open(tmp, "w") as fh:
        json.dump(manifest, fh, indent=2)
        fh.write("\n")
    os.replace(tmp, manifest_path)
    return path


def scan_chunks(sweep: RigiditySweep, path: str, clean: bool = False):
    """Finished chunk files of a sweep folder: ``(done, records, bad)``.

    ``done`` maps N to a bool array over its units; ``records`` lists the parsed files; ``bad``
    lists files that could not be read or do not match the sweep (they are recomputed).
    ``clean=True`` (run_sweep) removes temporary files an interrupted write left behind.
    """
    folder = os.path.join(path, CHUNK_DIR)
    done = {n: np.zeros(sweep.units_per_size, dtype=bool) for n in sweep.cells}
    records, bad = [], []
    if not os.path.isdir(folder):
        return done, records, bad
    for name in sorted(os.listdir(folder)):
        full = os.path.join(folder, name)
        if ".tmp" in name:          # left over by an interrupted write
            if clean:
                try:
                    os.remove(full)
                except OSError:
                    pass
            continue
        if not name.endswith(".csv"):
            continue
        try:
            rec = read_records(full)
            n = set(rec["n_cells"])
            if len(n) != 1 or next(iter(n)) not in done or not rec["n_cells"]:
                raise ValueError("size not in this sweep")
            n = next(iter(n))
            u = np.asarray(rec["p0_index"]) * sweep.replicas + np.asarray(rec["replica"])
            k = np.asarray(rec["p0_index"])
            if np.any(k < 0) or np.any(k >= len(sweep.p0)) or np.any(np.asarray(rec["replica"]) >= sweep.replicas):
                raise ValueError("unit outside this sweep")
            if not np.allclose(np.asarray(sweep.p0)[k], rec["p0"], rtol=0, atol=1e-12):
                raise ValueError("p0 values do not match the grid")
            if np.any(done[n][u]):
                raise ValueError("units already covered by another chunk file")
        except (ValueError, OSError) as exc:
            bad.append((full, str(exc)))
            continue
        done[n][u] = True
        records.append(rec)
    return done, records, bad


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
    from .device import resolve
    dev = resolve(device)
    if dev.is_gpu:
        return InProcessExecutor(), dev.name, True
    n = (os.cpu_count() or 1) if workers is None else _int("workers", workers, 1)
    if n <= 1:
        return InProcessExecutor(), dev.name, True
    import multiprocessing
    # spawn: no fork of a process that may hold a CUDA context or threads
    return cf.ProcessPoolExecutor(max_workers=n, mp_context=multiprocessing.get_context("spawn")), dev.name, True


@dataclass
class SweepProgress:
    """What a progress callback receives after every finished chunk (and once at the start)."""
    chunks_done: int
    chunks_total: int
    units_done: int        # minimisations finished, including those found on disk
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


@dataclass
class SweepResult:
    """What :func:`run_sweep` returns."""
    sweep: RigiditySweep
    out: str
    records: dict                      # per-replica columns (NumPy), sorted by (N, p0, replica)
    computed: list = field(default_factory=list)   # chunk ids computed in this call
    reused: int = 0                    # chunk files found finished on disk
    recomputed_bad: list = field(default_factory=list)  # unreadable chunk files that were recomputed
    elapsed: float = 0.0
    executor: str = ""

    def summarize(self, zero_tol=None, **kwargs):
        """``(fractions, p0star, density)`` tables, see :func:`spherevm.analysis.rigidity.summarize`."""
        return summarize_records(self.records, zero_tol=zero_tol, **kwargs)


def run_sweep(sweep: RigiditySweep, out, executor=None, device="auto", workers=None, batch_cells=None,
              progress=None) -> SweepResult:
    """Run (or resume) a rigidity sweep, writing each chunk to ``<out>/chunks/`` as it finishes.

    ``executor``: any :class:`concurrent.futures.Executor` (or a ``distributed.Client``, whose
    ``get_executor()`` is used); None picks :func:`default_executor` (in-process on a GPU, a
    process pool of ``workers`` processes on the CPU). ``device``: where each chunk is minimised
    (``"cpu"``, ``"gpu"`` or ``"auto"``; with your own executor it is resolved on the worker).
    ``batch_cells``: cells per chunk (default :data:`CPU_BATCH_CELLS` or :data:`GPU_BATCH_CELLS`);
    it changes how the work is cut, never the results. ``progress``: called with a
    :class:`SweepProgress` after every chunk.

    Everything is validated before the folder is created; a folder holding a sweep with other
    parameters raises ValueError. A chunk that fails stops the sweep (RuntimeError naming the
    chunk); the chunks finished before it stay on disk and a rerun resumes from them.
    """
    if not isinstance(sweep, RigiditySweep):
        raise TypeError(f"sweep must be a RigiditySweep, got {type(sweep).__name__}")
    from .device import DEVICE_NAMES, Device
    if not isinstance(device, Device) and (not isinstance(device, str) or device.lower() not in DEVICE_NAMES):
        raise ValueError(f"device must be one of {DEVICE_NAMES}, got {device!r}")
    if workers is not None:
        _int("workers", workers, 1)
    if batch_cells is not None:
        _int("batch_cells", batch_cells, 1)
    if progress is not None and not callable(progress):
        raise TypeError("progress must be callable")
    _check_out_folder(out)
    path = open_sweep_folder(sweep, out, create=False)   # mismatch errors before anything is made

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
    try:
        path = open_sweep_folder(sweep, out, create=True)
        done, parts, bad = scan_chunks(sweep, path, clean=True)
        chunks = plan_chunks(sweep, batch_cells, done)
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
        in_process = isinstance(executor, InProcessExecutor)
        # bounded submission for the in-process executor (it runs at submit time, so each chunk is
        # written before the next starts); everything at once otherwise, largest N first
        todo = sorted(chunks, key=lambda c: -c.n_cells * c.size)
        limit = 1 if in_process else len(todo)
        pending = {}
        computed = []
        folder = os.path.join(path, CHUNK_DIR)
        while todo or pending:
            while todo and len(pending) < limit:
                c = todo.pop(0)
                pending[executor.submit(run_chunk, params, c.n_cells, c.start, c.stop, device_name)] = c
            finished, _ = cf.wait(list(pending), return_when=cf.FIRST_COMPLETED)
            for fut in finished:
                c = pending.pop(fut)
                exc = fut.exception()
                if exc is not None:
                    for other in pending:
                        other.cancel()
                    raise RuntimeError(f"chunk {c.id} ({c.size} minimisations of N = {c.n_cells}) failed: "
                                       f"{type(exc).__name__}: {exc}; finished chunks are kept in {folder}, "
                                       "rerun to resume") from exc
                rec = fut.result()
                write_columns(os.path.join(folder, c.id + ".csv"), rec, RECORD_COLUMNS)
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
            executor.shutdown(wait=False, cancel_futures=True)
        raise
    finally:
        if owned:
            executor.shutdown(wait=True)
    return SweepResult(sweep=sweep, out=path, records=_sorted_records(_merge(parts)), computed=computed,
                       reused=len(parts) - len(computed), recomputed_bad=[b for b, _ in bad],
                       elapsed=time.perf_counter() - t0, executor=type(executor).__name__)


def load_sweep(out):
    """``(sweep, records)`` of a sweep folder (finished chunks only)."""
    path = os.path.abspath(os.fspath(out))
    manifest_path = os.path.join(path, MANIFEST)
    if not os.path.exists(manifest_path):
        raise ValueError(f"{out!r} holds no {MANIFEST}: not a rigidity sweep folder")
    with open(manifest_path) as fh:
        manifest = json.load(fh)
    sweep = RigiditySweep.from_parameters(manifest["parameters"])
    _, parts, _ = scan_chunks(sweep, path)
    return sweep, _sorted_records(_merge(parts))


# ---------------------------------------------------------------------------------------- tables and plots
def summarize_records(records: dict, zero_tol=None, sigma=None, resamples: int = 400):
    """``(fractions, p0star, density)`` from per-replica records (see analysis.rigidity.summarize)."""
    from .analysis import rigidity
    tol = rigidity.ZERO_ENERGY_TOL if zero_tol is None else zero_tol
    status = rigidity.classify(records["energy_per_cell"], records["reason"], tol)
    return rigidity.summarize(records["n_cells"], records["p0"], status, sigma=sigma, resamples=resamples)


def write_tables(out, records: dict, zero_tol=None, plots=True, sigma=None) -> dict:
    """Write ``replicas.csv``, ``fraction.csv`` (F(p0,N)), ``p0star.csv`` (p0*(N) beside the pentagon
    bound), ``p0star_density.csv`` and, with matplotlib, ``fraction.png``, ``p0star_distribution.png``
    (Fig. 2 style, F in the inset), ``p0star_vs_N.png`` and ``critical_perimeter.png`` (Fig. 4).

    Returns a dict with the tables (``fractions``, ``p0star``, ``density``), the ``files`` written
    and ``plot_note`` (why plots were skipped, or None).
    """
    from .analysis import rigidity
    path = os.path.abspath(os.fspath(out))
    os.makedirs(path, exist_ok=True)
    records = _sorted_records(records)
    tol = rigidity.ZERO_ENERGY_TOL if zero_tol is None else zero_tol
    status = rigidity.classify(records["energy_per_cell"], records["reason"], tol)
    frac, p0star, density = rigidity.summarize(records["n_cells"], records["p0"], status, sigma=sigma)
    files = []
    rec = dict(records)
    write_columns(os.path.join(path, "replicas.csv"), {**rec, "status": status}, RECORD_COLUMNS + ("status",))
    files.append(os.path.join(path, "replicas.csv"))
    for name, table in (("fraction.csv", frac), ("p0star.csv", p0star), ("p0star_density.csv", density)):
        write_columns(os.path.join(path, name), table)
        files.append(os.path.join(path, name))
    note = None
    if plots:
        try:
            import matplotlib
            matplotlib.use("Agg", force=False)
            import matplotlib.pyplot as plt
        except ImportError:
            note = "matplotlib is not installed: plots skipped (pip install 'spherevm[plot]')"
        else:
            for name, fig in (("fraction.png", lambda: rigidity.plot_fraction(frac)),
                              ("p0star_distribution.png", lambda: rigidity.plot_transition(frac, p0star, density)),
                              ("p0star_vs_N.png", lambda: rigidity.plot_p0_star(p0star)),
                              ("critical_perimeter.png", lambda: rigidity.plot_critical_perimeter(p0star))):
                f = fig()
                f.tight_layout()
                f.savefig(os.path.join(path, name), dpi=150)
                plt.close(f)
                files.append(os.path.join(path, name))
    return {"fractions": frac, "p0star": p0star, "density": density, "status": status, "files": files,
            "plot_note": note}


def format_p0star_table(p0star) -> str:
    """p0*(N) beside the pentagon bound, as plain text."""
    head = ("N", "p0*", "+-", "spread", "p0(F=1/2)", "pentagon", "p0*-pent", "replicas", "unconv", "note")
    rows = []
    for i in range(len(p0star["n_cells"])):
        p, pent = p0star["p0_star"][i], p0star["pentagon_perimeter"][i]
        rows.append((str(int(p0star["n_cells"][i])), f"{p:.4f}", f"{p0star['p0_star_err'][i]:.4f}",
                     f"{p0star['std'][i]:.4f}", f"{p0star['p0_half'][i]:.4f}", f"{pent:.4f}", f"{p - pent:+.4f}",
                     str(int(p0star["n_replicas"][i])), str(int(p0star["n_unconverged"][i])),
                     "" if p0star["bracketed"][i] else "transition not inside the p0 grid"))
    widths = [max(len(h), *(len(r[j]) for r in rows)) if rows else len(h) for j, h in enumerate(head)]
    lines = ["  ".join(h.rjust(w) for h, w in zip(head, widths)).rstrip()]
    lines += ["  ".join(v.rjust(w) if j < len(head) - 1 else v for j, (v, w) in enumerate(zip(r, widths))).rstrip()
              for r in rows]
    return "\n".join(lines)


# ---------------------------------------------------------------------------------------- command line
def parse_p0_grid(tokens) -> list:
    """``["3.60:3.90:0.01"]`` -> [3.60, 3.61, ..., 3.90] (end included); plain numbers pass through."""
    values = []
    for tok in tokens:
        tok = str(tok).strip()
        if ":" in tok:
            parts = tok.split(":")
            if len(parts) != 3:
                raise ValueError(f"p0 range must be START:STOP:STEP, got {tok!r}")
            try:
                a, b, h = (float(p) for p in parts)
            except ValueError:
                raise ValueError(f"p0 range must be START:STOP:STEP of numbers, got {tok!r}") from None
            if not all(math.isfinite(v) for v in (a, b, h)) or h <= 0 or b < a:
                raise ValueError(f"p0 range {tok!r} needs STEP > 0 and STOP >= START")
            n = int(math.floor((b - a) / h + 1e-9)) + 1
            if n > 100000:
                raise ValueError(f"p0 range {tok!r} has {n} values; that is too many")
            values.extend(round(a + i * h, 10) for i in range(n))
        else:
            try:
                values.append(float(tok))
            except ValueError:
                raise ValueError(f"p0 must be numbers or START:STOP:STEP ranges, got {tok!r}") from None
    return values


class TextProgress:
    """A plain-text progress bar on a stream (standard error): redrawn in place on a terminal,
    otherwise one line per finished chunk at most every 5 seconds (and the last)."""

    def __init__(self, stream=None, width=28, label="rigidity"):
        from .progress import StatusLine
        self.status = StatusLine(stream)
        self.tty = self.status.tty
        self.width, self.label = width, label
        self.last = -math.inf

    def __call__(self, p: SweepProgress):
        now = time.monotonic()
        final = p.chunks_done == p.chunks_total
        if not self.tty and not final and p.chunks_done and now - self.last < 5.0:
            return
        self.last = now
        frac = p.cells_done / p.cells_total if p.cells_total else 1.0
        fill = int(round(self.width * frac))
        eta = "" if not math.isfinite(p.eta) or final else f"  eta {p.eta:5.0f} s"
        reused = f" ({p.units_reused} on disk)" if p.units_reused else ""
        line = (f"{self.label}: [{'#' * fill}{'.' * (self.width - fill)}] {100 * frac:5.1f}%  "
                f"chunks {p.chunks_done}/{p.chunks_total}  minimisations {p.units_done}/{p.units_total}{reused}  "
                f"{p.elapsed:6.1f} s{eta}")
        self.status.show(line)

    def close(self):
        self.status.close()


DEFAULT_CELLS = (16, 32)
DEFAULT_P0 = "3.5:4.0:0.025"
DEFAULT_REPLICAS = 12


def add_cli(subparsers):
    """Register ``spherevm rigidity`` on an argparse subparsers object; returns its parser.

    In spherevm/cli.py: ``from .sweeps import add_cli as add_rigidity`` then ``add_rigidity(sub)``
    inside ``build_parser`` (and add ``rigidity`` to ``COMMANDS_METAVAR``).
    """
    from .cli import _integer as _cli_int, _real as _cli_real
    r = subparsers.add_parser(
        "rigidity", help="sweep p0 and N: F(p0, N), p0* distributions and p0*(N) (Fig. 2 and 4)",
        description="Minimise REPLICAS random tilings at every (N, p0) with FIRE and T1s, classify every "
                    "inherent state as zero energy or rigid, and write F(p0, N), the distributions of p0* "
                    "and p0*(N) beside the regular-pentagon bound (CSV, and PNG with matplotlib) to --out. "
                    "Chunks are saved as they finish: rerun the same command to resume. The default sweep "
                    "takes under a minute on a 2-core laptop. See docs/rigidity.md.")
    g = r.add_argument_group("sweep")
    g.add_argument("--cells", "-N", type=_cli_int(4), nargs="+", default=list(DEFAULT_CELLS), metavar="N",
                   help="system sizes, cells per tiling (default: %(default)s)")
    g.add_argument("--p0", nargs="+", default=[DEFAULT_P0], metavar="P0",
                   help="p0 values and/or START:STOP:STEP ranges, end included (default: %(default)s)")
    g.add_argument("--replicas", "-R", type=_cli_int(1), default=DEFAULT_REPLICAS,
                   help="random tilings per (N, p0) (default: %(default)s)")
    g.add_argument("--kr", type=_cli_real(0.0), default=0.0, help="area stiffness kA <A>/kP (default: %(default)s)")
    g.add_argument("--seed", type=_cli_int(0), default=0, help="random seed (default: %(default)s)")
    g.add_argument("--shared-tilings", action="store_true",
                   help="use the same tilings at every p0 (default: independent tilings per p0)")
    g = r.add_argument_group("minimiser")
    g.add_argument("--dt", type=_cli_real(0.0, strict=True), default=RigiditySweep.dt,
                   help="FIRE time step (default: %(default)s)")
    g.add_argument("--force-tol", type=_cli_real(0.0), default=RigiditySweep.force_tol,
                   help="stop a replica when its largest vertex force is below this (default: %(default)s)")
    g.add_argument("--energy-tol", type=_cli_real(0.0), default=RigiditySweep.energy_tol,
                   help="... or its energy per cell below this (default: %(default)s)")
    g.add_argument("--max-steps", type=_cli_int(1), default=RigiditySweep.max_steps,
                   help="step limit; replicas reaching it are reported as not converged (default: %(default)s)")
    g.add_argument("--t1", type=_cli_real(0.0, strict=True), default=RigiditySweep.t1_threshold, metavar="THRESHOLD",
                   help="T1 edge-length threshold in sqrt(<A>), new edges 3 x as long (default: %(default)s)")
    g.add_argument("--t1-reference", action="store_true",
                   help="the paper code's T1 rule instead: threshold 0.1, new edge twice the old length "
                        "(more floppy states near the transition: p0* lower by ~0.02 at N = 32)")
    g.add_argument("--max-flip-backs", type=_cli_int(1), default=RigiditySweep.t1_max_flip_backs,
                   help="stop a replica as 't1_oscillation' after this many re-joins of one cell pair "
                        "(default: %(default)s)")
    g = r.add_argument_group("analysis")
    g.add_argument("--zero-tol", type=_cli_real(0.0, strict=True), default=None,
                   help="energy per cell below which a state counts as zero energy (default: 1e-12)")
    g.add_argument("--sigma", type=_cli_real(0.0, strict=True), default=None,
                   help="Gaussian width for dF/dp0 (default: half the measured width of the transition, "
                        "at least half the p0 spacing)")
    g = r.add_argument_group("running")
    g.add_argument("--out", "-o", default="sweep", metavar="FOLDER",
                   help="output folder; an existing sweep folder is resumed (default: %(default)s)")
    g.add_argument("--device", choices=("cpu", "gpu", "auto"), default="auto",
                   help="auto takes the GPU when CuPy sees one (default: %(default)s)")
    g.add_argument("--workers", "-j", type=_cli_int(1), default=None,
                   help="processes on the CPU (default: all cores)")
    g.add_argument("--batch-cells", type=_cli_int(1), default=None,
                   help=f"cells per batched chunk (default: {CPU_BATCH_CELLS} on the CPU, {GPU_BATCH_CELLS} on a GPU)")
    g.add_argument("--scheduler", default=None, metavar="ADDRESS",
                   help="run the chunks on a Dask cluster (needs spherevm[cluster]): a scheduler address "
                        "such as tcp://host:8786, or 'local' for a LocalCluster on this machine")
    g.add_argument("--no-plots", action="store_true", help="write the CSV tables only")
    g.add_argument("--quiet", "-q", action="store_true", help="no progress bar or notes on standard error")
    r.set_defaults(func=cmd_rigidity)
    return r


def _dask_client(address):
    try:
        from distributed import Client, LocalCluster
    except ImportError:
        raise ValueError("--scheduler needs Dask: pip install 'spherevm[cluster]' "
                         "(dask[distributed])") from None
    if address == "local":
        return Client(LocalCluster(threads_per_worker=1, processes=True))
    return Client(address)


def sweep_from_args(args) -> RigiditySweep:
    """The RigiditySweep that ``spherevm rigidity`` arguments describe (ValueError on bad input)."""
    t1 = {"t1_threshold": args.t1, "t1_new_length": 3.0 * args.t1}
    if args.t1_reference:
        t1 = RigiditySweep.reference_t1()
    return RigiditySweep(cells=args.cells, p0=parse_p0_grid(args.p0), replicas=args.replicas, kr=args.kr,
                         seed=args.seed, shared_tilings=args.shared_tilings, dt=args.dt, force_tol=args.force_tol,
                         energy_tol=args.energy_tol, max_steps=args.max_steps, t1_max_flip_backs=args.max_flip_backs,
                         **t1)


def cmd_rigidity(args) -> int:
    """The handler of ``spherevm rigidity``."""
    err = sys.stderr
    sweep = sweep_from_args(args)
    if args.zero_tol is not None and args.zero_tol <= 0:
        raise ValueError("--zero-tol must be > 0")
    _check_out_folder(args.out)
    open_sweep_folder(sweep, args.out, create=False)        # a mismatch fails before any work
    client = _dask_client(args.scheduler) if args.scheduler else None
    try:
        if not args.quiet:
            where = f"Dask cluster {args.scheduler}" if client else f"device {args.device}"
            err.write(f"spherevm: rigidity sweep of N = {list(sweep.cells)}, {len(sweep.p0)} p0 values "
                      f"({sweep.p0[0]:g}..{sweep.p0[-1]:g}), {sweep.replicas} replicas, kr = {sweep.kr:g}: "
                      f"{sweep.total_units} minimisations on {where}, writing {args.out}\n")
            err.flush()
        bar = TextProgress(err) if not args.quiet else None
        try:
            result = run_sweep(sweep, args.out, executor=client, device=args.device, workers=args.workers,
                               batch_cells=args.batch_cells, progress=bar)
        finally:
            if bar is not None:
                bar.close()
    finally:
        if client is not None:
            client.close()
    tables = write_tables(args.out, result.records, zero_tol=args.zero_tol, plots=not args.no_plots,
                          sigma=args.sigma)
    print(format_p0star_table(tables["p0star"]))
    if not args.quiet:
        frac = tables["fractions"]
        n_max, n_osc = int(frac["n_max_steps"].sum()), int(frac["n_t1_oscillation"].sum())
        err.write(f"spherevm: {len(result.computed)} chunk(s) computed, {result.reused} found on disk, "
                  f"{result.elapsed:.1f} s; not converged: {n_max} max_steps, {n_osc} t1_oscillation "
                  f"(left out of F, counted in fraction.csv)\n")
        if not all(tables["p0star"]["bracketed"]):
            err.write("spherevm: note: for some N, F does not go from 0 to 1 inside the p0 grid; widen --p0\n")
        if tables["plot_note"]:
            err.write(f"spherevm: note: {tables['plot_note']}\n")
        err.write(f"spherevm: wrote {', '.join(os.path.basename(f) for f in tables['files'])} to {args.out}\n")
    return 0
