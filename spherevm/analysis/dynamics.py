"""Glassy dynamics of cells on a sphere: centroids, MSD, self-overlap Q_s, F_s(q, t) and tau_alpha.

The paper ("Finite temperature dynamics") measures the relaxation of a tissue by the self-overlap

    Q_s(t) = (1/N) sum_i w(|r_i(t) - r_i(0)|),   w(r) = 1 if r <= b else 0,   b = 1/2,

and takes tau_alpha as the time at which Q_s falls to 1/e. This module computes it, together with
the mean squared displacement and the self-intermediate scattering function, from a
:class:`Trajectory` of cell centroids (read from a GSD file, built from States, or recorded on a
live Simulation with :class:`spherevm.analysis.recorder.Recorder`). See ``docs/analysis.md``.

Conventions
-----------
* Positions are cell centroids on the sphere (:func:`cell_centroids`). Cells keep their index for
  the whole run (a T1 changes which vertices a cell owns, never its number), so cell ``i`` of frame
  ``t`` is cell ``i`` of frame 0.
* Lengths are in units of ``sqrt(<A>)`` of each replica (``<A> = 4 pi R^2 / N``) unless
  ``scaled=False``; a tiling with the default radius ``sqrt(N / 4 pi)`` has ``<A> = 1``, so the two
  agree. Times are the trajectory's times as given (timesteps, or whatever was passed).
* Every measure can first remove the global rigid rotation of each tissue (``remove_rotation``,
  on by default): a closed tissue on a sphere has three zero modes, its rigid rotations, and noise
  makes it diffuse as a whole; measured in the lab frame, that diffusion decorrelates Q_s without
  any cell leaving its cage. The best proper rotation about the centre (Kabsch) between the two
  configurations of each pair ``(r(t0), r(t0 + t))`` is removed, per replica.
* Averages run over every cell of every replica (replicas of equal size weigh equally); the
  per-replica curves come along in :attr:`TimeCorrelation.per_replica`.
"""
from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field

import numpy as np

CENTROID_METHODS = ("area", "vertex")


# ======================================================================================== centroids
def cell_centroids(state, method: str = "area"):
    """Cell positions on the sphere, ``(n_cells, 3)`` NumPy float64, each at distance R from the centre.

    ``method="area"`` (default): the centre of mass of the spherical polygon, pushed radially onto
    the sphere. The surface integral of the unit normal over a spherical polygon is exact and
    cheap: closing the polygon with the planar sectors (centre, edge arc) gives a closed surface,
    so ``integral of n dA = (R^2 / 2) sum_edges theta_e (a_e x b_e) / |a_e x b_e|`` over the edges
    ``a_e -> b_e`` taken counter-clockwise, ``theta_e`` the arc angle. The centroid direction is
    that vector, normalised.

    ``method="vertex"``: ``R`` times the normalised mean of the unit vertex directions
    (:meth:`spherevm.constraints.Sphere.cell_centers`).

    Why "area" is the default: the vertex centroid depends on how the vertices are spread along the
    boundary, not only on the cell's shape, and it jumps at every T1. Just before a T1 the short
    edge's two vertices almost coincide and count twice in the two cells that lose the edge; after
    the flip they count once, so the vertex centroid of an n-sided cell jumps by about
    ``|r_edge - r_cell| / n``, roughly 0.08 sqrt(<A>) for a hexagon, a spurious displacement in
    every T1 that a cage plateau of the MSD (around 0.01 <A> in a glass) would feel. The area
    centroid is continuous through a T1: flipping a vanishing edge barely changes the polygon.

    A cell folded over (non-positive area, allowed at kA = 0) has no meaningful area centroid (its
    area vector vanishes or points inward); such cells fall back to the vertex centroid.

    Works on either device (the sums run where the state lives); only the Sphere is supported.
    """
    from ..constraints import Sphere
    if method not in CENTROID_METHODS:
        raise ValueError(f"method must be one of {CENTROID_METHODS}, got {method!r}")
    if not isinstance(state.constraint, Sphere):
        raise NotImplementedError(f"cell_centroids supports the Sphere constraint only, got "
                                  f"{type(state.constraint).__name__}")
    xp = state.device.xp
    pos = state.positions
    unit = pos / xp.sqrt((pos * pos).sum(axis=1))[:, None]
    cells = state.vertex_cells.reshape(-1)            # corner k of vertex v lies in cell vertex_cells[v, k]
    n = state.n_cells

    def per_cell(w):                                  # w: (V, 3 corners, 3 components)
        return xp.stack([xp.bincount(cells, weights=w[..., i].reshape(-1), minlength=n) for i in range(3)],
                        axis=1)

    vertex_centroid = state.constraint.cell_centers(state)
    direction = vertex_centroid
    if method == "area":
        a = unit[:, None, :]
        b = unit[state.vertex_neighbors]               # edge v -> vertex_neighbors[v, k] runs CCW in that cell
        cr = xp.cross(a, b)
        s = xp.sqrt((cr * cr).sum(axis=-1))
        theta = xp.arctan2(s, (a * b).sum(axis=-1))
        factor = xp.where(s > 0, theta / xp.where(s > 0, s, 1.0), 1.0)
        area_vec = per_cell(cr * factor[..., None])    # = 2 * integral of n over the cell (unit sphere)
        ok = (area_vec * vertex_centroid).sum(axis=1) > 0
        direction = xp.where(ok[:, None], area_vec, vertex_centroid)
    direction = direction / xp.sqrt((direction * direction).sum(axis=1))[:, None]
    out = state.radius[state.cell_replica][:, None] * direction
    return np.asarray(state.device.to_numpy(out), dtype=np.float64)


