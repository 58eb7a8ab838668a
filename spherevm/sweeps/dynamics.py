"""The glassy-dynamics protocol (:func:`spherevm.protocols.glassy_dynamics`) as a sweep over the
size N, the temperature T, the target shape index p0 and the bending modulus B, on the store,
executors and resume of the rigidity sweep (:func:`spherevm.sweeps.run_sweep`).

A point is one (N, T, p0, B); its ``replicas`` tissues are cut into fixed chunks of
``chunk_replicas`` tissues, each one batched ``glassy_dynamics`` call (the tissues of a chunk are
replicas of one State). A tissue's random tiling is drawn from ``(seed, N, T, p0, B, replica)`` and
its chunk's Brownian noise from ``(seed, N, T, p0, B, first replica of the chunk)``: the noise of a
vertex is keyed by its place in the batch, so the chunk layout is part of the sweep (it is in the
manifest), while the executor, the number of GPUs, the order of the chunks and a resume change
nothing.
"""
from __future__ import annotations

import math
import os
import time
from dataclasses import asdict, dataclass, fields

import numpy as np

from ..validation import SHAPE_INDEX_MAX, integer, positive, real
from .spec import Chunk, Sweep, _check_forces
from .store import CURVE_COLUMNS, CURVE_DIR, DYNAMICS_COLUMNS, write_columns


def _grid(name, values, low, high=math.inf, low_open=False) -> tuple:
    """A non-empty list of distinct finite numbers in the allowed range, as a sorted tuple."""
    if isinstance(values, (int, float, np.integer, np.floating)):
        values = (values,)
    try:
        out = sorted(float(v) for v in values)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a list of numbers, got {values!r}") from None
    if not out:
        raise ValueError(f"{name} must list at least one value, got an empty list")
    bad = [v for v in out if not math.isfinite(v) or v < low or (low_open and v == low) or v > high]
    if bad:
        what = f"{'(' if low_open else '['}{low:g}, {high:g}]"
        raise ValueError(f"{name} values must be finite numbers in {what}, got {bad[0]!r}")
    if len(set(out)) != len(out):
        raise ValueError(f"{name} must not repeat a value, got {list(values)}")
    return tuple(out)


def _bits(x: float) -> int:
    """The exact 64-bit pattern of a float (a seed key that no grid order or rounding changes)."""
    return int(np.float64(x).view(np.uint64))


def run_dynamics_chunk(parameters: dict, n_cells: int, start: int, stop: int, device="cpu", timing=False) -> dict:
    """Run one chunk of a :class:`DynamicsSweep` as one batched ``glassy_dynamics`` call; returns its
    per-tissue records (:data:`DYNAMICS_COLUMNS`) and, under ``"curves"``, the chunk's MSD and Q_s
    averaged over its tissues (:data:`CURVE_COLUMNS`); with ``timing``, under ``"timing"``, when its
    stages ended as :func:`~spherevm.sweeps.execution.run_chunk` gives them (``minimized``: the end of
    the protocol). Plain arguments, for any executor."""
    from ..plugins import build_force
    from ..protocols import glassy_dynamics
    from .tilings import build_tilings

    t0, started = time.perf_counter(), time.time()
    sweep = DynamicsSweep.from_parameters(parameters)
    chunk = Chunk(int(n_cells), int(start), int(stop))
    k, first = divmod(chunk.start, sweep.replicas)
    replicas = list(range(first, first + chunk.size))
    T, p0, B = sweep.point(k)
    tilings, noise = sweep.seeds(chunk.n_cells, k, replicas)
    forces = [build_force(name, dict(params)) for name, params in sweep.forces]
    if B > 0:
        forces.append(build_force("bending", {"B": B}))
    state = build_tilings(sweep.surface, chunk.n_cells, tilings)
    built = time.time()
    res = glassy_dynamics(None, p0, sweep.kr, T, dt=sweep.dt, steps=sweep.steps, seed=noise, device=device,
                          relax_steps=sweep.relax_steps, equilibrate_steps=sweep.equilibrate_steps, b=sweep.b,
                          points_per_decade=sweep.points_per_decade, extra_forces=forces,
                          initial_state=state)
    flips = np.asarray(res.simulation.log("t1_total_flips"))
    elapsed, ran = time.perf_counter() - t0, time.time()
    n, lags = chunk.size, len(res.lag)
    curves = {"n_cells": [chunk.n_cells] * lags, "point": [k] * lags, "tissues": [n] * lags,
              "time": [float(x) for x in res.lag], "msd": [float(x) for x in res.msd],
              "self_overlap": [float(x) for x in res.self_overlap]}
    extra = {"timing": {"pid": os.getpid(), "started": started, "built": built, "minimized": ran,
                        "ended": time.time()}} if timing else {}
    return {**extra, "curves": curves, "n_cells": [chunk.n_cells] * n, "point": [k] * n, "T": [T] * n, "p0": [p0] * n,
            "B": [B] * n, "replica": replicas, "tiling_seed": tilings, "noise_seed": [noise] * n,
            "tau_alpha": [float(x) for x in res.tau_alpha_per_replica],
            "msd_end": [float(x) for x in res.msd_per_replica[-1]],
            "overlap_end": [float(x) for x in res.self_overlap_per_replica[-1]],
            "t1_flips": [int(f) for f in flips], "chunk": [chunk.id] * n,
            "chunk_seconds": [round(elapsed, 4)] * n}



