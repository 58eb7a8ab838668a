"""What a rigidity sweep computes: its parameters, the seed of every tiling, and its chunks; and
:class:`Sweep`, what every sweep kind tells the store and :func:`~spherevm.sweeps.execution.run_sweep`."""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass, fields

import numpy as np

from ..init_plane import MIN_PLANAR_CELLS
from ..plugins.updaters.t1 import PRESETS
from ..validation import SHAPE_INDEX_MAX, ParameterError, integer, positive, real
from .store import FORMAT, RIGIDITY_COLUMNS


class Sweep:
    """What a sweep kind provides to the store and to :func:`~spherevm.sweeps.execution.run_sweep`.

    A sweep is a grid of units, ``units_per_size`` per size N in ``cells`` (unit
    ``u = point * replicas + replica``); a chunk (:class:`Chunk`) is a run of units of one N computed
    by one call of the kind's ``chunk_function(parameters, n_cells, start, stop, device)``, which
    returns its records (a dict of lists, ``columns``) and may add entries that
    :meth:`write_extras` writes beside the chunk file."""
    KIND = ""               # the word in messages: "rigidity", "dynamics"
    FORMAT = ""             # the manifest's "format"
    UNIT = "point"          # what the unit's first index counts, for the manifest's layout note
    columns = None          # the records' store.Columns
    chunk_function = None   # None: spherevm.sweeps.execution.run_chunk (the rigidity sweep's)
    prefetch_tilings = False   # run_sweep may build the chunks' tilings ahead (TilingPrefetch)
    keeps_states = False    # run_sweep(save_states=True) is allowed

    def plan(self, batch_cells: int, done=None) -> list:
        """The chunks that cover every unit not in ``done`` (N -> bool array over units)."""
        raise NotImplementedError

    def chunk_units(self, records: dict) -> np.ndarray:
        """The units a chunk file's records cover (ValueError when they do not belong to this sweep)."""
        raise NotImplementedError

    def write_extras(self, path: str, chunk, records: dict):
        """Pop and write what a chunk returned besides its records (before the chunk file)."""

    @property
    def total_units(self) -> int:
        return len(self.cells) * self.units_per_size