# ======================================================================================== trajectory
@dataclass(eq=False)
class Trajectory:
    """Cell centroids over time, for one tissue or an ensemble of replicas.

    times : (T,) sampling times (timesteps, or times in any unit), increasing.
    centroids : (T, n_cells, 3) cell positions on the sphere of each replica.
    cell_replica : (n_cells,) replica of each cell.
    radius : (n_replicas,) sphere radius of each replica.
    """
    times: np.ndarray
    centroids: np.ndarray
    cell_replica: np.ndarray
    radius: np.ndarray
    _order: np.ndarray = field(default=None, init=False, repr=False, compare=False)
    _starts: np.ndarray = field(default=None, init=False, repr=False, compare=False)

    def __post_init__(self):
        self.times = np.asarray(self.times, dtype=np.float64).reshape(-1)
        self.centroids = np.asarray(self.centroids, dtype=np.float64)
        self.cell_replica = np.asarray(self.cell_replica, dtype=np.int64).reshape(-1)
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
        if self.radius.shape != (n_rep,):
            raise ValueError(f"radius must have one value per replica ({n_rep}), got shape {self.radius.shape}")
        if not np.all(np.isfinite(self.radius)) or np.any(self.radius <= 0):
            raise ValueError("radius must be positive and finite")
        counts = np.bincount(self.cell_replica, minlength=n_rep)
        if np.any(counts == 0):
            raise ValueError(f"replica {int(np.flatnonzero(counts == 0)[0])} has no cells")
        if not np.all(np.isfinite(self.centroids)):
            raise ValueError("centroids contain NaN or inf")
        self._order, self._starts = _replica_layout(self.cell_replica, n_rep)

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
        return len(self.radius)

    @property
    def cells_per_replica(self) -> np.ndarray:
        return np.bincount(self.cell_replica, minlength=self.n_replicas)

    @property
    def length_unit(self) -> np.ndarray:
        """sqrt(<A>) per replica, with <A> = 4 pi R^2 / N: the unit of every length the measures return."""
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
        return cls(times, np.stack(cents), first.cell_replica_np(), first.radius_np())

    @classmethod
    def from_gsd(cls, path, frames=None, method: str = "area", times: str = "step") -> "Trajectory":
        """Centroids of the frames of a spherevm GSD file (all frames, or ``frames``: a slice or indices).

        ``times="step"`` takes each frame's ``configuration/step`` (timesteps); ``"frame"`` uses the
        frame indices. Each frame's State is restored exactly (``State.from_gsd``), so the cell
        topology after T1s is the one of that frame.
        """
        import gsd.hoomd
        from ..state import State
        with gsd.hoomd.open(path, "r") as traj:
            n = len(traj)
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
            if times == "step":
                t = np.array([traj[int(i)].configuration.step for i in idx], dtype=np.float64)
            elif times == "frame":
                t = idx.astype(np.float64)
            else:
                raise ValueError(f"times must be 'step' or 'frame', got {times!r}")
        return cls.from_states(t, (State.from_gsd(path, frame=int(i)) for i in idx), method=method)

    # ------------------------------------------------------------------ helpers
    def without_rotation(self, reference: int = 0) -> "Trajectory":
        """A copy in which every frame is rigidly rotated (per replica) onto frame ``reference``.

        For viewing and for custom analyses; the measures below remove the rotation pair by pair.
        """
        ref = self.centroids[reference]
        return Trajectory(self.times.copy(), remove_rigid_rotation(ref, self.centroids, self.cell_replica),
                          self.cell_replica.copy(), self.radius.copy())


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
    """Rotate each replica of ``current`` rigidly onto ``reference``; returns the rotated positions.

    For every replica r (cells ``cell_replica == r``) the proper rotation ``Q_r`` (det +1) about the
    sphere's centre that minimises ``sum_i |Q_r c_i - ref_i|^2`` (Kabsch: SVD of
    ``H = sum_i c_i ref_i^T = U S V^T``, ``Q = V diag(1, 1, d) U^T``, ``d = sign det(V U^T)``) is
    applied to ``current``. No translation: the sphere's centre is fixed.

    ``reference`` is ``(n_cells, 3)`` or ``(..., n_cells, 3)``, ``current`` ``(..., n_cells, 3)``
    (broadcast against each other, e.g. all frames of a trajectory onto one reference). All
    replicas and leading indices are solved in one batched ``np.linalg.svd``.
    ``return_rotation=True`` also returns ``Q`` with shape ``(..., n_replicas, 3, 3)``.
    """
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


