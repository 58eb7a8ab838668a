"""Glassy dynamics of cells on a sphere: MSD, self-overlap Q_s, F_s(q, t) and tau_alpha.

The paper ("Finite temperature dynamics") measures the relaxation of a tissue by the self-overlap

    Q_s(t) = (1/N) sum_i w(|r_i(t) - r_i(0)|),   w(r) = 1 if r <= b else 0,   b = 1/2,

and takes tau_alpha as the time at which Q_s falls to 1/e. This module computes it, together with
the mean squared displacement and the self-intermediate scattering function, from a
:class:`~spherevm.analysis.trajectory.Trajectory` of cell centroids (read from a GSD file, built
from States, or recorded on a live Simulation with :class:`spherevm.plugins.writers.Recorder`). See
``docs/analysis.md``.

Conventions
-----------
* Positions are cell centroids on the sphere (:func:`spherevm.shapes.cell_centroids`). Cells keep their index for
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
* On the periodic plane (a Trajectory with a ``box``) displacements are those of the unwrapped
  centroids (:attr:`Trajectory.positions`: minimum images of the frame-to-frame displacements,
  summed), Euclidean in the plane (``geodesic`` makes no difference). There is no rigid rotation to
  remove (``remove_rotation=True`` raises there); the zero modes are the two translations, and
  ``remove_drift`` (default: on, on the plane) subtracts each replica's mean cell displacement
  between the two frames of every pair, the analogue of the sphere's rotation removal.
* Averages run over every cell of every replica (replicas of equal size weigh equally); the
  per-replica curves come along in :attr:`TimeCorrelation.per_replica`.
"""
from __future__ import annotations

import math
import warnings
from dataclasses import dataclass

import numpy as np

from .trajectory import ROTATIONS, Trajectory, _replica_sum, remove_rigid_rotation, replica_mean, surface_motion


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


def _zero_modes(traj, remove_rotation, remove_drift):
    """``(remove_rotation, remove_drift)`` resolved for the trajectory's surface: None is on where
    the surface has that rigid motion (rotations on a sphere, about z on a torus, translations on
    the plane); asking for a motion the surface lacks is refused. A rotation to remove is given as
    its kind (:data:`~spherevm.analysis.trajectory.ROTATIONS`), else False."""
    motions = tuple(traj.constraint.rigid_motions)
    resolved = []
    for flag, value, kinds, what in (("remove_rotation", remove_rotation, ROTATIONS, "rigid rotation"),
                                     ("remove_drift", remove_drift, ("translations",), "centre-of-mass drift")):
        has = any(m in motions for m in kinds)
        if value or (value is None and has):
            resolved.append(surface_motion(traj.constraint, kinds, f"{flag}=True", what))
        else:
            resolved.append(False)
    return tuple(resolved)


def _displacements(traj, origin, remove_rotation, geodesic, scaled, remove_drift=False):
    """Distances ``(T - origin, n_cells)`` of every cell between frame ``origin`` and each later frame
    (of the unwrapped positions), each pair's rigid rotation or drift removed first if asked."""
    rep = traj.cell_replica
    ref = traj.positions[origin]
    cur = traj.positions[origin:]
    if remove_rotation:
        cur = remove_rigid_rotation(ref, cur, rep, about_z=remove_rotation == "z-rotations")
    dr = None
    if remove_drift:
        dr = cur - ref
        dr = dr - replica_mean(dr, rep, traj.replica_order, traj.replica_starts)[:, rep, :]
    if geodesic and dr is None:
        d = traj.constraint.geodesic_distance(ref, cur, traj.size[rep])
    else:
        d = np.linalg.norm(cur - ref if dr is None else dr, axis=-1)
    if scaled:
        d = d / traj.length_unit[rep]
    d[0] = 0.0   # the origin against itself (the fitted rotation is the identity only to rounding)
    return d


def _correlate(traj, func, origins, remove_rotation, geodesic, scaled, name, remove_drift=None):
    """Average ``func(distance)`` over cells, per replica and over all, for every lag of the pairs."""
    if not isinstance(traj, Trajectory):
        raise TypeError(f"expected a spherevm.analysis.Trajectory, got {type(traj).__name__}")
    remove_rotation, remove_drift = _zero_modes(traj, remove_rotation, remove_drift)
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
        d = _displacements(traj, int(i), remove_rotation, geodesic, scaled, remove_drift)
        per_rep = _replica_sum(func(d), traj.replica_order, traj.replica_starts) / cells
        np.add.at(sums, inverse[int(i)], per_rep)
        np.add.at(count, inverse[int(i)], 1)
    per_replica = sums / count[:, None]
    value = (per_replica * cells).sum(axis=1) / cells.sum()
    return TimeCorrelation(lag=np.asarray(lags_unique, dtype=np.float64), value=value,
                           per_replica=per_replica, count=count, name=name)


