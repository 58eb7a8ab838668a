"""The spherevm GSD schema: chunk names, format version, writing a frame and reading States back.

This module is to :class:`spherevm.plugins.writers.GSD` what ``gsd.hoomd`` is to ``gsd.fl``: it
knows what a frame holds; the writer only decides when to write and what to log. It sits at the
state layer (it imports state, topology, device, constraints), so reading a file needs no plugin.

One frame holds (see ``docs/file-format.md`` for every chunk):

* the HOOMD part, read by OVITO, HOOMD and ``gsd.hoomd``: vertices as particles (single type
  ``V``, float32 positions), edges as bonds (single type ``E``), a cube box centred on the origin,
  global values under ``log/<name>``, per-vertex values under ``log/particles/<name>`` and
  per-edge values under ``log/bonds/<name>``;
* the spherevm part, chunks named ``spherevm/...`` that OVITO and ``gsd.hoomd`` ignore: float64
  positions, the cell and vertex tables, the replica layout, the radii and the constraint, enough
  for :func:`read_state` to rebuild the State bit for bit, plus exact per-cell values.

Per-cell values cannot be particle or bond properties (their count is neither), and OVITO turns any
other ``log/`` array into one global attribute holding a tuple, which is useless for viewing and
heavy for large ensembles. So the exact per-cell arrays go to ``spherevm/cell_*`` and OVITO gets
each vertex's mean over its three cells as ``log/particles/cell_*``.

As in the HOOMD schema, a chunk missing from a frame takes its value from frame 0: the writer
leaves out the topology chunks (and gsd.hoomd the HOOMD ones) that equal frame 0's.
"""
from __future__ import annotations

import inspect
import json
import os
import warnings
import zlib

import numpy as np

from . import gsdrecover
from .constraints import Constraint
from .device import CPU, resolve
from .state import State
from .topology import edges as _edges
from .validation import stored, stored_size

FORMAT_VERSION = 1
BOX_FACTOR = 2.2
DIAMETER_FACTOR = 0.15
PREFIX = "spherevm/"
# chunks written every frame (the restore needs them) and chunks left out when equal to frame 0's
ALWAYS = ("format_version", "constraint", "position", "vertex_start", "cell_start")
# and the surface size chunk, named by the constraint's size_key (read first): "radius"
# (n_replicas,) on a sphere, "box" (n_replicas, 2) on a periodic plane
TOPOLOGY = ("cell_vertices", "cell_sides", "vertex_neighbors", "vertex_cells")
CELL_QUANTITIES = ("area", "perimeter", "shape_index", "energy")
CHECKSUM = PREFIX + "checksum"   # CRC32 of the step and of each spherevm chunk of the frame


def _crc(array) -> int:
    return zlib.crc32(np.ascontiguousarray(array))


class FrameIndexError(IndexError, ValueError):
    """A frame index outside the file (both an IndexError and a ValueError)."""


class DamagedFileWarning(UserWarning):
    """A GSD file damaged or cut short: only the complete frames before the damage are read."""


class Saved(dict):
    """One operation's saved fields ``{field: array}`` as read from a checkpoint frame;
    :meth:`where` names a field's chunk, file and frame for the operation's error messages."""

    def __init__(self, fields, prefix):
        super().__init__(fields)
        self.prefix = prefix

    def where(self, field) -> str:
        return f"{self.prefix}{field}'"


# ---------------------------------------------------------------------------------------- constraint
def _constraint_json(constraint) -> np.ndarray:
    """Name, class and parameters: public attributes that are numbers or strings, or number sequences
    the constructor takes by name (a box)."""
    taken = inspect.signature(type(constraint)).parameters
    params = {k: v if isinstance(v, (bool, int, float, str)) else [float(x) for x in v]
              for k, v in vars(constraint).items() if not k.startswith("_") and (
                  isinstance(v, (bool, int, float, str)) or (k in taken and isinstance(v, (tuple, list))))}
    text = json.dumps({"name": getattr(constraint, "name", type(constraint).__name__),
                       "class": type(constraint).__name__, "params": params}, sort_keys=True)
    return np.frombuffer(text.encode("utf-8"), dtype=np.uint8).copy()


def _all_subclasses(cls):
    out = []
    for sub in cls.__subclasses__():
        out.append(sub)
        out.extend(_all_subclasses(sub))
    return out


