"""Cell centroids over time (:class:`Trajectory`) and the removal of each tissue's rigid rotation
(on a sphere) or centre-of-mass drift (on the periodic plane).

A Trajectory is built from States, from a spherevm GSD file or from a Recorder's
:class:`~spherevm.plugins.writers.recorder.Recording`; :mod:`spherevm.analysis.dynamics` measures it.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..constraints.plane import _wrap, minimum_image
from ..gsdio import Reader
from ..plugins.writers.recorder import Recorder
from ..shapes import cell_centroids


# ======================================================================================== trajectory
@dataclass(eq=False)
class Trajectory:
    """Cell centroids over time, for one tissue or an ensemble of replicas.

    On the plane the centroids are unwrapped across the boundary (:attr:`positions`): each
    frame-to-frame displacement is taken as its minimum image and summed from frame 0, so a cell
    that leaves the box on one side keeps its true displacement. This needs every cell to move
    less than half the box between consecutive frames (sample often enough).

    Parameters
    ----------
    times : numpy.ndarray (T,)
        Sampling times (timesteps, or times in any unit), increasing.
    centroids : numpy.ndarray (T, n_cells, 3)
        Cell positions on the sphere of each replica, or in the periodic box of each replica
        (stored wrapped, z = 0).
    cell_replica : numpy.ndarray (n_cells,)
        Replica of each cell.
    radius : numpy.ndarray (n_replicas,), optional
        Sphere radius of each replica; None on the periodic plane.
    box : numpy.ndarray (n_replicas, 2), optional
        Periodic box (Lx, Ly) of each replica on the plane; None on a sphere."""
    times: np.ndarray
    centroids: np.ndarray
    cell_replica: np.ndarray
    radius: np.ndarray = None
    box: np.ndarray = None
    replica_order: np.ndarray = field(default=None, init=False, repr=False, compare=False)
    replica_starts: np.ndarray = field(default=None, init=False, repr=False, compare=False)
    _unwrapped: np.ndarray = field(default=None, init=False, repr=False, compare=False)

    def __post_init__(self):
        self.times = np.asarray(self.times, dtype=np.float64).reshape(-1)
        self.centroids = np.asarray(self.centroids, dtype=np.float64)
        self.cell_replica = np.asarray(self.cell_replica, dtype=np.int64).reshape(-1)
        if (self.radius is None) == (self.box is None):
            raise ValueError("give the radius (sphere) or the box (periodic plane) of each replica, not "
                             f"{'both' if self.box is not None else 'neither'}")
        if self.box is not None:
            self.box = np.asarray(self.box, dtype=np.float64)
            if self.box.ndim == 1 and self.box.shape == (2,):
                self.box = self.box[None, :]
        else:
            self.radius = np.atleast_1d(np.asarray(self.radius, dtype=np.float64))
        T = len(self.times)
        if self.centroids.ndim != 3 or self.centroids.shape[2] != 3 or self.centroids.shape[0] != T:
            raise ValueError(f"centroids must have shape (len(times), n_cells, 3) = ({T}, n_cells, 3), "
                             f"got {self.centroids.shape}")
        if T < 1:
            raise ValueError("a Trajectory needs at least one frame")
        if np.any(np.diff(self.times) <= 0):
            raise ValueError("times must increase strictly")
        if self.cell_replica.shape != (self.centroids.shape[1],):
            raise ValueError(f"cell_replica must have one entry per cell ({self.centroids.shape[1]}), "
                             f"got shape {self.cell_replica.shape}")
        if len(self.cell_replica) and self.cell_replica.min() < 0:
            raise ValueError("cell_replica must be non-negative")
        n_rep = int(self.cell_replica.max()) + 1 if len(self.cell_replica) else 0
        if self.box is not None:
            if self.box.shape != (n_rep, 2):
                raise ValueError(f"box must have one (Lx, Ly) per replica, shape ({n_rep}, 2), got {self.box.shape}")
            if not np.all(np.isfinite(self.box)) or np.any(self.box <= 0):
                raise ValueError("box must be positive and finite")
        elif self.radius.shape != (n_rep,):
            raise ValueError(f"radius must have one value per replica ({n_rep}), got shape {self.radius.shape}")
        elif not np.all(np.isfinite(self.radius)) or np.any(self.radius <= 0):
            raise ValueError("radius must be positive and finite")
        counts = np.bincount(self.cell_replica, minlength=n_rep)
        if np.any(counts == 0):
            raise ValueError(f"replica {int(np.flatnonzero(counts == 0)[0])} has no cells")
        if not np.all(np.isfinite(self.centroids)):
            raise ValueError("centroids contain NaN or inf")
        self.replica_order, self.replica_starts = _replica_layout(self.cell_replica, n_rep)
        if self.box is not None:
            self._unwrapped = unwrap_trajectory(self.centroids, self.box[self.cell_replica])

    # ------------------------------------------------------------------ surface
    @property
    def planar(self) -> bool:
        """True for a trajectory on the periodic plane (it has a box, no radius)."""
        return self.box is not None

    @property
    def positions(self) -> np.ndarray:
        """(T, n_cells, 3) positions to measure displacements with: the centroids on a sphere, the
        centroids unwrapped across the periodic boundary (continuous in time) on the plane."""
        return self._unwrapped if self.planar else self.centroids

    # ------------------------------------------------------------------ sizes
    @property
    def n_frames(self) -> int:
        return len(self.times)

    def __len__(self):
        return self.n_frames

    @property
    def n_cells(self) -> int:
        return self.centroids.shape[1]

    @property
    def n_replicas(self) -> int:
        return len(self.box) if self.planar else len(self.radius)

    @property
    def cells_per_replica(self) -> np.ndarray:
        return np.bincount(self.cell_replica, minlength=self.n_replicas)

    @property
    def length_unit(self) -> np.ndarray:
        """sqrt(<A>) per replica, with <A> = 4 pi R^2 / N (sphere) or Lx Ly / N (plane): the unit of every
        length the measures return."""
        if self.planar:
            return np.sqrt(self.box[:, 0] * self.box[:, 1] / self.cells_per_replica)
        return np.sqrt(4 * np.pi * self.radius ** 2 / self.cells_per_replica)

    # ------------------------------------------------------------------ builders
    @classmethod
    def from_states(cls, times, states, method: str = "area") -> "Trajectory":
        """A Trajectory from States of the same tissue(s) at the given times (cells never renumbered)."""
        states = list(states)
        times = np.asarray(times, dtype=np.float64).reshape(-1)
        if len(states) != len(times) or not states:
            raise ValueError(f"need one State per time, got {len(states)} states and {len(times)} times")
        first = states[0]
        cents = []
        for k, s in enumerate(states):   # one vectorised centroid computation per frame
            if s.n_cells != first.n_cells or not np.array_equal(s.cell_start, first.cell_start):
                raise ValueError(f"state {k} has {s.n_cells} cells in {s.n_replicas} replicas, frame 0 "
                                 f"{first.n_cells} in {first.n_replicas}: the analysis follows fixed cells")
            cents.append(cell_centroids(s, method=method))
        box = first.box_np()
        if box is not None:
            return cls(times, np.stack(cents), first.cell_replica_np(), box=box)
        return cls(times, np.stack(cents), first.cell_replica_np(), first.radius_np())

    @classmethod
    def from_gsd(cls, path, frames=None, method: str = "area", times: str = "step") -> "Trajectory":
        """Centroids of the frames of a spherevm GSD file (all frames, or ``frames``: a slice or indices).

        ``times="step"`` takes each frame's ``configuration/step`` (timesteps); ``"frame"`` uses the
        frame indices. Each frame's State is restored exactly (:func:`spherevm.init.from_gsd`), so
        the cell topology after T1s is the one of that frame. The file is opened once.
        """
        if times not in ("step", "frame"):
            raise ValueError(f"times must be 'step' or 'frame', got {times!r}")
        with Reader(path) as reader:
            n = len(reader)
            if frames is None:
                idx = np.arange(n)
            elif isinstance(frames, slice):
                idx = np.arange(n)[frames]
            else:
                idx = np.asarray(frames, dtype=np.int64).reshape(-1)
                idx = np.where(idx < 0, idx + n, idx)
                if np.any((idx < 0) | (idx >= n)):
                    raise IndexError(f"frames must lie in 0..{n - 1} (or -{n}..-1) for {path!r}")
            if len(idx) == 0:
                raise ValueError(f"no frames selected from {path!r} ({n} frames)")
            t = (np.array([reader.step(int(i)) for i in idx], dtype=np.float64) if times == "step"
                 else idx.astype(np.float64))
            return cls.from_states(t, [reader.state(int(i)) for i in idx], method=method)

    @classmethod
    def from_recording(cls, recording, dt: float = None) -> "Trajectory":
        """A Trajectory from a :class:`~spherevm.plugins.writers.Recorder` or the
        :class:`~spherevm.plugins.writers.recorder.Recording` it returns or reads from its CSV.

        Times are the recorded timesteps, or ``timestep * dt`` if ``dt`` is given.
        """
        if isinstance(recording, Recorder):
            recording = recording.recording()
        times = np.asarray(recording.timesteps, dtype=np.float64)
        if dt is not None:
            if not np.isfinite(dt) or dt <= 0:
                raise ValueError(f"dt must be positive and finite, got {dt!r}")
            times = times * dt
        box = getattr(recording, "box", None)
        if box is not None:
            return cls(times, recording.centroids, recording.cell_replica, box=box)
        return cls(times, recording.centroids, recording.cell_replica, recording.radius)

    # ------------------------------------------------------------------ helpers
    def without_rotation(self, reference: int = 0) -> "Trajectory":
        """A copy in which every frame is rigidly rotated (per replica) onto frame ``reference``.

        For viewing and for custom analyses; the measures below remove the rotation pair by pair.
        Sphere only: a periodic plane has no rigid rotation (its zero modes are the two translations,
        see :meth:`without_drift`), so this raises ValueError there.
        """
        if self.planar:
            raise ValueError("without_rotation: a trajectory on the periodic plane has no rigid rotation to remove "
                             "(the box is not rotation invariant; its zero modes are the translations): use "
                             "without_drift() or remove_drift=True in the measures")
        ref = self.centroids[reference]
        return Trajectory(self.times.copy(), remove_rigid_rotation(ref, self.centroids, self.cell_replica),
                          self.cell_replica.copy(), self.radius.copy())


    def without_drift(self, reference: int = 0) -> "Trajectory":
        """Plane only: a copy in which every frame is translated (per replica) so that the mean
        unwrapped displacement of the replica's cells from frame ``reference`` is zero (centroids
        wrapped back into the box). The measures do the same pair by pair with ``remove_drift``."""
        if not self.planar:
            raise ValueError("without_drift: a tissue on a sphere has no centre-of-mass drift (the centre is fixed); "
                             "use without_rotation()")
        pos = self._unwrapped
        shift = replica_mean(pos - pos[reference], self.cell_replica, self.replica_order, self.replica_starts)
        moved = pos - shift[:, self.cell_replica, :]
        out = moved.copy()
        out[..., :2] = _wrap(np, moved[..., :2], self.box[self.cell_replica])
        return Trajectory(self.times.copy(), out, self.cell_replica.copy(), box=self.box.copy())


def unwrap_trajectory(centroids, box_per_cell):
    """Positions (T, n, 3) continuous in time: frame 0 as stored, then the cumulative sum of the
    minimum images of the frame-to-frame displacements (``box_per_cell`` (n, 2))."""
    out = np.array(centroids, dtype=np.float64, copy=True)
    if len(out) > 1:
        step = minimum_image(np.diff(out[..., :2], axis=0), box_per_cell)
        out[1:, :, :2] = out[0, :, :2] + np.cumsum(step, axis=0)
    return out


def replica_mean(values, cell_replica, order=None, starts=None):
    """The mean of ``values (..., n_cells, k)`` over the cells of each replica: ``(..., n_replicas, k)``."""
    rep = np.asarray(cell_replica, dtype=np.int64)
    if starts is None:
        order, starts = _replica_layout(rep, int(rep.max()) + 1)
    counts = np.diff(np.append(starts, len(rep)))
    v = np.moveaxis(values, -1, -2)                                     # (..., k, n_cells)
    return np.moveaxis(_replica_sum(v, order, starts), -1, -2) / counts[:, None]


def _replica_layout(cell_replica, n_rep):
    """Sort order of cells by replica (None when already sorted) and the start of each replica."""
    order = None if np.all(np.diff(cell_replica) >= 0) else np.argsort(cell_replica, kind="stable")
    counts = np.bincount(cell_replica, minlength=n_rep)
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]]).astype(np.int64)
    return order, starts


def _replica_sum(values, order, starts):
    """Sum ``values (..., n_cells)`` over the cells of each replica: ``(..., n_replicas)``."""
    if order is not None:
        values = values[..., order]
    return np.add.reduceat(values, starts, axis=-1)


# ======================================================================================== rotation
def remove_rigid_rotation(reference, current, cell_replica, return_rotation: bool = False):
    """Rotate each replica of ``current`` rigidly onto ``reference``.

    For every replica r the proper rotation ``Q_r`` (det +1) about the sphere's centre that
    minimises ``sum_i |Q_r c_i - ref_i|^2`` (Kabsch: SVD of ``H = sum_i c_i ref_i^T = U S V^T``,
    ``Q = V diag(1, 1, d) U^T``, ``d = sign det(V U^T)``) is applied to ``current``; all replicas
    and leading indices in one batched ``np.linalg.svd``. No translation.

    Parameters
    ----------
    reference : numpy.ndarray (n_cells, 3) or (..., n_cells, 3)
    current : numpy.ndarray (..., n_cells, 3)
        Broadcast against ``reference`` (e.g. all frames of a trajectory onto one reference).
    cell_replica : numpy.ndarray (n_cells,)
    return_rotation : bool
        Also return ``Q``, shape ``(..., n_replicas, 3, 3)``.

    Returns
    -------
    numpy.ndarray, or (numpy.ndarray, numpy.ndarray)
        The rotated positions (and ``Q``)."""
    ref = np.asarray(reference, dtype=np.float64)
    cur = np.asarray(current, dtype=np.float64)
    rep = np.asarray(cell_replica, dtype=np.int64).reshape(-1)
    if ref.shape[-1] != 3 or cur.shape[-1] != 3 or ref.shape[-2] != len(rep) or cur.shape[-2] != len(rep):
        raise ValueError(f"reference {ref.shape} and current {cur.shape} must end in (n_cells, 3) with "
                         f"n_cells = len(cell_replica) = {len(rep)}")
    n_rep = int(rep.max()) + 1
    order, starts = _replica_layout(rep, n_rep)
    sizes = np.diff(np.append(starts, len(rep)))
    if np.any(sizes == 0):
        raise ValueError("every replica index 0..max(cell_replica) must have cells")
    equal = order is None and np.all(sizes == sizes[0])
    if equal:   # the usual ensemble: contiguous replicas of equal size, batched BLAS products
        m = int(sizes[0])
        ref_r = ref.reshape(ref.shape[:-2] + (n_rep, m, 3))
        cur_r = cur.reshape(cur.shape[:-2] + (n_rep, m, 3))
        H = np.swapaxes(cur_r, -1, -2) @ ref_r                              # (..., n_rep, 3, 3)
    else:       # H[..., r, a, b] = sum over the cells of replica r of cur[a] ref[b]
        outer = cur[..., :, :, None] * ref[..., :, None, :]                 # (..., n_cells, 3, 3)
        outer = np.moveaxis(outer.reshape(outer.shape[:-2] + (9,)), -2, -1)  # (..., 9, n_cells)
        H = _replica_sum(outer, order, starts)                                # (..., 9, n_rep)
        H = np.moveaxis(H, -1, -2).reshape(H.shape[:-2] + (n_rep, 3, 3))
    U, _, Vt = np.linalg.svd(H)
    V = np.swapaxes(Vt, -1, -2)
    d = np.sign(np.linalg.det(V) * np.linalg.det(U))
    d = np.where(d == 0, 1.0, d)
    V = V.copy()
    V[..., :, 2] *= d[..., None]
    Q = V @ np.swapaxes(U, -1, -2)                                        # (..., n_rep, 3, 3)
    if equal:
        rotated = (cur_r @ np.swapaxes(Q, -1, -2)).reshape(np.broadcast_shapes(Q.shape[:-3], cur.shape[:-2])
                                                          + cur.shape[-2:])
    else:
        Qc = np.broadcast_to(Q, np.broadcast_shapes(Q.shape[:-3], cur.shape[:-2]) + Q.shape[-3:])
        Qg = Qc[..., rep, :, :]                                           # (..., n_cells, 3, 3)
        rotated = (Qg[..., 0] * cur[..., None, 0] + Qg[..., 1] * cur[..., None, 1]
                   + Qg[..., 2] * cur[..., None, 2])
    return (rotated, Q) if return_rotation else rotated