# ======================================================================================== correlations
@dataclass(eq=False)
class TimeCorrelation:
    """A time-correlation function: ``value[k]`` at lag ``lag[k]``, averaged over cells and replicas.

    per_replica : (n_lags, n_replicas) the same average within each replica.
    count : (n_lags,) number of time origins that contributed to each lag.
    ``lag, value = result`` unpacks the two main arrays.
    """
    lag: np.ndarray
    value: np.ndarray
    per_replica: np.ndarray
    count: np.ndarray
    name: str = ""

    def __iter__(self):
        return iter((self.lag, self.value))

    def tau_alpha(self, level: float = 1 / math.e, per_replica: bool = False, interpolation: str = "log"):
        """:func:`tau_alpha` of this curve (of each replica's with ``per_replica=True``)."""
        return tau_alpha(self.lag, self.per_replica if per_replica else self.value, level=level,
                         interpolation=interpolation, _stacklevel=3)


def _origin_frames(origins, n):
    if isinstance(origins, str):
        if origins == "first":
            return np.array([0])
        if origins == "all":
            return np.arange(n)
        raise ValueError(f"origins must be 'first', 'all' or a sequence of frame indices, got {origins!r}")
    idx = np.unique(np.asarray(origins, dtype=np.int64).reshape(-1))
    if len(idx) == 0 or idx.min() < -n or idx.max() >= n:
        raise ValueError(f"origins must be frame indices in 0..{n - 1}, got {origins!r}")
    return np.unique(np.where(idx < 0, idx + n, idx))