def _constraint_from_json(raw, path):
    try:
        spec = json.loads(bytes(np.asarray(raw, dtype=np.uint8)).decode("utf-8"))
        name, params = spec["name"], spec.get("params", {})
    except (ValueError, KeyError, TypeError) as exc:
        raise ValueError(f"{path}: chunk spherevm/constraint is not valid JSON ({exc}); the file is damaged") from exc
    matches = [c for c in _all_subclasses(Constraint) if getattr(c, "name", None) == name]
    if not matches:                               # a plugin's surface, loaded through its entry point
        from .constraints.registry import surface_class
        matches = [c for c in (surface_class(name),) if c is not None]
    if not matches:
        raise ValueError(f"{path}: unknown constraint {name!r}; import the module that defines the "
                         f"Constraint subclass with name = {name!r} before reading the file")
    cls = next((c for c in matches if c.__name__ == spec.get("class")), matches[0])
    try:
        return cls(**params)
    except Exception as exc:
        raise ValueError(f"{path}: cannot rebuild constraint {name!r} from parameters {params}: {exc}") from exc


# ---------------------------------------------------------------------------------------- writing
class FrameWriter:
    """Appends spherevm frames to an open ``gsd.hoomd`` trajectory.

    Carries what the schema needs from frame to frame: frame 0's topology chunks (left out of later
    frames that equal them), the box (it only grows), and the per-vertex and per-edge log keys the
    file holds (every frame writes all of them). Opened on a file that already has frames, it takes
    these from the file, so appending continues the same file.
    """

    def __init__(self, traj):
        self.traj = traj
        self._frame0 = {}
        self._box = 0.0
        self._item_keys = {}   # per-vertex / per-edge log keys: (trailing shape, dtype)
        if len(traj) > 0:
            f = traj.file
            for name in TOPOLOGY:
                if f.chunk_exists(frame=0, name=PREFIX + name):
                    self._frame0[name] = f.read_chunk(frame=0, name=PREFIX + name)
            traj[0]  # caches gsd.hoomd's initial frame before chunks of the next frame are written
            self._box = float(traj[len(traj) - 1].configuration.box[0])
            for key in f.find_matching_chunk_names("log/particles/") + f.find_matching_chunk_names("log/bonds/"):
                last = next(i for i in range(len(traj) - 1, -1, -1) if f.chunk_exists(frame=i, name=key))
                arr = f.read_chunk(frame=last, name=key)
                self._item_keys[key[4:]] = (arr.shape[1:], arr.dtype)

    def append(self, state, timestep, log, cell_values, vertex_values, checkpoint=None):
        """Write one frame of ``state`` at ``timestep``.

        log : ``{name: per-replica array}``, written as ``log/<name>``.
        cell_values : ``{quantity: (n_cells,) float64}``, written exactly as ``spherevm/cell_<q>``
            and as the mean over each vertex's cells as ``log/particles/cell_<q>``.
        vertex_values : ``{name: (n_vertices, ...) array}``, written as ``log/particles/<name>``.
        checkpoint : ``{suffix: NumPy array}`` (``Simulation.checkpoint()``), written as
            ``spherevm/<suffix>`` in this frame only (a reader never takes them from frame 0).
        """
        import gsd.hoomd
        dev = state.device
        to_np = dev.to_numpy
        pos = np.ascontiguousarray(to_np(state.positions), dtype=np.float64)
        vn = np.ascontiguousarray(to_np(state.vertex_neighbors), dtype=np.int32)
        vc = np.ascontiguousarray(to_np(state.vertex_cells), dtype=np.int32)
        cv = np.ascontiguousarray(to_np(state.cell_vertices), dtype=np.int32)
        sides = np.ascontiguousarray(to_np(state.cell_sides), dtype=np.int32)
        size = np.ascontiguousarray(state.size_np(), dtype=np.float64)
        n_v = len(pos)
        vrep = state.vertex_replica_np()
        bonds = _edges(vn)
        traj = self.traj

        # ---- HOOMD part
        chord = np.sqrt(((pos[bonds[:, 0]] - pos[bonds[:, 1]]) ** 2).sum(axis=1))
        extent = max(state.constraint.display_extent(size), float(np.abs(pos).max()), float(chord.max(initial=0.0)))
        # fixed unless something outgrows it; float32 as stored, so gsd skips an unchanged box
        self._box = max(self._box, float(np.float32(BOX_FACTOR * extent * (1 + 1e-6))))
        frame = gsd.hoomd.Frame()
        frame.configuration.step = int(timestep)
        frame.configuration.dimensions = 3
        frame.configuration.box = np.array([self._box] * 3 + [0.0] * 3, dtype=np.float32)
        own = state.constraint.hoomd_box(size)     # a periodic surface's real box
        if own is not None:
            frame.configuration.dimensions, box = own
            frame.configuration.box = np.asarray(box, dtype=np.float32)
        frame.particles.N = n_v
        frame.particles.types = ["V"]
        frame.particles.typeid = np.zeros(n_v, dtype=np.uint32)
        frame.particles.position = (pos - particle_origin(state)).astype(np.float32)
        frame.particles.diameter = _diameters(state, chord, bonds)[vrep]
        frame.bonds.N = len(bonds)
        frame.bonds.types = ["E"]
        frame.bonds.typeid = np.zeros(len(bonds), dtype=np.uint32)
        frame.bonds.group = bonds.astype(np.uint32)

        log = dict(log)
        log["particles/replica"] = vrep.astype(np.int32)
        log.update(("particles/" + name, values) for name, values in vertex_values.items())
        try:
            log["bonds/length"] = np.asarray(to_np(state.constraint.edge_lengths(
                state, dev.asarray(bonds[:, 0]), dev.asarray(bonds[:, 1]))), dtype=np.float64)
        except NotImplementedError:
            log["bonds/length"] = chord
        for q, values in cell_values.items():
            log[f"particles/cell_{q}"] = values[vc].mean(axis=1)
        # A per-vertex or per-edge key missing from a frame would take frame 0's array, of the wrong
        # length after a topology change, and OVITO would reject the frame: every key this file has
        # seen (from earlier frames or from the file we append to) is written, NaN if unknown now.
        for key, (trailing, dtype) in self._item_keys.items():
            if key not in log:
                n = n_v if key.startswith("particles/") else len(bonds)
                fill = np.nan if np.issubdtype(dtype, np.floating) else -1
                log[key] = np.full((n,) + trailing, fill, dtype=dtype)
        self._item_keys.update((k, (np.shape(v)[1:], np.asarray(v).dtype)) for k, v in log.items()
                               if k.startswith(("particles/", "bonds/")))
        frame.log = log

        # ---- spherevm part (written before append, which ends the frame)
        chunks = {"format_version": np.array([FORMAT_VERSION], dtype=np.uint32),
                  "constraint": _constraint_json(state.constraint),
                  "position": pos,
                  "vertex_start": np.asarray(state.vertex_start, dtype=np.int64),
                  "cell_start": np.asarray(state.cell_start, dtype=np.int64),
                  state.constraint.size_key: size}
        first = len(traj) == 0
        for name, arr in zip(TOPOLOGY, (cv, sides, vn, vc)):
            if first or name not in self._frame0 or not np.array_equal(self._frame0[name], arr):
                chunks[name] = arr
            if first:
                self._frame0[name] = arr.copy()
        for q, values in cell_values.items():
            chunks["cell_" + q] = values
        for name, arr in (checkpoint or {}).items():
            arr = np.asarray(arr)
            if arr.dtype == bool:
                arr = arr.astype(np.uint8)
            if arr.dtype.kind not in "uif":
                raise TypeError(f"checkpoint field {name!r} has dtype {arr.dtype}; state_to_save must return "
                                "numeric or bool arrays (encode text as uint8)")
            chunks[name] = arr.reshape(1) if arr.ndim == 0 else arr
        chunks = {PREFIX + name: np.ascontiguousarray(arr) for name, arr in chunks.items()}
        sums = [_crc(np.uint64(timestep))] + [_crc(chunks[name]) for name in sorted(chunks)]
        chunks[CHECKSUM] = np.array(sums, dtype=np.uint32)
        for name, arr in chunks.items():
            traj.file.write_chunk(name, arr)
        traj.append(frame)


