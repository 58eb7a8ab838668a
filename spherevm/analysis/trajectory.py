"""Cell centroids over time (:class:`Trajectory`) and the removal of each tissue's rigid rotation
(on a sphere) or centre-of-mass drift (on the periodic plane): the surface's rigid motions.

A Trajectory is built from States, from a spherevm GSD file or from a Recorder's
:class:`~spherevm.plugins.writers.recorder.Recording`; :mod:`spherevm.analysis.dynamics` measures it.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..constraints import Constraint, surface_for_key
from ..gsdio import Reader
from ..plugins.writers.recorder import Recorder
from ..shapes import cell_centroids


# ======================================================================================== trajectory
@dataclass(eq=False)
class Trajectory:
    """Cell centroids over time, for one tissue or an ensemble of replicas.

    On a periodic surface (the plane) the centroids are unwrapped across the boundary
    (:attr:`positions`, :meth:`~spherevm.constraints.Constraint.unwrap_path`): each frame-to-frame
    displacement is taken as its minimum image and summed from frame 0, so a cell that leaves the
    box on one side keeps its true displacement. This needs every cell to move less than half the
    box between consecutive frames (sample often enough).

    Parameters
    ----------
    times : numpy.ndarray (T,)
        Sampling times (timesteps, or times in any unit), increasing.
    centroids : numpy.ndarray (T, n_cells, 3)
        Cell positions on the surface of each replica (on the plane stored wrapped, z = 0).
    cell_replica : numpy.ndarray (n_cells,)
        Replica of each cell.
    radius : numpy.ndarray (n_replicas,), optional
        Sphere radius of each replica (the surface then a :class:`~spherevm.constraints.Sphere`).
    box : numpy.ndarray (n_replicas, 2), optional
        Periodic box (Lx, Ly) of each replica (a :class:`~spherevm.constraints.PeriodicPlane`).
    constraint : Constraint, optional
        The surface, with ``size``; or the surface whose size ``radius`` or ``box`` is.
    size : numpy.ndarray, ``(n_replicas,) + constraint.size_shape``, optional
        Each replica's surface size (``State.size``), instead of ``radius`` or ``box``."""
    times: np.ndarray
    centroids: np.ndarray
    cell_replica: np.ndarray
    radius: np.ndarray = None
    box: np.ndarray = None
    constraint: Constraint = None
    size: np.ndarray = None
    replica_order: np.ndarray = field(default=None, init=False, repr=False, compare=False)
    replica_starts: np.ndarray = field(default=None, init=False, repr=False, compare=False)
    _unwrapped: np.ndarray = field(default=None, init=False, repr=False, compare=False)

    def __post_init__(self):
        self.times = np.asarray(self.times, dtype=np.float64).reshape(-1)
        self.centroids = np.asarray(self.centroids, dtype=np.float64)
        self.cell_replica = np.asarray(self.cell_replica, dtype=np.int64).reshape(-1)
        given = [k for k in ("radius", "box", "size") if getattr(self, k) is not None]
        if len(given) != 1:
            raise ValueError("give the radius (sphere) or the box (periodic plane) of each replica, or a constraint "
                             f"and its size, once; got {', '.join(given) or 'neither'}")
        key = given[0]
        if self.constraint is None:
            if key == "size":
                raise ValueError("size is given without its constraint: pass constraint= too")
            self.constraint = surface_for_key(key)
        self.size = np.asarray(getattr(self, key), dtype=np.float64)
        shape = tuple(self.constraint.size_shape)
        if self.size.shape == shape:            # one size: one replica
            self.size = self.size[None]
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
        if self.size.shape != (n_rep,) + shape:
            raise ValueError(f"{key} must have one ({', '.join(self.constraint.size_names)}) per replica, shape "
                             f"{(n_rep,) + shape}, got {self.size.shape}")
        self.constraint.check_size(self.size)
        self.radius, self.box = (self.size if self.constraint.size_key == k else None for k in ("radius", "box"))
        counts = np.bincount(self.cell_replica, minlength=n_rep)
        if np.any(counts == 0):
            raise ValueError(f"replica {int(np.flatnonzero(counts == 0)[0])} has no cells")
        if not np.all(np.isfinite(self.centroids)):
            raise ValueError("centroids contain NaN or inf")
        self.replica_order, self.replica_starts = _replica_layout(self.cell_replica, n_rep)
        self._unwrapped = self.constraint.unwrap_path(self.centroids, self.size[self.cell_replica])

    # ------------------------------------------------------------------ surface
    @property
    def positions(self) -> np.ndarray:
        """(T, n_cells, 3) positions to measure displacements with: the centroids, unwrapped across
        the boundary of a periodic surface (continuous in time)."""
        return self._unwrapped

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
        return len(self.size)

    @property
    def cells_per_replica(self) -> np.ndarray:
        return np.bincount(self.cell_replica, minlength=self.n_replicas)

    @property
    def length_unit(self) -> np.ndarray:
        """sqrt(<A>) per replica, with <A> the surface's area over the cells (4 pi R^2 / N on a
        sphere, Lx Ly / N on the plane): the unit of every length the measures return."""
        return np.sqrt(self.constraint.total_area_np(self.size) / self.cells_per_replica)

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
        return cls(times, np.stack(cents), first.cell_replica_np(), constraint=first.constraint, size=first.size_np())

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
        if recording.constraint is not None:
            return cls(times, recording.centroids, recording.cell_replica, constraint=recording.constraint,
                       size=recording.size)
        return cls(times, recording.centroids, recording.cell_replica, recording.radius, recording.box)

    # ------------------------------------------------------------------ helpers
    def _surface_motion(self, motion: str, what: str, instead: str):
        """Refuse a rigid ``motion`` ("translations") the surface does not have."""
        surface_motion(self.constraint, (motion,), what, instead)

    def without_rotation(self, reference: int = 0) -> "Trajectory":
        """A copy in which every frame is rigidly rotated (per replica) onto frame ``reference``.

        For viewing and for custom analyses; the measures below remove the rotation pair by pair.
        Only on a surface with rigid rotations about the origin (the sphere): a periodic plane has
        none (its zero modes are the two translations, see :meth:`without_drift`), so this raises
        ValueError there.
        """
        about_z = surface_motion(self.constraint, ROTATIONS, "without_rotation", "rigid rotation") == "z-rotations"
        ref = self.centroids[reference]
        return Trajectory(self.times.copy(), remove_rigid_rotation(ref, self.centroids, self.cell_replica,
                                                                   about_z=about_z),
                          self.cell_replica.copy(), constraint=self.constraint, size=self.size.copy())

    def without_drift(self, reference: int = 0) -> "Trajectory":
        """On a surface with rigid translations (the periodic plane): a copy in which every frame is
        translated (per replica) so that the mean unwrapped displacement of the replica's cells from
        frame ``reference`` is zero (centroids put back on the surface, wrapped into the box). The
        measures do the same pair by pair with ``remove_drift``."""
        self._surface_motion("translations", "without_drift", "centre-of-mass drift")
        pos = self._unwrapped
        shift = replica_mean(pos - pos[reference], self.cell_replica, self.replica_order, self.replica_starts)
        moved = pos - shift[:, self.cell_replica, :]
        out = self.constraint.project_normal(moved, self.size[self.cell_replica])
        return Trajectory(self.times.copy(), out, self.cell_replica.copy(), constraint=self.constraint,
                          size=self.size.copy())


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
#: the rigid rotations a surface may have (:attr:`~spherevm.constraints.Constraint.rigid_motions`):
#: about any axis through the origin (a sphere), or about the z axis only (a torus)
ROTATIONS = ("rotations", "z-rotations")