def _displacements(traj, origin, remove_rotation, geodesic, scaled):
    """Distances ``(T - origin, n_cells)`` of every cell between frame ``origin`` and each later frame."""
    rep = traj.cell_replica
    ref = traj.centroids[origin]
    cur = traj.centroids[origin:]
    if remove_rotation:
        cur = remove_rigid_rotation(ref, cur, rep)
    if geodesic:
        a = ref / np.linalg.norm(ref, axis=-1)[:, None]
        b = cur / np.linalg.norm(cur, axis=-1)[..., None]
        d = traj.radius[rep] * 2.0 * np.arctan2(np.linalg.norm(a - b, axis=-1), np.linalg.norm(a + b, axis=-1))
    else:
        d = np.linalg.norm(cur - ref, axis=-1)
    if scaled:
        d = d / traj.length_unit[rep]
    d[0] = 0.0   # the origin against itself (the fitted rotation is the identity only to rounding)
    return d


def _correlate(traj, func, origins, remove_rotation, geodesic, scaled, name):
    """Average ``func(distance)`` over cells, per replica and over all, for every lag of the pairs."""
    if not isinstance(traj, Trajectory):
        raise TypeError(f"expected a spherevm.analysis.Trajectory, got {type(traj).__name__}")
    T = traj.n_frames
    t = traj.times
    frames = _origin_frames(origins, T)
    if isinstance(origins, str) and origins == "first":
        keys = np.arange(T)
        lags_unique = t - t[0]
        inverse = {0: keys}
    else:
        scale = 1e-9 * max(float(np.abs(t).max()), 1e-300)
        all_lags = [t[i:] - t[i] for i in frames]
        keys_all = np.round(np.concatenate(all_lags) / scale).astype(np.int64)
        uniq, inv = np.unique(keys_all, return_inverse=True)
        inv = inv.reshape(-1)
        # each group's lag: the mean of its (equal up to rounding) members
        lags_unique = np.bincount(inv, weights=np.concatenate(all_lags)) / np.bincount(inv)
        inverse, pos = {}, 0
        for i, lags in zip(frames, all_lags):
            inverse[int(i)] = inv[pos:pos + len(lags)]
            pos += len(lags)
    n_rep = traj.n_replicas
    sums = np.zeros((len(lags_unique), n_rep))
    count = np.zeros(len(lags_unique), dtype=np.int64)
    cells = traj.cells_per_replica
    for i in frames:                     # loop over time origins; each is vectorised over lags and cells
        d = _displacements(traj, int(i), remove_rotation, geodesic, scaled)
        per_rep = _replica_sum(func(d), traj._order, traj._starts) / cells
        np.add.at(sums, inverse[int(i)], per_rep)
        np.add.at(count, inverse[int(i)], 1)
    per_replica = sums / count[:, None]
    value = (per_replica * cells).sum(axis=1) / cells.sum()
    return TimeCorrelation(lag=np.asarray(lags_unique, dtype=np.float64), value=value,
                           per_replica=per_replica, count=count, name=name)


def msd(traj, remove_rotation: bool = True, geodesic: bool = False, origins="first",
        scaled: bool = True) -> TimeCorrelation:
    """Mean squared displacement ``<|r_i(t0 + t) - r_i(t0)|^2>`` of the cell centroids.

    geodesic : False for the chord (straight 3D distance, the paper's ``|r_i(t) - r_i(0)|``), True
        for the arc length on the sphere. Both saturate at long times: the chord at ``2 R``, the
        arc at ``pi R`` (the mean over a uniform sphere is ``2 R^2`` for the chord squared).
    origins : ``"first"`` (lags from frame 0 only; suits log-spaced sampling), ``"all"`` (every pair
        of frames ``t0 <= t1``, grouped by equal lag ``t1 - t0``) or a sequence of origin frames.
    remove_rotation : remove each replica's rigid rotation between the two frames first.
    scaled : lengths in units of ``sqrt(<A>)`` per replica (default) rather than simulation units.
    """
    return _correlate(traj, np.square, origins, remove_rotation, geodesic, scaled, "msd")