@dataclass(frozen=True)
class DynamicsSweep(Sweep):
    """What to compute: ``replicas`` tissues at every point (N in ``cells``, T, p0, B), each run
    through :func:`spherevm.protocols.glassy_dynamics` (FIRE + T1 relaxation, equilibration, Brownian
    production with T1; MSD, self-overlap Q_s and tau_alpha per tissue).

    Parameters
    ----------
    cells : tuple of int
        Cells per tissue, each >= 4 (>= 8 on the plane), no duplicates (sorted for you).
    T, p0, B : tuple of float
        Temperatures (>= 0), target shape indices (in (0, 100]) and bending moduli (>= 0; B > 0
        adds the ``bending`` force), each non-empty and without duplicates (sorted for you).
    replicas : int
        Tissues per point, >= 1.
    kr : float
        Area stiffness kA <A> / kP.
    seed : int
        Every tiling and every chunk's noise is drawn from ``seed`` and the point's values only.
    chunk_replicas : int, optional
        Tissues per chunk (one batched protocol call); None: all the point's replicas in one chunk.
        Part of the sweep: the noise of a tissue depends on its place in its chunk.
    dt, steps, equilibrate_steps, relax_steps, b, points_per_decade
        As in :func:`~spherevm.protocols.glassy_dynamics` (``equilibrate_steps`` None: ``steps // 10``).
    surface : str
        "sphere", "plane" or an implicit surface's spec, ``"torus:R=3,r=1"`` (:func:`spherevm.init.tilings_on`)
    forces : tuple
        Further forces, ``(name, {parameter: value})`` of registered plugins, at every point."""
    cells: tuple
    T: tuple
    p0: tuple = (3.775,)
    B: tuple = (0.0,)
    replicas: int = 4
    kr: float = 0.0
    seed: int = 0
    chunk_replicas: int = None
    dt: float = 0.05
    steps: int = 5000
    equilibrate_steps: int = None
    relax_steps: int = 5000
    b: float = 0.5
    points_per_decade: int = 10
    surface: str = "sphere"
    forces: tuple = ()

    KIND, FORMAT, columns = "dynamics", "spherevm-dynamics-sweep", DYNAMICS_COLUMNS
    chunk_function = staticmethod(run_dynamics_chunk)

    def __post_init__(self):
        set_ = object.__setattr__
        from ..init import check_surface_spec
        check_surface_spec(self.surface)
        least = 8 if self.surface == "plane" else 4
        cells = self.cells if not isinstance(self.cells, (int, np.integer)) else (self.cells,)
        try:
            cells = [integer("cells", c, least) for c in cells]
        except TypeError:
            raise ValueError(f"cells must be a list of integers >= {least}, got {self.cells!r}") from None
        if not cells or len(set(cells)) != len(cells):
            raise ValueError(f"cells must list distinct sizes N >= {least}, got {self.cells!r}")
        set_(self, "cells", tuple(sorted(cells)))
        set_(self, "T", _grid("T", self.T, 0.0))
        set_(self, "p0", _grid("p0", self.p0, 0.0, SHAPE_INDEX_MAX, low_open=True))
        set_(self, "B", _grid("B", self.B, 0.0))
        set_(self, "replicas", integer("replicas", self.replicas, 1))
        per = self.replicas if self.chunk_replicas is None else integer("chunk_replicas", self.chunk_replicas, 1)
        set_(self, "chunk_replicas", min(per, self.replicas))
        set_(self, "kr", real("kr", self.kr))
        set_(self, "seed", integer("seed", self.seed))
        set_(self, "dt", positive("dt", self.dt))
        set_(self, "steps", integer("steps", self.steps, 1))
        eq = self.steps // 10 if self.equilibrate_steps is None else self.equilibrate_steps
        set_(self, "equilibrate_steps", integer("equilibrate_steps", eq, 0))
        set_(self, "relax_steps", integer("relax_steps", self.relax_steps, 0))
        set_(self, "b", positive("b", self.b))
        set_(self, "points_per_decade", integer("points_per_decade", self.points_per_decade, 1))
        set_(self, "forces", _check_forces(self.forces))

    def parameters(self) -> dict:
        """JSON-ready parameters (what the manifest stores and a resumed sweep must match)."""
        out = asdict(self)
        for key in ("cells", "T", "p0", "B"):
            out[key] = list(getattr(self, key))
        out["forces"] = [[name, dict(params)] for name, params in self.forces]
        return out

    @classmethod
    def from_parameters(cls, params: dict) -> "DynamicsSweep":
        unknown = set(params) - {f.name for f in fields(cls)}
        if unknown:
            raise ValueError(f"unknown sweep parameters {sorted(unknown)}")
        return cls(**params)

    @property
    def points_per_size(self) -> int:
        return len(self.T) * len(self.p0) * len(self.B)

    @property
    def units_per_size(self) -> int:
        """(point, replica) pairs per N."""
        return self.points_per_size * self.replicas

    def point(self, k: int):
        """``(T, p0, B)`` of point ``k`` of a size (T-major, then p0, then B)."""
        t, rest = divmod(int(k), len(self.p0) * len(self.B))
        p, b = divmod(rest, len(self.B))
        return self.T[t], self.p0[p], self.B[b]

    def seeds(self, n_cells: int, k: int, replicas):
        """The tiling seeds of ``replicas`` of point ``k`` of size ``n_cells`` and the noise seed of
        a chunk whose first tissue is ``replicas[0]``: functions of the seed and the point's values."""
        from numpy.random import SeedSequence
        key = [self.seed, int(n_cells), *(_bits(v) for v in self.point(k))]
        tilings = []
        for r in replicas:
            a, b = SeedSequence(key + [int(r)]).generate_state(2, dtype=np.uint32)
            tilings.append((int(a) << 31) ^ int(b))
        noise = int(SeedSequence(key + [int(replicas[0]), 1]).generate_state(1, dtype=np.uint32)[0])
        return tilings, noise

    def plan(self, batch_cells=None, done=None) -> list:
        """The fixed chunks (``chunk_replicas`` tissues of one point) not all of whose units are in
        ``done``; ``batch_cells`` is not used (the layout is part of the sweep)."""
        out = []
        for n in self.cells:
            for k in range(self.points_per_size):
                for r in range(0, self.replicas, self.chunk_replicas):
                    a, b = k * self.replicas + r, k * self.replicas + min(r + self.chunk_replicas, self.replicas)
                    if done is None or n not in done or not done[n][a:b].all():
                        out.append(Chunk(n, a, b))
        return out

    def chunk_units(self, records: dict) -> np.ndarray:
        k, r = np.asarray(records["point"]), np.asarray(records["replica"])
        if np.any(k < 0) or np.any(k >= self.points_per_size) or np.any(r < 0) or np.any(r >= self.replicas):
            raise ValueError("unit outside this sweep")
        u = k * self.replicas + r
        if len(set(k.tolist())) != 1 or u[0] % self.replicas % self.chunk_replicas or \
                not np.array_equal(u, np.arange(u[0], u[0] + min(self.chunk_replicas, self.replicas - r[0]))):
            raise ValueError("not one chunk of this sweep's layout")
        if tuple(records[c][0] for c in ("T", "p0", "B")) != self.point(k[0]):
            raise ValueError("T, p0 or B do not match the grid")
        return u

    def write_extras(self, path: str, chunk, records: dict):
        """The chunk's averaged MSD and Q_s curves, ``<out>/curves/<chunk id>.csv``."""
        folder = os.path.join(path, CURVE_DIR)
        os.makedirs(folder, exist_ok=True)
        write_columns(os.path.join(folder, chunk.id + ".csv"), records.pop("curves"), CURVE_COLUMNS)