@dataclass(frozen=True)
class RigiditySweep(Sweep):
    """What to compute: every (N in ``cells``, p0 in ``p0``, replica < ``replicas``) minimised.

    The energy is ``E = sum_c kr/<A> (A_c - <A>)^2 + (P_c - p0 sqrt(<A>))^2`` per tiling (kP = 1), so
    that ``energy_per_cell`` is in units of kP <A> (<A> = 1 at the default radius sqrt(N/4 pi)).
    Defaults from docs/rigidity.md.

    Parameters
    ----------
    cells : tuple of int
        Cells per tiling, each >= 4, no duplicates (sorted for you).
    p0 : tuple of float
        The target shape indices, non-empty, in (0, 100] (``SHAPE_INDEX_MAX``) and strictly increasing.
    replicas : int
        Random tilings per (N, p0), >= 1.
    kr : float
        Area stiffness kA <A> / kP (0: the paper's Fig. 2).
    seed : int
        The tiling of (N, p0, replica) is drawn from ``seed`` and those three numbers only.
    shared_tilings : bool
        The same tilings at every p0 (then F(p0) per tiling is a step).
    dt, force_tol, energy_tol, max_steps, check_every
        FIRE's time step; a replica stops when its largest vertex force is below ``force_tol``, its
        energy per cell below ``energy_tol`` (a zero-energy state), or after ``max_steps``.
    t1_threshold, t1_new_length, t1_max_flip_backs, t1_length_factor
        T1 exchanges of edges shorter than ``t1_threshold`` (new edges ``t1_new_length``, or
        ``t1_length_factor`` times the old one), units sqrt(<A>); a replica stops when one pair
        re-joins ``t1_max_flip_backs`` times. The paper code's rule is ``t1_threshold=0.1,
        t1_length_factor=2`` (:meth:`reference_t1`).
    surface : str
        "sphere": random convex-hull tilings of radius sqrt(N / 4 pi); "plane": periodic Voronoi
        tilings in the square box of side sqrt(N) (N >= 8); an implicit surface's spec
        (``"torus:R=3,r=1"``): its tilings, shape scaled (:func:`spherevm.init.tilings_on`); <A> = 1 on all.
    forces : tuple
        Extra forces, ``(name, {parameter: value})`` of registered plugins."""
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
    surface: str = "sphere"
    forces: tuple = ()

    KIND, FORMAT, UNIT, columns = "rigidity", FORMAT, "p0_index", RIGIDITY_COLUMNS
    prefetch_tilings = keeps_states = True

    def __post_init__(self):
        set_ = object.__setattr__
        cells = self.cells
        if isinstance(cells, (int, np.integer)):
            cells = (cells,)
        try:
            cells = [integer("cells", c, 4) for c in cells]
        except TypeError:
            raise ValueError(f"cells must be a list of integers >= 4, got {self.cells!r}") from None
        if not cells:
            raise ValueError("cells must list at least one system size N >= 4, got an empty list")
        if len(set(cells)) != len(cells):
            raise ValueError(f"cells must not repeat a size, got {list(self.cells)}")
        set_(self, "cells", tuple(sorted(cells)))
        from ..init import check_surface_spec
        check_surface_spec(self.surface)
        if self.surface == "plane" and cells and min(cells) < MIN_PLANAR_CELLS:
            raise ValueError(f"cells must be >= {MIN_PLANAR_CELLS} on the periodic plane (a simple random tiling of "
                             f"the torus needs them), got {min(cells)}")
        p0 = self.p0
        if isinstance(p0, (int, float, np.floating, np.integer)):
            p0 = (p0,)
        try:
            p0 = np.asarray([float(p) for p in p0], dtype=np.float64)
        except (TypeError, ValueError):
            raise ValueError(f"p0 must be a list of numbers, got {self.p0!r}") from None
        if len(p0) == 0:
            raise ValueError("p0 grid is empty: give at least one value (two or more to locate p0*)")
        if not np.all(np.isfinite(p0)) or np.any(p0 <= 0) or np.any(p0 > SHAPE_INDEX_MAX):
            raise ParameterError("p0", p0.tolist(), f"finite numbers in (0, {SHAPE_INDEX_MAX:g}]")
        if np.any(np.diff(p0) <= 0):
            i = int(np.flatnonzero(np.diff(p0) <= 0)[0])
            raise ValueError(f"p0 grid must be strictly increasing: p0[{i}] = {p0[i]:g} is followed by "
                             f"p0[{i + 1}] = {p0[i + 1]:g}")
        if len(set(_p0_key(p) for p in p0)) != len(p0):
            raise ValueError("p0 values must differ by more than 1e-6")
        set_(self, "p0", tuple(float(p) for p in p0))
        set_(self, "replicas", integer("replicas", self.replicas, 1))
        set_(self, "kr", real("kr", self.kr))
        set_(self, "seed", integer("seed", self.seed))
        set_(self, "shared_tilings", bool(self.shared_tilings))
        set_(self, "dt", positive("dt", self.dt))
        set_(self, "force_tol", real("force_tol", self.force_tol))
        set_(self, "energy_tol", real("energy_tol", self.energy_tol))
        set_(self, "max_steps", integer("max_steps", self.max_steps, 1))
        set_(self, "check_every", integer("check_every", self.check_every, 1))
        set_(self, "t1_threshold", positive("t1_threshold", self.t1_threshold))
        set_(self, "t1_new_length", positive("t1_new_length", self.t1_new_length))
        if self.t1_length_factor is None and self.t1_new_length <= self.t1_threshold:
            raise ValueError(f"t1_new_length must be > t1_threshold = {self.t1_threshold}, got {self.t1_new_length}")
        set_(self, "t1_max_flip_backs", integer("t1_max_flip_backs", self.t1_max_flip_backs, 1))
        if self.t1_length_factor is not None:
            set_(self, "t1_length_factor", positive("t1_length_factor", self.t1_length_factor))
        set_(self, "forces", _check_forces(self.forces))

    @staticmethod
    def reference_t1() -> dict:
        """The T1 rules of the paper's own code (``T1(preset="reference")``), as sweep parameters."""
        preset = PRESETS["reference"]
        return {"t1_threshold": preset["threshold"], "t1_length_factor": preset["length_factor"]}

    def parameters(self) -> dict:
        """JSON-ready parameters (what the manifest stores and a resumed sweep must match)."""
        out = asdict(self)
        out["cells"], out["p0"] = list(self.cells), list(self.p0)
        if self.forces:      # extra forces: [[name, {k: v}], ...]; absent otherwise (old manifests match)
            out["forces"] = [[name, dict(params)] for name, params in self.forces]
        else:
            del out["forces"]
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

    def unit(self, u: int):
        """``(p0_index, replica)`` of unit ``u`` (p0-major order)."""
        return divmod(int(u), self.replicas)

    def plan(self, batch_cells: int, done=None) -> list:
        """:func:`plan_chunks`."""
        return plan_chunks(self, batch_cells, done)

    def chunk_units(self, records: dict) -> np.ndarray:
        k, r = np.asarray(records["p0_index"]), np.asarray(records["replica"])
        if np.any(k < 0) or np.any(k >= len(self.p0)) or np.any(r < 0) or np.any(r >= self.replicas):
            raise ValueError("unit outside this sweep")
        if not np.allclose(np.asarray(self.p0)[k], records["p0"], rtol=0, atol=1e-12):
            raise ValueError("p0 values do not match the grid")
        return k * self.replicas + r


def _check_forces(forces) -> tuple:
    """Extra forces as ``((name, ((key, value), ...)), ...)``, each built once by its plugin's own
    constructor to check it (ValueError naming the plugin and parameter)."""
    from ..plugins import build_force
    out = []
    for item in forces or ():
        try:
            name, params = item
            params = dict(params)
        except (TypeError, ValueError):
            raise ValueError(f"forces must be (name, {{parameter: value}}) pairs, got {item!r}") from None
        build_force(str(name), params)
        out.append((str(name), tuple(sorted(params.items()))))
    return tuple(out)


def _p0_key(p0: float) -> int:
    return int(round(float(p0) * 1e6))


def tiling_seed(seed: int, n_cells: int, p0: float, replica: int, shared: bool = False) -> int:
    """The seed of the random tiling of (N, p0, replica): a function of these numbers only, so the
    result of a replica does not depend on the chunking, the executor or the rest of the grid.
    With ``shared=True`` it does not depend on p0 either."""
    key = [int(seed), int(n_cells), int(replica)] if shared else [int(seed), int(n_cells), _p0_key(p0), int(replica)]
    a, b = np.random.SeedSequence(key).generate_state(2, dtype=np.uint32)
    return (int(a) << 31) ^ int(b)   # < 2^63


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


def plan_chunks(sweep: Sweep, batch_cells: int, done=None) -> list:
    """Chunks covering every unit not in ``done`` (a dict N -> bool array over units).

    Each maximal run of missing units of one N is cut into chunks of ``max(1, batch_cells // N)``
    units, so a fresh sweep has ``ceil(P R N / batch_cells)`` chunks per N and a resumed one
    recomputes exactly the missing runs.
    """
    batch_cells = integer("batch_cells", batch_cells, 1)
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