def self_overlap(traj, b: float = 0.5, geodesic: bool = False, remove_rotation: bool = True, origins="first",
                 scaled: bool = True) -> TimeCorrelation:
    """Self-overlap ``Q_s(t)``: the fraction of cells displaced by at most ``b`` (paper: ``b = 1/2``).

    ``w(d) = 1`` for ``d <= b``, else 0, on the chord ``|r_i(t) - r_i(0)|`` (or the arc with
    ``geodesic=True``), in units of ``sqrt(<A>)``. Other arguments as in :func:`msd`.
    """
    if not np.isfinite(b) or b <= 0:
        raise ValueError(f"b must be positive and finite, got {b!r}")
    return _correlate(traj, lambda d: (d <= b).astype(np.float64), origins, remove_rotation, geodesic, scaled,
                      "self_overlap")


def self_intermediate_scattering(traj, q: float = 2 * np.pi, remove_rotation: bool = True, average: str = "2d",
                                 geodesic: bool = False, origins="first", scaled: bool = True) -> TimeCorrelation:
    """Self-intermediate scattering function ``F_s(q, t) = < exp(i q . (r_i(t) - r_i(0))) >``.

    The average over the directions of ``q`` makes it a function of ``d = |dr|`` only:

    * ``average="2d"`` (default): ``J0(q d)``, the average of ``exp(i q . u)`` over ``q`` uniform in
      a plane containing ``u``. Cells move on the surface, so a displacement lies in the tangent
      plane at ``r_i(0)`` up to a radial part ``d^2 / 2R`` (second order), and the physically
      meaningful wave vectors are the tangent ones: the 2D average is the right one, as for a flat
      monolayer. At a given ``q`` it decays faster than the 3D one (``J0(x) ~ 1 - x^2/4`` against
      ``1 - x^2/6``).
    * ``average="3d"``: ``sin(q d) / (q d)``, the average over all directions in space.

    ``q`` in units of ``1/sqrt(<A>)``; the default ``2 pi`` is a wavelength of one cell length, near
    the first peak of the cells' structure factor (``4 pi / (sqrt 3 a) = 6.75`` for a hexagonal
    tiling of unit-area cells, spacing ``a = 1.075``), the usual choice for alpha relaxation.
    ``d`` is the chord, or the arc length with ``geodesic=True``. Other arguments as in :func:`msd`.
    """
    if not np.isfinite(q) or q <= 0:
        raise ValueError(f"q must be positive and finite, got {q!r}")
    if average == "2d":
        from scipy.special import j0
        func = lambda d: j0(q * d)  # noqa: E731
    elif average == "3d":
        func = lambda d: np.sinc(q * d / np.pi)  # noqa: E731  (np.sinc(x) = sin(pi x) / (pi x))
    else:
        raise ValueError(f"average must be '2d' (J0, tangent wave vectors) or '3d' (sin x / x), got {average!r}")
    return _correlate(traj, func, origins, remove_rotation, geodesic, scaled, "self_intermediate_scattering")


# ======================================================================================== tau_alpha
class NoRelaxationWarning(RuntimeWarning):
    """tau_alpha could not be measured: the curve never crossed the level inside the data."""