def surface_motion(constraint, kinds, what: str, instead: str) -> str:
    """Which of the rigid motions ``kinds`` the surface has (the first); ValueError naming ``what``
    when it has none of them."""
    motions = tuple(constraint.rigid_motions)
    found = [m for m in kinds if m in motions]
    if not found:
        raise ValueError(f"{what}: a trajectory on {constraint!r} has no {instead} to remove (its rigid "
                         f"motions: {', '.join(motions) or 'none'})")
    return found[0]


def remove_rigid_rotation(reference, current, cell_replica, return_rotation: bool = False, about_z: bool = False):
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
    about_z : bool
        Only rotations about the z axis (a torus's rigid motions): the angle ``atan2(H_xy - H_yx,
        H_xx + H_yy)`` of each replica, which minimises the same sum among them.

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
    Q = _about_z(H) if about_z else _kabsch(H)                           # (..., n_rep, 3, 3)
    if equal:
        rotated = (cur_r @ np.swapaxes(Q, -1, -2)).reshape(np.broadcast_shapes(Q.shape[:-3], cur.shape[:-2])
                                                          + cur.shape[-2:])
    else:
        Qc = np.broadcast_to(Q, np.broadcast_shapes(Q.shape[:-3], cur.shape[:-2]) + Q.shape[-3:])
        Qg = Qc[..., rep, :, :]                                           # (..., n_cells, 3, 3)
        rotated = (Qg[..., 0] * cur[..., None, 0] + Qg[..., 1] * cur[..., None, 1]
                   + Qg[..., 2] * cur[..., None, 2])
    return (rotated, Q) if return_rotation else rotated


def _kabsch(H):
    """The proper rotations ``Q`` maximising ``tr(Q H)`` (Kabsch), batched over the leading axes."""
    U, _, Vt = np.linalg.svd(H)
    V = np.swapaxes(Vt, -1, -2)
    d = np.sign(np.linalg.det(V) * np.linalg.det(U))
    d = np.where(d == 0, 1.0, d)
    V = V.copy()
    V[..., :, 2] *= d[..., None]
    return V @ np.swapaxes(U, -1, -2)


def _about_z(H):
    """The rotations about z maximising ``tr(Q H)``, batched over the leading axes."""
    angle = np.arctan2(H[..., 0, 1] - H[..., 1, 0], H[..., 0, 0] + H[..., 1, 1])
    c, s = np.cos(angle), np.sin(angle)
    Q = np.zeros(H.shape)
    Q[..., 0, 0], Q[..., 0, 1], Q[..., 1, 0], Q[..., 1, 1], Q[..., 2, 2] = c, -s, s, c, 1.0
    return Q
