"""GSD trajectories (HOOMD schema) that open in OVITO and restore a State exactly.

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

import json
import os

import numpy as np

from ...device import CPU, resolve
from ...topology import edges as _edges
from ..base import Writer

FORMAT_VERSION = 1
BOX_FACTOR = 2.2
DIAMETER_FACTOR = 0.15
DEFAULT_LOG = ("energy", "energy_per_cell", "mean_shape_index", "max_force")
_FORCE_LOGGABLES = {"energy", "energy_per_cell", "max_force"}
_MODES = {"wb": "w", "w": "w", "ab": "a", "a": "a", "xb": "x", "x": "x"}
# chunks written every frame (the restore needs them) and chunks left out when equal to frame 0's
_ALWAYS = ("format_version", "constraint", "position", "vertex_start", "cell_start", "radius")
_TOPOLOGY = ("cell_vertices", "cell_sides", "vertex_neighbors", "vertex_cells")
_REQUIRED = _ALWAYS + _TOPOLOGY
CELL_QUANTITIES = ("area", "perimeter", "shape_index", "energy")


class FrameIndexError(IndexError, ValueError):
    """A frame index outside the file (both an IndexError and a ValueError)."""


# ---------------------------------------------------------------------------------------- helpers
def _constraint_json(constraint) -> np.ndarray:
    params = {k: v for k, v in vars(constraint).items()
              if not k.startswith("_") and isinstance(v, (bool, int, float, str))}
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
    from ...constraints import Constraint
    try:
        spec = json.loads(bytes(np.asarray(raw, dtype=np.uint8)).decode("utf-8"))
        name, params = spec["name"], spec.get("params", {})
    except (ValueError, KeyError, TypeError) as exc:
        raise ValueError(f"{path}: chunk spherevm/constraint is not valid JSON ({exc}); the file is damaged") from exc
    matches = [c for c in _all_subclasses(Constraint) if getattr(c, "name", None) == name]
    if not matches:
        raise ValueError(f"{path}: unknown constraint {name!r}; import the module that defines the "
                         f"Constraint subclass with name = {name!r} before reading the file")
    cls = next((c for c in matches if c.__name__ == spec.get("class")), matches[0])
    try:
        return cls(**params)
    except Exception as exc:
        raise ValueError(f"{path}: cannot rebuild constraint {name!r} from parameters {params}: {exc}") from exc


def _per_replica(name, value, n_replicas):
    arr = np.asarray(value, dtype=np.float64)
    if arr.ndim == 0:
        return arr.reshape(1)
    if arr.shape != (n_replicas,):
        raise ValueError(f"loggable {name!r} must be a scalar or one value per replica "
                         f"(length {n_replicas}), got shape {arr.shape}")
    return arr


# ---------------------------------------------------------------------------------------- writer
class GSD(Writer):
    """Write frames to a GSD file (HOOMD schema) that OVITO opens and :func:`read_state` restores.

    Parameters
    ----------
    filename : path of the ``.gsd`` file; opened at the first write (not at construction).
    trigger : a :class:`spherevm.trigger.Trigger` or an int period (default every 1000 steps).
    mode : ``"wb"`` overwrites (or creates) the file, ``"ab"`` appends to it (or creates it),
        ``"xb"`` creates it and fails if it exists. ``"w"``, ``"a"``, ``"x"`` are accepted too.
    log : names of loggable quantities (see ``Simulation.loggables``), written as ``log/<name>``
        with one value per replica (scalars as one value). The default skips the force-dependent
        ones when the simulation has no force.
    cell_quantities : which per-cell values to record, from ``("area", "perimeter", "shape_index",
        "energy")``: exact arrays under ``spherevm/cell_<q>`` and the mean over each vertex's three
        cells under ``log/particles/cell_<q>`` (for colouring in OVITO). ``"energy"`` is written
        when every force reports per-cell energies (``ForceResult.cell_energy``, taken from the
        simulation's force cache, so writing costs no extra force evaluation).

    Every frame is flushed to disk, so a crash leaves a readable file. After :meth:`close`, a
    later write reopens the file in append mode.
    """

    def __init__(self, filename, trigger=1000, mode="wb", log=None, cell_quantities=CELL_QUANTITIES):
        super().__init__(trigger)
        if not isinstance(filename, (str, os.PathLike)) or not os.fspath(filename):
            raise ValueError(f"filename must be a non-empty path, got {filename!r}")
        if mode not in _MODES:
            raise ValueError(f"mode must be one of 'wb' (overwrite), 'ab' (append) or 'xb' (create), got {mode!r}")
        self.filename = os.fspath(filename)
        self.mode = mode
        self._default_log = log is None
        names = DEFAULT_LOG if log is None else ((log,) if isinstance(log, str) else tuple(log))
        if not all(isinstance(n, str) for n in names):
            raise ValueError(f"log must be a sequence of loggable names (str), got {log!r}")
        self.log = names
        bad = [q for q in cell_quantities if q not in CELL_QUANTITIES]
        if bad:
            raise ValueError(f"cell_quantities must be drawn from {CELL_QUANTITIES}, got {bad}")
        self.cell_quantities = tuple(cell_quantities)
        self._traj = None
        self._opened = False
        self._frame0 = {}        # spherevm topology chunks of frame 0
        self._box = 0.0
        self._log_names = None   # fixed at the first write
        self._cell_keys = None   # fixed at the first write
        self._extra_keys = {}    # per-vertex / per-edge log keys the file holds: (trailing shape, dtype)

    # ------------------------------------------------------------------ file handling
    def _open(self):
        import gsd.hoomd
        if self._traj is not None:
            return self._traj
        mode = _MODES[self.mode] if not self._opened else "a"
        folder = os.path.dirname(os.path.abspath(self.filename))
        if not os.path.isdir(folder):
            raise FileNotFoundError(f"GSD writer: folder {folder!r} of {self.filename!r} does not exist; "
                                    "create it first")
        try:
            traj = gsd.hoomd.open(self.filename, mode)
        except FileExistsError:
            raise FileExistsError(f"GSD writer: {self.filename!r} exists and mode='xb' refuses to overwrite it; "
                                  "use mode='wb' to overwrite or 'ab' to append") from None
        except RuntimeError as exc:
            raise ValueError(f"GSD writer: cannot append to {self.filename!r}: {exc}; use mode='wb' to "
                             "overwrite it or write to another file") from exc
        self._traj, self._opened = traj, True
        self._frame0, self._extra_keys = {}, {}
        if len(traj) > 0:  # appending: take frame 0's topology and the file's box and per-item keys
            f = traj.file
            for name in _TOPOLOGY:
                if f.chunk_exists(frame=0, name="spherevm/" + name):
                    self._frame0[name] = f.read_chunk(frame=0, name="spherevm/" + name)
            traj[0]  # caches gsd.hoomd's initial frame before chunks of the next frame are written
            self._box = float(traj[len(traj) - 1].configuration.box[0])
            for key in f.find_matching_chunk_names("log/particles/") + f.find_matching_chunk_names("log/bonds/"):
                last = next(i for i in range(len(traj) - 1, -1, -1) if f.chunk_exists(frame=i, name=key))
                arr = f.read_chunk(frame=last, name=key)
                self._extra_keys[key[4:]] = (arr.shape[1:], arr.dtype)
        return traj

    def flush(self):
        """Write buffered frames to disk (each write already does)."""
        if self._traj is not None:
            self._traj.flush()

    def close(self):
        """Flush and close the file; a later write reopens it in append mode."""
        if self._traj is not None:
            self._traj.flush()
            self._traj.close()
            self._traj = None

    def detach(self):
        self.close()
        super().detach()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    # ------------------------------------------------------------------ writing
    def _resolve_log_names(self, simulation):
        names = self.log
        has_forces = bool(simulation.operations.forces)
        if self._default_log and not has_forces:
            names = tuple(n for n in names if n not in _FORCE_LOGGABLES)
        known = simulation.loggables
        unknown = [n for n in names if n not in known]
        if unknown:
            raise ValueError(f"GSD writer: unknown loggable(s) {unknown}; available: {sorted(known)}")
        return names

    def write(self, simulation, timestep):
        import gsd.hoomd
        state = simulation.state
        dev = state.device
        to_np = dev.to_numpy
        pos = np.ascontiguousarray(to_np(state.positions), dtype=np.float64)
        bad = ~np.isfinite(pos).all(axis=1)
        if bad.any():
            v = int(np.flatnonzero(bad)[0])
            raise FloatingPointError(f"GSD writer: vertex {v} of replica {int(state.vertex_replica_np()[v])} has "
                                     f"non-finite position {pos[v]} at timestep {timestep}; frame not written, "
                                     f"the last good frame stays in {self.filename!r}")
        vn = np.ascontiguousarray(to_np(state.vertex_neighbors), dtype=np.int32)
        vc = np.ascontiguousarray(to_np(state.vertex_cells), dtype=np.int32)
        cv = np.ascontiguousarray(to_np(state.cell_vertices), dtype=np.int32)
        sides = np.ascontiguousarray(to_np(state.cell_sides), dtype=np.int32)
        radius = np.ascontiguousarray(state.radius_np(), dtype=np.float64)
        n_v, n_r = len(pos), state.n_replicas
        vrep = state.vertex_replica_np()
        bonds = _edges(vn)

        if self._log_names is None:
            self._log_names = self._resolve_log_names(simulation)
        traj = self._open()

        # ---- HOOMD part
        chord = np.sqrt(((pos[bonds[:, 0]] - pos[bonds[:, 1]]) ** 2).sum(axis=1))
        extent = max(float(radius.max()), float(np.abs(pos).max()), float(chord.max(initial=0.0)))
        # fixed unless something outgrows it; float32 as stored, so gsd skips an unchanged box
        self._box = max(self._box, float(np.float32(BOX_FACTOR * extent * (1 + 1e-6))))
        frame = gsd.hoomd.Frame()
        frame.configuration.step = int(timestep)
        frame.configuration.dimensions = 3
        frame.configuration.box = np.array([self._box] * 3 + [0.0] * 3, dtype=np.float32)
        frame.particles.N = n_v
        frame.particles.types = ["V"]
        frame.particles.typeid = np.zeros(n_v, dtype=np.uint32)
        frame.particles.position = pos.astype(np.float32)
        frame.particles.diameter = self._diameters(state, chord, bonds)[vrep]
        frame.bonds.N = len(bonds)
        frame.bonds.types = ["E"]
        frame.bonds.typeid = np.zeros(len(bonds), dtype=np.uint32)
        frame.bonds.group = bonds.astype(np.uint32)

        log = {}
        for name in self._log_names:
            log[name] = _per_replica(name, simulation.log(name), n_r)
        log["particles/replica"] = vrep.astype(np.int32)
        if simulation.operations.forces:
            forces, _ = simulation.compute_forces()
            log["particles/force"] = np.ascontiguousarray(to_np(forces), dtype=np.float64)
        try:
            log["bonds/length"] = np.asarray(to_np(state.constraint.edge_lengths(
                state, dev.asarray(bonds[:, 0]), dev.asarray(bonds[:, 1]))), dtype=np.float64)
        except NotImplementedError:
            log["bonds/length"] = chord
        cells = self._cell_values(simulation, state)
        for q, values in cells.items():
            log[f"particles/cell_{q}"] = values[vc].mean(axis=1)
        # A per-vertex or per-edge key missing from a frame would take frame 0's array, of the wrong
        # length after a topology change, and OVITO would reject the frame: every key this file has
        # seen (from earlier frames or from the file we append to) is written, NaN if unknown now.
        for key, (trailing, dtype) in self._extra_keys.items():
            if key not in log:
                n = n_v if key.startswith("particles/") else len(bonds)
                fill = np.nan if np.issubdtype(dtype, np.floating) else -1
                log[key] = np.full((n,) + trailing, fill, dtype=dtype)
        self._extra_keys.update((k, (np.shape(v)[1:], np.asarray(v).dtype)) for k, v in log.items()
                                if k.startswith(("particles/", "bonds/")))
        frame.log = log

        # ---- spherevm part (written before append, which ends the frame)
        chunks = {"format_version": np.array([FORMAT_VERSION], dtype=np.uint32),
                  "constraint": _constraint_json(state.constraint),
                  "position": pos,
                  "vertex_start": np.asarray(state.vertex_start, dtype=np.int64),
                  "cell_start": np.asarray(state.cell_start, dtype=np.int64),
                  "radius": radius}
        first = len(traj) == 0
        for name, arr in (("cell_vertices", cv), ("cell_sides", sides), ("vertex_neighbors", vn),
                          ("vertex_cells", vc)):
            if first or name not in self._frame0 or not np.array_equal(self._frame0[name], arr):
                chunks[name] = arr
            if first:
                self._frame0[name] = arr.copy()
        for q, values in cells.items():
            chunks["cell_" + q] = values
        for name, arr in chunks.items():
            traj.file.write_chunk("spherevm/" + name, np.ascontiguousarray(arr))
        traj.append(frame)
        traj.flush()

    @staticmethod
    def _diameters(state, chord, bonds):
        """Per-replica display diameter: 0.15 sqrt(<A>), or a quarter of the mean edge chord."""
        try:
            d = DIAMETER_FACTOR * np.sqrt(np.asarray(state.mean_cell_area, dtype=np.float64))
        except NotImplementedError:
            rep = state.vertex_replica_np()[bonds[:, 0]]
            n = np.maximum(np.bincount(rep, minlength=state.n_replicas), 1)
            d = 0.25 * np.bincount(rep, weights=chord, minlength=state.n_replicas) / n
        return d.astype(np.float32)

    def _cell_values(self, simulation, state):
        """Exact per-cell arrays by quantity name (those the constraint and forces can provide)."""
        from ...analysis import cell_shapes
        out = {}
        wanted = self.cell_quantities
        if {"area", "perimeter", "shape_index"} & set(wanted):
            try:
                area, perimeter = cell_shapes(state)
            except NotImplementedError:
                area = perimeter = None
            if area is not None:
                if "area" in wanted:
                    out["area"] = np.asarray(area, dtype=np.float64)
                if "perimeter" in wanted:
                    out["perimeter"] = np.asarray(perimeter, dtype=np.float64)
                if "shape_index" in wanted:
                    out["shape_index"] = perimeter / np.sqrt(np.where(area > 0, area, np.nan))
        if "energy" in wanted and simulation.operations.forces:
            ce = simulation.cell_energy()
            if ce is not None:
                out["energy"] = np.asarray(state.device.to_numpy(ce), dtype=np.float64)
        # the set of per-cell keys is fixed by the first frame (a frame missing a log/particles key
        # would take frame 0's array, of the wrong length after a T1): fill what is missing with NaN
        if self._cell_keys is None:
            self._cell_keys = tuple(out)
        return {q: out.get(q, np.full(state.n_cells, np.nan)) for q in self._cell_keys}

    def __repr__(self):
        return f"GSD({self.filename!r}, trigger={self.trigger!r}, mode={self.mode!r}, log={self.log!r})"


# ---------------------------------------------------------------------------------------- reader
def _open_for_reading(path):
    import gsd.fl
    if not isinstance(path, (str, os.PathLike)):
        raise TypeError(f"path must be a file path, got {type(path).__name__}")
    path = os.fspath(path)
    if not os.path.exists(path):
        raise FileNotFoundError(f"GSD file {path!r} does not exist; check the path "
                                f"(working directory: {os.getcwd()!r})")
    if os.path.isdir(path):
        raise ValueError(f"{path!r} is a directory, not a GSD file")
    try:
        return gsd.fl.open(name=path, mode="r")
    except (RuntimeError, OSError) as exc:
        raise ValueError(f"{path!r} is not a readable GSD file ({exc}); pass a .gsd trajectory written by "
                         "spherevm.plugins.writers.GSD") from exc


def n_frames(path) -> int:
    """Number of frames in a GSD file."""
    with _open_for_reading(path) as f:
        return int(f.nframes)


def read_state(path, frame: int = -1, device=CPU, validate: bool = False):
    """Restore the State stored in frame ``frame`` (negative counts from the end) of a spherevm GSD file.

    Positions come back bitwise (the float64 copy), the topology identical, also across T1s and
    changes of ``max_sides``. ``validate=True`` also runs :meth:`State.validate` (off by default:
    a valid run may pass through folded cells that the check rejects).

    Raises FileNotFoundError for a missing file, ValueError for a file that is not GSD, not written
    by spherevm or damaged, and :class:`FrameIndexError` (an IndexError and a ValueError) for a
    frame outside the file.
    """
    from ...state import State
    device = resolve(device)
    if isinstance(frame, bool) or not isinstance(frame, (int, np.integer)):
        raise TypeError(f"frame must be an integer, got {frame!r}")
    with _open_for_reading(path) as f:
        path = os.fspath(path)
        n = int(f.nframes)
        if n == 0:
            raise ValueError(f"{path!r} holds no complete frame (the writer stopped before its first frame "
                             "ended, or nothing was written); write the run again")
        if not f.find_matching_chunk_names("spherevm/"):
            raise ValueError(f"{path!r} is a GSD file (schema {f.schema!r}) without spherevm chunks: it was not "
                             "written by spherevm.plugins.writers.GSD (a plain HOOMD trajectory, say), so it "
                             "holds no cell topology; write the run with spherevm.plugins.writers.GSD, or build "
                             "the State with spherevm.init.from_polygons")
        idx = int(frame) + n if frame < 0 else int(frame)
        if not 0 <= idx < n:
            raise FrameIndexError(f"frame {int(frame)} is out of range for {path!r}, which holds {n} frame(s); "
                                  f"use 0..{n - 1} or -{n}..-1")

        def chunk(name):
            full = "spherevm/" + name
            for i in (idx, 0):  # HOOMD rule: a chunk missing from a frame takes frame 0's value
                if f.chunk_exists(frame=i, name=full):
                    return f.read_chunk(frame=i, name=full)
            raise ValueError(f"{path!r}: frame {idx} lacks chunk {full!r} (and frame 0 too): the frame was not "
                             "written by spherevm.plugins.writers.GSD or the file is damaged")

        version = int(chunk("format_version")[0])
        if version > FORMAT_VERSION:
            raise ValueError(f"{path!r} uses spherevm GSD format version {version}, newer than this spherevm "
                             f"reads ({FORMAT_VERSION}); upgrade spherevm")
        data = {name: chunk(name) for name in _REQUIRED if name != "format_version"}
    constraint = _constraint_from_json(data.pop("constraint"), path)
    pos = data["position"]
    nv, nc = len(pos), len(data["cell_sides"])
    cv = data["cell_vertices"]
    if cv.ndim == 1:  # gsd stores a (C, 1) table as 1-D; never written by spherevm, but be safe
        cv = cv.reshape(nc, -1)
    shapes_ok = (pos.ndim == 2 and pos.shape[1] == 3 and data["vertex_neighbors"].shape == (nv, 3)
                 and data["vertex_cells"].shape == (nv, 3) and cv.ndim == 2 and cv.shape[0] == nc)
    if not shapes_ok:
        raise ValueError(f"{path!r}, frame {idx}: inconsistent spherevm chunks (positions {pos.shape}, "
                         f"vertex_neighbors {data['vertex_neighbors'].shape}, vertex_cells "
                         f"{data['vertex_cells'].shape}, cell_vertices {cv.shape}, cell_sides "
                         f"{data['cell_sides'].shape}); the file is damaged")
    try:
        return State(positions=pos, cell_vertices=cv, cell_sides=data["cell_sides"],
                     vertex_neighbors=data["vertex_neighbors"], vertex_cells=data["vertex_cells"],
                     vertex_start=data["vertex_start"], cell_start=data["cell_start"], radius=data["radius"],
                     constraint=constraint, device=device, validate=validate)
    except ValueError as exc:
        raise ValueError(f"{path!r}, frame {idx}: the stored state is invalid: {exc}") from exc


def read_cell_values(path, frame: int = -1) -> dict:
    """The exact per-cell arrays (``area``, ``perimeter``, ``shape_index``, ``energy``) of a frame."""
    with _open_for_reading(path) as f:
        n = int(f.nframes)
        idx = int(frame) + n if frame < 0 else int(frame)
        if not 0 <= idx < n:
            raise FrameIndexError(f"frame {int(frame)} is out of range for {os.fspath(path)!r}, which holds "
                                  f"{n} frame(s)")
        return {q: f.read_chunk(frame=idx, name=f"spherevm/cell_{q}") for q in CELL_QUANTITIES
                if f.chunk_exists(frame=idx, name=f"spherevm/cell_{q}")}