def tau_alpha(times, q_s=None, level: float = 1 / math.e, interpolation: str = "log", warn: bool = True,
              _stacklevel: int = 2):
    """The first time at which ``q_s`` falls to ``level`` (default ``1/e``), interpolated.

    ``times`` and ``q_s`` are arrays of equal length (``q_s`` may be ``(T, k)``: one tau per column),
    or pass a :class:`TimeCorrelation` alone. With the first sample ``k`` at which ``q_s <= level``,
    the crossing is interpolated between samples ``k - 1`` and ``k``, linearly in the value and

    * ``interpolation="log"`` (default) linearly in ``log t``: the natural variable for log-spaced
      sampling, and accurate where it matters: for ``exp(-t/tau)`` the curve against ``log t`` has
      its inflection point exactly at ``t = tau``, so the interpolation error is third order in the
      spacing. Falls back to linear in ``t`` for an interval starting at ``t <= 0``.
    * ``interpolation="linear"``: linearly in ``t``.

    Returns a float (or an array per column). NaN where the curve never reaches the level (the
    run is too short: no alpha relaxation observed) or is already below it at the first sample;
    a :class:`NoRelaxationWarning` says which, unless ``warn=False``.
    """
    if isinstance(times, TimeCorrelation) and q_s is None:
        times, q_s = times.lag, times.value
    t = np.asarray(times, dtype=np.float64).reshape(-1)
    q = np.asarray(q_s, dtype=np.float64)
    if interpolation not in ("log", "linear"):
        raise ValueError(f"interpolation must be 'log' or 'linear', got {interpolation!r}")
    if q.shape[0] != len(t) or q.ndim not in (1, 2):
        raise ValueError(f"q_s must have shape ({len(t)},) or ({len(t)}, k), got {q.shape}")
    if len(t) == 0:
        raise ValueError("times is empty")
    if np.any(np.diff(t) <= 0):
        raise ValueError("times must increase strictly")
    cols = q.reshape(len(t), -1)
    out = np.full(cols.shape[1], np.nan)
    never, early = [], []
    for j in range(cols.shape[1]):  # one search per curve
        c = cols[:, j]
        below = np.flatnonzero(c <= level)
        if len(below) == 0:
            never.append(j)
            continue
        k = int(below[0])
        if k == 0:
            early.append(j)
            continue
        t0, t1, y0, y1 = t[k - 1], t[k], c[k - 1], c[k]
        f = (y0 - level) / (y0 - y1) if y0 != y1 else 1.0
        if interpolation == "log" and t0 > 0:
            out[j] = math.exp(math.log(t0) + f * (math.log(t1) - math.log(t0)))
        else:
            out[j] = t0 + f * (t1 - t0)
    if warn and (never or early):
        which = "" if q.ndim == 1 else " (curves {})"
        if never:
            low = np.nanmin(cols[:, never])
            warnings.warn(f"Q_s never fell to {level:.4g}{which.format(never)} (lowest {low:.4g}, last t = "
                          f"{t[-1]:g}): no alpha relaxation in the data, tau_alpha = NaN; run longer",
                          NoRelaxationWarning, stacklevel=_stacklevel)
        if early:
            warnings.warn(f"Q_s is already <= {level:.4g} at the first sample t = {t[0]:g}{which.format(early)}: "
                          "tau_alpha lies before the data, NaN; sample earlier times",
                          NoRelaxationWarning, stacklevel=_stacklevel)
    return float(out[0]) if q.ndim == 1 else out


# ======================================================================================== sampling
def log_spaced_times(t_max: int, points_per_decade: int = 10, t_min: int = 1, include_zero: bool = True) -> np.ndarray:
    """Sorted unique integer timesteps, about ``points_per_decade`` per decade from ``t_min`` to ``t_max``.

    The points ``t_min * 10^(k / points_per_decade)`` rounded to integers (duplicates at small t
    dropped, so the first decades hold every integer), always including ``t_min`` and ``t_max``,
    plus 0 (the time origin) when ``include_zero``. Feed them to
    :class:`spherevm.analysis.recorder.Recorder` (add the current timestep for a run not starting at 0).
    """
    for name, v in (("t_max", t_max), ("t_min", t_min), ("points_per_decade", points_per_decade)):
        if isinstance(v, bool) or int(v) != v or v < 1:
            raise ValueError(f"{name} must be a positive integer, got {v!r}")
    t_max, t_min, ppd = int(t_max), int(t_min), int(points_per_decade)
    if t_max < t_min:
        raise ValueError(f"t_max ({t_max}) must be >= t_min ({t_min})")
    n = int(math.floor(ppd * math.log10(t_max / t_min) + 1e-9))
    pts = np.rint(t_min * 10.0 ** (np.arange(n + 1) / ppd)).astype(np.int64)
    pts = np.concatenate([[0] if include_zero else [], [t_min], pts, [t_max]]).astype(np.int64)
    pts = pts[(pts <= t_max) & ((pts >= t_min) | (include_zero & (pts == 0)))]
    return np.unique(pts)