def msd(traj, remove_rotation: bool = None, geodesic: bool = False, origins="first",
        scaled: bool = True, remove_drift: bool = None) -> TimeCorrelation:
    """Mean squared displacement ``<|r_i(t0 + t) - r_i(t0)|^2>`` of the cell centroids.

    Parameters
    ----------
    traj : Trajectory
    remove_rotation : bool, optional
        Remove each replica's rigid rotation between the two frames first (sphere; None = True
        there; refused on the plane).
    geodesic : bool
        False for the chord (straight 3D distance, the paper's ``|r_i(t) - r_i(0)|``), True for the
        arc length on the sphere. Both saturate: the chord at ``2 R``, the arc at ``pi R``.
    origins : {"first", "all"} or sequence of int
        "first": lags from frame 0 only (suits log-spaced sampling); "all": every pair of frames
        ``t0 <= t1``, grouped by equal lag; or the origin frames.
    scaled : bool
        Lengths in units of ``sqrt(<A>)`` per replica (default) rather than simulation units.
    remove_drift : bool, optional
        Periodic plane: subtract each replica's mean cell displacement between the two frames
        (None = True on the plane; refused on a sphere). Displacements on the plane are unwrapped.

    Returns
    -------
    TimeCorrelation"""
    return _correlate(traj, np.square, origins, remove_rotation, geodesic, scaled, "msd", remove_drift)


def self_overlap(traj, b: float = 0.5, geodesic: bool = False, remove_rotation: bool = None, origins="first",
                 scaled: bool = True, remove_drift: bool = None) -> TimeCorrelation:
    """Self-overlap ``Q_s(t)``: the fraction of cells displaced by at most ``b`` (paper: ``b = 1/2``).

    ``w(d) = 1`` for ``d <= b``, else 0, on the chord ``|r_i(t) - r_i(0)|`` (or the arc with
    ``geodesic=True``).

    Parameters
    ----------
    traj : Trajectory
    b : float
        The window, in units of ``sqrt(<A>)``.
    geodesic, remove_rotation, origins, scaled, remove_drift
        As in :func:`msd`.

    Returns
    -------
    TimeCorrelation"""
    if not np.isfinite(b) or b <= 0:
        raise ValueError(f"b must be positive and finite, got {b!r}")
    return _correlate(traj, lambda d: (d <= b).astype(np.float64), origins, remove_rotation, geodesic, scaled,
                      "self_overlap", remove_drift)


def self_intermediate_scattering(traj, q: float = 2 * np.pi, remove_rotation: bool = None, average: str = "2d",
                                 geodesic: bool = False, origins="first", scaled: bool = True,
                                 remove_drift: bool = None) -> TimeCorrelation:
    """Self-intermediate scattering function ``F_s(q, t) = < exp(i q . (r_i(t) - r_i(0))) >``,
    averaged over the directions of ``q``, so a function of ``d = |dr|`` only.

    Parameters
    ----------
    traj : Trajectory
    q : float
        In units of ``1/sqrt(<A>)``; the default ``2 pi`` is a wavelength of one cell length, near
        the first peak of the cells' structure factor, the usual choice for alpha relaxation.
    average : {"2d", "3d"}
        "2d": ``J0(q d)``, the average over ``q`` in a plane containing the displacement: cells move
        on the surface, so the tangent wave vectors are the meaningful ones, as for a flat monolayer.
        "3d": ``sin(q d) / (q d)``, the average over all directions in space.
    remove_rotation, geodesic, origins, scaled, remove_drift
        As in :func:`msd` (``d`` is the chord, or the arc length with ``geodesic=True``).

    Returns
    -------
    TimeCorrelation"""
    if not np.isfinite(q) or q <= 0:
        raise ValueError(f"q must be positive and finite, got {q!r}")
    if average == "2d":
        from scipy.special import j0
        func = lambda d: j0(q * d)  # noqa: E731
    elif average == "3d":
        func = lambda d: np.sinc(q * d / np.pi)  # noqa: E731  (np.sinc(x) = sin(pi x) / (pi x))
    else:
        raise ValueError(f"average must be '2d' (J0, tangent wave vectors) or '3d' (sin x / x), got {average!r}")
    return _correlate(traj, func, origins, remove_rotation, geodesic, scaled, "self_intermediate_scattering",
                      remove_drift)


# ======================================================================================== tau_alpha
class NoRelaxationWarning(RuntimeWarning):
    """tau_alpha could not be measured: the curve never crossed the level inside the data."""