def particle_origin(state) -> np.ndarray:
    """Where a State's origin sits in the file's particle coordinates, ``(3,)``
    (:meth:`~spherevm.constraints.Constraint.particle_origin`: half the largest box on the periodic
    plane, whose HOOMD box is centred on the origin; zero on a sphere). Particle positions are the
    State's positions minus this."""
    return state.constraint.particle_origin(state.size_np())


def _diameters(state, chord, bonds):
    """Per-replica display diameter: 0.15 sqrt(<A>), or a quarter of the mean edge chord."""
    try:
        d = DIAMETER_FACTOR * np.sqrt(np.asarray(state.mean_cell_area, dtype=np.float64))
    except NotImplementedError:
        rep = state.vertex_replica_np()[bonds[:, 0]]
        n = np.maximum(np.bincount(rep, minlength=state.n_replicas), 1)
        d = 0.25 * np.bincount(rep, weights=chord, minlength=state.n_replicas) / n
    return d.astype(np.float32)


# ---------------------------------------------------------------------------------------- reading
class Reader:
    """A spherevm GSD file open for reading: the State, exact per-cell values and timestep of any
    frame, the file opened once. Use it as a context manager (or call :meth:`close`).

    Raises FileNotFoundError for a missing file and ValueError for a file that is not GSD.
    """

    def __init__(self, path):
        if not isinstance(path, (str, os.PathLike)):
            raise TypeError(f"path must be a file path, got {type(path).__name__}")
        self.path = os.fspath(path)
        if not os.path.exists(self.path):
            raise FileNotFoundError(f"GSD file {self.path!r} does not exist; check the path "
                                    f"(working directory: {os.getcwd()!r})")
        if os.path.isdir(self.path):
            raise ValueError(f"{self.path!r} is a directory, not a GSD file")
        self._sums = {}           # frame: {chunk name: CRC32} from its spherevm/checksum (None without one)
        self.file, problem = gsdrecover.open_file(self.path)
        self.recovered = problem is not None   # damaged: only the complete frames before the damage are read
        if self.file is None:
            raise ValueError(f"{self.path!r} is not a readable GSD file ({problem}); pass a .gsd trajectory written "
                             "by spherevm.plugins.writers.GSD")
        if self.recovered:
            warnings.warn(f"{self.path!r} is damaged or cut short ({problem}): reading its {len(self)} complete "
                          f"frame(s) before the damage; 'spherevm repair {self.path}' writes them to a new file",
                          DamagedFileWarning, stacklevel=2)

    def __len__(self):
        return int(self.file.nframes)

    def close(self):
        self.file.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    def index(self, frame) -> int:
        """The non-negative index of ``frame`` (negative counts from the end); FrameIndexError outside."""
        if isinstance(frame, bool) or not isinstance(frame, (int, np.integer)):
            raise TypeError(f"frame must be an integer, got {frame!r}")
        n = len(self)
        idx = int(frame) + n if frame < 0 else int(frame)
        if not 0 <= idx < n:
            raise FrameIndexError(f"frame {int(frame)} is out of range for {self.path!r}, which holds {n} "
                                  f"frame(s); use 0..{n - 1} or -{n}..-1")
        return idx

    def _read(self, idx, name):
        """Chunk ``name`` of frame ``idx`` (it exists), checked against the frame's CRC32 when it has
        them; ValueError naming them if gsd cannot read it or it is not what was written."""
        try:
            value = self.file.read_chunk(frame=idx, name=name)
        except (RuntimeError, OSError, KeyError) as exc:
            raise ValueError(f"{self.path!r}, frame {idx}: chunk {name!r} cannot be read ({exc}); the file is "
                             f"damaged: 'spherevm repair {self.path}' keeps the frames before the damage") from exc
        if name.startswith(PREFIX) and name != CHECKSUM:
            self._verify(idx, name, value)
        return value

    def _verify(self, idx, name, value):
        """Compare ``value`` (chunk ``name`` of frame ``idx``) with the CRC32 the writer stored."""
        if idx not in self._sums:
            table = None
            if self.file.chunk_exists(frame=0, name=CHECKSUM) and not self.file.chunk_exists(frame=idx, name=CHECKSUM):
                raise ValueError(f"{self._where(idx, CHECKSUM)}: missing, although frame 0 has one: the file is damaged")
            if self.file.chunk_exists(frame=idx, name=CHECKSUM):
                names = sorted(n for n in self.file.find_matching_chunk_names(PREFIX)
                               if n != CHECKSUM and self.file.chunk_exists(frame=idx, name=n))
                sums = stored(self._where(idx, CHECKSUM), self._read(idx, CHECKSUM), np.uint32, (len(names) + 1,))
                table = dict(zip(["configuration/step"] + names, sums.tolist()))
            self._sums[idx] = table
        table = self._sums[idx]
        if table is not None and _crc(value) != table[name]:
            raise ValueError(f"{self._where(idx, name)}: expected the CRC32 {table[name]:08x} stored in {CHECKSUM!r}, "
                             f"got {_crc(value):08x}: the chunk was changed after it was written (the file is damaged)")

    def _chunk(self, name, idx):
        """Chunk ``name`` of frame ``idx``, by the HOOMD rule (missing: frame 0's); None if neither has it."""
        for i in (idx, 0):
            if self.file.chunk_exists(frame=i, name=name):
                return self._read(i, name)
        return None

    def _where(self, idx, name) -> str:
        return f"{self.path!r}, frame {idx}, chunk {name!r}"

    def step(self, frame) -> int:
        """The timestep (``configuration/step``) of a frame; 0 where no frame stores it (HOOMD's default)."""
        idx = self.index(frame)
        step = self._chunk("configuration/step", idx)
        step = 0 if step is None else int(stored(self._where(idx, "configuration/step"), step, np.uint64, (1,))[0])
        self._verify(idx, "configuration/step", np.uint64(step))
        return step

    def _require_spherevm(self):
        path = self.path
        if len(self) == 0:
            why = ("before its damage" if self.recovered else "(the writer stopped before its first frame ended, or "
                   "nothing was written)")
            raise ValueError(f"{path!r} holds no complete frame {why}; write the run again")
        if not self.file.find_matching_chunk_names(PREFIX):
            raise ValueError(f"{path!r} is a GSD file (schema {self.file.schema!r}) without spherevm chunks: it "
                             "was not written by spherevm.plugins.writers.GSD (a plain HOOMD trajectory, say), so "
                             "it holds no cell topology; write the run with spherevm.plugins.writers.GSD, or build "
                             "the State with spherevm.init.from_polygons")

    def state(self, frame: int = -1, device=CPU, validate: bool = True, orientation: bool = False) -> State:
        """The State of a frame; see :func:`read_state`."""
        device = resolve(device)
        path = self.path
        self._require_spherevm()
        idx = self.index(frame)

        def chunk(name):
            value = self._chunk(PREFIX + name, idx)
            if value is None:
                raise ValueError(f"{path!r}: frame {idx} lacks chunk {PREFIX + name!r} (and frame 0 too): the "
                                 "frame was not written by spherevm.plugins.writers.GSD or the file is damaged")
            return value

        def check(name, value, dtype, shape, **bounds):
            return stored(self._where(idx, PREFIX + name), value, dtype, shape, **bounds)

        version = int(check("format_version", chunk("format_version"), np.uint32, (1,), low=1)[0])
        if version > FORMAT_VERSION:
            raise ValueError(f"{path!r} uses spherevm GSD format version {version}, newer than this spherevm "
                             f"reads ({FORMAT_VERSION}); upgrade spherevm")
        data = {name: chunk(name) for name in ALWAYS[1:] + TOPOLOGY}
        constraint = _constraint_from_json(check("constraint", data.pop("constraint"), np.uint8, (None,)), path)
        key = constraint.size_key
        pos = check("position", data["position"], np.float64, (None, 3), finite=False)   # validate names a bad vertex
        nv, nc = len(pos), len(check("cell_sides", data["cell_sides"], np.int32, (None,)))
        cv = data["cell_vertices"]
        if cv.ndim == 1:  # gsd stores a (C, 1) table as 1-D; never written by spherevm, but be safe
            cv = cv.reshape(nc, -1)
        check("cell_vertices", cv, np.int32, (nc, None))
        for name in ("vertex_neighbors", "vertex_cells"):
            check(name, data[name], np.int32, (nv, 3))
        starts = [check(name, data[name], np.int64, (None,), low=0, high=n)
                  for name, n in (("vertex_start", nv), ("cell_start", nc))]
        n_rep = len(starts[1]) - 1
        size = check(key, chunk(key), np.float64, (n_rep,) + tuple(constraint.size_shape), above=0)
        stored_size(self._where(idx, PREFIX + key), size, np.diff(starts[1]), constraint.total_area_np)
        where = f"{path!r}, frame {idx} (timestep {self.step(idx)})"
        try:
            state = State(positions=pos, cell_vertices=cv, cell_sides=data["cell_sides"],
                          vertex_neighbors=data["vertex_neighbors"], vertex_cells=data["vertex_cells"],
                          vertex_start=data["vertex_start"], cell_start=data["cell_start"], size=size,
                          constraint=constraint, device=CPU, validate=False)
            if validate:
                bad = (cv < -1) | (cv >= nv)
                if bad.any():
                    c = int(np.flatnonzero(bad.any(axis=1))[0])
                    raise ValueError(f"cell_vertices of cell {c} is {cv[c].tolist()}, outside -1..{nv - 1}")
                state.validate(orientation=orientation)
        except (ValueError, IndexError, TypeError) as exc:
            hint = "" if not validate else " (the file is damaged or was not written by spherevm; validate=False reads it anyway)"
            raise ValueError(f"{where}: the stored state is invalid: {exc}{hint}") from exc
        return state if device is CPU else state.to(device)

    # the Simulation's own checkpoint fields: (dtype, shape, lowest, highest)
    SIMULATION_FIELDS = {"seed": (np.int64, (1,), 0, 2 ** 32 - 1), "updated_at": (np.int64, (1,), -1, None),
                         "held_back": (np.int64, (1,), 0, 1)}

    def checkpoint(self, frame: int = -1) -> dict:
        """The saved run state of a frame: ``{"simulation": {field: array}, "op": {key: Saved}}``,
        from the ``spherevm/simulation/*`` and ``spherevm/op/<key>/<field>`` chunks of that frame
        only (empty dicts where the frame holds none). The Simulation's fields are checked here
        (:attr:`SIMULATION_FIELDS`); an operation's, which must be numeric, by its ``restore_state``."""
        idx = self.index(frame)
        out = {"simulation": {}, "op": {}}
        for kind in ("simulation/", "op/"):
            for name in self.file.find_matching_chunk_names(PREFIX + kind):
                if not self.file.chunk_exists(frame=idx, name=name):
                    continue
                rest = name[len(PREFIX + kind):]
                value = self._read(idx, name)
                if not isinstance(value, np.ndarray) or value.dtype.kind not in "uif":
                    raise ValueError(f"{self._where(idx, name)}: expected a numeric array, got "
                                     f"{getattr(value, 'dtype', type(value).__name__)}")
                if kind == "simulation/":
                    if rest in self.SIMULATION_FIELDS:
                        dtype, shape, low, high = self.SIMULATION_FIELDS[rest]
                        value = stored(self._where(idx, name), value, dtype, shape, low=low, high=high)
                    out["simulation"][rest] = value
                else:
                    key, _, field_name = rest.rpartition("/")
                    prefix = f"{self.path!r}, frame {idx}, chunk '{PREFIX}{kind}{key}/"
                    out["op"].setdefault(key, Saved({}, prefix))[field_name] = value
        return out

    def cell_values(self, frame: int = -1) -> dict:
        """The exact per-cell arrays (``area``, ``perimeter``, ``shape_index``, ``energy``) of a frame."""
        self._require_spherevm()
        idx = self.index(frame)
        out = {}
        for q in CELL_QUANTITIES:
            name = f"{PREFIX}cell_{q}"
            if self.file.chunk_exists(frame=idx, name=name):   # NaN where undefined (A <= 0)
                out[q] = stored(self._where(idx, name), self._read(idx, name), np.float64, (None,), finite=False)
        return out


