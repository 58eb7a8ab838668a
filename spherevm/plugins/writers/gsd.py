"""The GSD writer: when to write a frame and what to log; :mod:`spherevm.gsdio` writes it.

The file opens in OVITO and restores a State exactly (:func:`spherevm.init.from_gsd`); the schema
is described in :mod:`spherevm.gsdio` and ``docs/file-format.md``.
"""
from __future__ import annotations

import os

import numpy as np

from ... import gsdio
from ...shapes import cell_shapes, shape_index_of
from ...logging import Logger
from ..base import Writer
from .arguments import trigger_first

DEFAULT_LOG = ("energy", "energy_per_cell", "mean_shape_index", "max_force")
_FORCE_LOGGABLES = {"energy", "energy_per_cell", "max_force"}
_MODES = {"wb": "w", "w": "w", "ab": "a", "a": "a", "xb": "x", "x": "x"}


def _per_replica(name, value, n_replicas):
    arr = np.asarray(value, dtype=np.float64)
    if arr.ndim == 0:
        return arr.reshape(1)
    if arr.shape != (n_replicas,):
        raise ValueError(f"loggable {name!r} must be a scalar or one value per replica "
                         f"(length {n_replicas}), got shape {arr.shape}")
    return arr

class GSD(Writer):
    """Write frames to a GSD file (HOOMD schema) that OVITO opens and :func:`spherevm.init.from_gsd` restores.

    ``GSD(trigger, filename, mode=None, logger=None, ...)``: HOOMD-blue's argument order
    (``hoomd.write.GSD(trigger, filename)``); keywords work too, and the older order, the path
    first (``GSD("run.gsd", trigger=100)``), still works with a DeprecationWarning. Every frame is
    flushed to disk, so a crash leaves a readable file. After :meth:`close`, a later write reopens
    the file in append mode.

    Parameters
    ----------
    trigger : Trigger or int
        When to write (default every 1000 steps).
    filename : str or path
        The ``.gsd`` file; opened at the first write (not at construction).
    mode : {"wb", "ab", "xb"} or None
        "wb" overwrites (or creates) the file, "ab" appends to it (or creates it), "xb" creates it
        and fails if it exists; "w", "a", "x" are accepted too. The default (None) is "wb", except
        for the file the Simulation was restored from (``create_state_from_gsd``), which it appends
        to; "wb" on that file is refused, as it would erase the frames the run continues. (HOOMD's
        default is "ab"; docs/hoomd.md says why this one overwrites.)
    logger : Logger, optional
        What is logged, written as ``log/<name>`` with one value per replica.
    log : sequence of str or Logger, optional
        The short form: loggable names (see ``Simulation.loggables``); give ``logger`` or ``log``,
        not both. Default: energy, energy per cell, mean shape index and largest force (those that
        need a force only with one).
    cell_quantities : sequence of str
        Per-cell values to record, from ``("area", "perimeter", "shape_index", "energy")``: exact
        arrays under ``spherevm/cell_<q>`` and the mean over each vertex's three cells under
        ``log/particles/cell_<q>`` (for colouring in OVITO). "energy" is written when every force
        reports per-cell energies (from the force cache: no extra force evaluation).
    checkpoint : bool
        Write the run state too (every operation's ``state_to_save``), so that every frame is a
        checkpoint that ``Simulation.create_state_from_gsd`` continues bitwise.
    final : bool
        Also write the state a ``run`` or ``minimize`` ends in, whatever the trigger."""

    def __init__(self, *args, trigger=None, filename=None, mode=None, logger=None, log=None,
                 cell_quantities=gsdio.CELL_QUANTITIES, checkpoint=True, final=True):
        trigger, filename = trigger_first("GSD", args, trigger, filename, 1000, "filename")
        super().__init__(trigger)
        self.checkpoint = bool(checkpoint)
        self.final = bool(final)
        if not isinstance(filename, (str, os.PathLike)) or not os.fspath(filename):
            raise ValueError(f"filename must be a non-empty path, got {filename!r}")
        if mode is not None and mode not in _MODES:
            raise ValueError(f"mode must be one of 'wb' (overwrite), 'ab' (append) or 'xb' (create), got {mode!r}")
        if os.path.isdir(filename):
            raise ValueError(f"GSD writer: {os.fspath(filename)!r} is a directory; give a file name such as "
                             f"{os.path.join(os.fspath(filename), 'run.gsd')!r}")
        self.filename = os.fspath(filename)
        self.mode = mode
        if isinstance(log, Logger) and logger is None:     # HOOMD-blue 3 spelled it log=Logger
            logger, log = log, None
        if logger is not None and log is not None:
            raise ValueError("give GSD either logger= (a spherevm.logging.Logger) or log= (names), not both")
        if logger is not None and not isinstance(logger, Logger):
            raise TypeError(f"logger must be a spherevm.logging.Logger, got {type(logger).__name__}")
        self._default_log = logger is None and log is None
        self.logger = logger if logger is not None else Logger(DEFAULT_LOG if log is None else log)
        bad = [q for q in cell_quantities if q not in gsdio.CELL_QUANTITIES]
        if bad:
            raise ValueError(f"cell_quantities must be drawn from {gsdio.CELL_QUANTITIES}, got {bad}")
        self.cell_quantities = tuple(cell_quantities)
        self._frames = None      # the open file, a gsdio.FrameWriter
        self._opened = False
        self._checked = False    # the logger is checked against the Simulation at the first write
        self._cell_keys = None   # fixed at the first write
        self._continues = None   # appending to the file the run was restored from: the step it ends at

    @property
    def log(self) -> tuple:
        """The logged names (the logger's)."""
        return self.logger.names

    # ------------------------------------------------------------------ file handling
    def _mode(self, simulation):
        """The gsd mode of the first open: see ``mode``. Sets ``_continues`` when the run appends to
        the file it was restored from (its last frame is the state the run starts from)."""
        source, step = simulation.restored_from or (None, None)
        if source is None or os.path.realpath(self.filename) != source or not os.path.exists(source):
            return _MODES[self.mode or "wb"]
        mode = _MODES[self.mode or "ab"]
        if mode == "w":
            raise ValueError(f"GSD writer: {self.filename!r} is the file this Simulation was restored from; mode='wb' "
                             "would erase the frames it continues: use mode='ab' (the default for this file) "
                             "to append, or write to another file")
        if mode == "a":
            from ... import gsdio
            with gsdio.Reader(self.filename) as reader:
                last = reader.step(-1) if len(reader) else None
            if last != step:
                raise ValueError(f"GSD writer: {self.filename!r} ends at step {last}, but the Simulation was restored "
                                 f"from its frame of step {step}; appending would break its timeline: write to "
                                 "another file")
            self._continues = step
        return mode

    def _open(self, simulation):
        import gsd.hoomd
        if self._frames is not None:
            return self._frames
        mode = self._mode(simulation) if not self._opened else "a"
        folder = os.path.dirname(os.path.abspath(self.filename))
        if not os.path.isdir(folder):
            raise FileNotFoundError(f"GSD writer: folder {folder!r} of {self.filename!r} does not exist; "
                                    "create it first")
        if os.path.isdir(self.filename):
            raise IsADirectoryError(f"GSD writer: {self.filename!r} is a directory; give a file name such as "
                                    f"{os.path.join(self.filename, 'run.gsd')!r}")
        try:
            traj = gsd.hoomd.open(self.filename, mode)
        except FileExistsError:
            raise FileExistsError(f"GSD writer: {self.filename!r} exists and mode='xb' refuses to overwrite it; "
                                  "use mode='wb' to overwrite or 'ab' to append") from None
        except RuntimeError as exc:
            raise ValueError(f"GSD writer: cannot append to {self.filename!r}: {exc}; use mode='wb' to "
                             f"overwrite it, write to another file, or 'spherevm repair {self.filename}' to "
                             "copy its complete frames to a new file first") from exc
        except OSError as exc:
            raise type(exc)(f"GSD writer: cannot open filename {self.filename!r} for writing "
                            f"({exc.strerror or exc}); choose a file in a folder where files can be created") from None
        self._frames, self._opened = gsdio.FrameWriter(traj), True
        return self._frames

    def flush(self):
        """Write buffered frames to disk (each write already does)."""
        if self._frames is not None:
            self._frames.traj.flush()

    def close(self):
        """Flush and close the file; a later write reopens it in append mode."""
        if self._frames is not None:
            self._frames.traj.flush()
            self._frames.traj.close()
            self._frames = None

    def detach(self):
        self.close()
        super().detach()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    # ------------------------------------------------------------------ writing
    def _check_logger(self, simulation):
        if self._default_log and not simulation.operations.forces:
            for name in _FORCE_LOGGABLES:
                self.logger.remove(name)
        self.logger.check(simulation, who="GSD writer")
        self._checked = True

    def write(self, simulation, timestep):
        state = simulation.state
        xp = state.device.xp
        bad = ~xp.isfinite(state.positions).all(axis=1)
        if bool(bad.any()):
            v = int(xp.flatnonzero(bad)[0])
            raise FloatingPointError(f"GSD writer: vertex {v} of replica {int(state.vertex_replica_np()[v])} has "
                                     f"non-finite position {state.device.to_numpy(state.positions[v])} at "
                                     f"timestep {timestep}; frame not written, the last good frame stays in "
                                     f"{self.filename!r}")
        if not self._checked:
            self._check_logger(simulation)
        frames = self._open(simulation)
        if timestep == self._continues:   # the frame the file ends with: the run starts from it
            return
        log = {name: _per_replica(name, value, state.n_replicas) for name, value in self.logger.log(simulation).items()}
        vertex_values = {}
        if simulation.operations.forces:
            forces, _ = simulation.compute_forces()
            vertex_values["force"] = np.ascontiguousarray(state.device.to_numpy(forces), dtype=np.float64)
        checkpoint = simulation.checkpoint() if self.checkpoint else None
        frames.append(state, timestep, log, self._cell_values(simulation, state), vertex_values, checkpoint)
        frames.traj.flush()

    def _cell_values(self, simulation, state):
        """Exact per-cell arrays by quantity name (those the constraint and forces can provide)."""
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
                    out["shape_index"] = shape_index_of(area, perimeter)
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
        return f"GSD({self.trigger!r}, {self.filename!r}, mode={self.mode!r}, logger={self.logger!r})"


def write_gsd(simulation, filename, mode=None, **options):
    """Write the Simulation's current state as one frame (a checkpoint by default) at
    ``simulation.timestep``, and close the file: the one-shot form of :class:`GSD`.

    Parameters
    ----------
    simulation : Simulation
    filename : str or path
    mode : {"wb", "ab", "xb"} or None
        As in :class:`GSD` ("ab" appends a frame to an existing file).
    **options
        :class:`GSD`'s other keywords.

    Returns
    -------
    str or path
        The file written."""
    simulation.require_state()
    writer = GSD(1, filename, mode=mode, **options)
    try:
        writer.write(simulation, simulation.timestep)
    finally:
        writer.close()
    return writer.filename