def tau_alpha(times, q_s=None, level: float = 1 / math.e, interpolation: str = "log", warn: bool = True,
              _stacklevel: int = 2):
    """The first time at which ``q_s`` falls to ``level`` (default ``1/e``), interpolated between the
    samples ``k - 1`` and ``k`` around the first sample ``k`` with ``q_s <= level``.

    Parameters
    ----------
    times : array or TimeCorrelation
        Sample times; or a :class:`TimeCorrelation` alone (its lags and values).
    q_s : array, optional
        Same length as ``times``, or ``(T, k)``: one tau per column.
    level : float
    interpolation : {"log", "linear"}
        "log": linearly in ``log t`` (the natural variable for log-spaced sampling: for
        ``exp(-t/tau)`` the curve against ``log t`` has its inflection exactly at ``t = tau``;
        linear in ``t`` for an interval starting at ``t <= 0``); "linear": linearly in ``t``.
    warn : bool
        Issue a :class:`NoRelaxationWarning` where a NaN is returned.

    Returns
    -------
    float or numpy.ndarray
        One per column; NaN where the curve never reaches the level (no alpha relaxation within
        the run) or is already below it at the first sample."""
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


# ======================================================================================== Arrhenius plots
@dataclass(eq=False)
class ArrheniusFit:
    """``log tau = a + b/T + c/T^2`` fitted to the mean over tissues of ``log tau_alpha`` at each
    temperature; ``c`` is the curvature of the Arrhenius plot (< 0: the barrier
    ``d log tau / d(1/T) = b + 2c/T`` falls on cooling, sub-Arrhenius; > 0: super-Arrhenius).

    T : the temperatures used (those at which every tissue relaxed); log_tau, log_tau_se : the mean
    of log tau_alpha over the tissues there and its standard error; coef : (a, b, c);
    c_err : the standard deviation of c over bootstrap resamplings of the tissues at each T;
    c_samples : those resampled c."""
    T: np.ndarray
    log_tau: np.ndarray
    log_tau_se: np.ndarray
    coef: np.ndarray
    c_err: float
    c_samples: np.ndarray

    @property
    def c(self) -> float:
        return float(self.coef[2])

    def verdict(self) -> str:
        """"sub-Arrhenius", "super-Arrhenius" (|c| at least 2 c_err) or "consistent with Arrhenius"."""
        if not abs(self.c) >= 2 * self.c_err:
            return f"consistent with Arrhenius (c = {self.c:.3g} +- {self.c_err:.2g})"
        kind = "sub-Arrhenius" if self.c < 0 else "super-Arrhenius"
        return f"{kind} (c = {self.c:.3g} +- {self.c_err:.2g}, {abs(self.c) / self.c_err:.1f} sigma)"


def arrhenius_fit(T, tau, n_boot: int = 1000, seed: int = 0):
    """Fit ``log tau = a + b/T + c/T^2`` (the curvature ``c``, errors by bootstrap over tissues).

    Parameters
    ----------
    T : array (n_T,)
        Temperatures.
    tau : array (n_T, n_tissues)
        tau_alpha of each tissue at each T; a temperature with a NaN (a tissue that did not
        relax) is left out.
    n_boot : int
        Bootstrap resamplings: at each T the tissues are drawn with replacement and the fit repeated.
    seed : int

    Returns
    -------
    ArrheniusFit, or None when fewer than 4 temperatures have every tissue relaxed."""
    T = np.asarray(T, dtype=np.float64).reshape(-1)
    tau = np.asarray(tau, dtype=np.float64).reshape(len(T), -1)
    ok = np.all(np.isfinite(tau) & (tau > 0), axis=1)
    if ok.sum() < 4:
        return None
    x, logs = 1.0 / T[ok], np.log(tau[ok])
    design = np.stack((np.ones_like(x), x, x * x), axis=1)
    solve = np.linalg.pinv(design)                       # the same least squares for every resampling
    k = logs.shape[1]
    pick = np.random.default_rng(seed).integers(0, k, size=(n_boot,) + logs.shape)
    boot = np.take_along_axis(np.broadcast_to(logs, pick.shape), pick, axis=2).mean(axis=2)   # (n_boot, n_T)
    c_samples = boot @ solve[2]
    se = logs.std(axis=1, ddof=1) / np.sqrt(k) if k > 1 else np.full(len(x), np.nan)
    return ArrheniusFit(T=T[ok], log_tau=logs.mean(axis=1), log_tau_se=se, coef=solve @ logs.mean(axis=1),
                        c_err=float(c_samples.std(ddof=1)), c_samples=c_samples)