def n_frames(path) -> int:
    """Number of frames in a GSD file."""
    with Reader(path) as r:
        return len(r)


def read_state(path, frame: int = -1, device=CPU, validate: bool = True, orientation: bool = False) -> State:
    """Restore the State stored in frame ``frame`` (negative counts from the end) of a spherevm GSD file.

    Positions come back bitwise (the float64 copy), the topology identical, also across T1s and
    changes of ``max_sides``. ``validate=True`` (default) runs :meth:`State.validate` on it: finite
    positions on the surface, index ranges, trivalent reciprocal tables consistent with the cell
    table, replica layout, Euler characteristic; an invalid frame raises ValueError naming the file,
    frame, timestep and the first bad entry. ``orientation=True`` adds the positive-area test (off
    by default: a valid run at kA = 0 may pass through folded cells). ``validate=False`` skips it.

    Raises FileNotFoundError for a missing file, ValueError for a file that is not GSD, not written
    by spherevm or damaged, and :class:`FrameIndexError` (an IndexError and a ValueError) for a
    frame outside the file.
    """
    with Reader(path) as r:
        return r.state(frame, device=device, validate=validate, orientation=orientation)


def read_cell_values(path, frame: int = -1) -> dict:
    """The exact per-cell arrays (``area``, ``perimeter``, ``shape_index``, ``energy``) of a frame."""
    with Reader(path) as r:
        return r.cell_values(frame)
