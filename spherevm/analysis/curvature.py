"""Cells against the local Gaussian curvature: K at points of each surface, the torus's range of K,
and per-cell quantities binned against a per-cell value with their standard errors.

The pentagon bound at a curvature K is :func:`spherevm.shapes.pentagon_perimeter_at_curvature`
(re-exported by :mod:`spherevm.analysis`). See docs/results.md, "Curvature gradients".
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..constraints import Constraint


def gaussian_curvature(constraint, x, radius=None, size=None):
    """Gaussian curvature K of ``constraint``'s surface at the points ``x``
    (:meth:`~spherevm.constraints.Constraint.gaussian_curvature`).

    Sphere: ``1 / R^2``. Periodic plane: 0. Torus (tube ``r`` around a circle ``R``):
    ``(rho - R) / (r^2 rho)`` with ``rho`` the distance from the axis, from ``1 / (r (R + r))`` outside
    to ``-1 / (r (R - r))`` inside. An implicit surface ``F = 0`` (the Gaussian bump in the middle of
    its box, the ellipsoid, a user's): ``-det([[H, g], [g^T, 0]]) / |g|^4`` with ``g = grad F`` and
    ``H`` its Hessian; the bump's is ``h^2 / w^4`` on top and negative beyond ``rho = w``. The points
    are taken as given (not projected onto the surface).

    Parameters
    ----------
    constraint : Constraint
    x : array (..., 3)
    radius : float or array (...), optional
        The sphere's radius (per point or one); needed on a sphere only.
    size : array, optional
        Another surface's parameters (per point or one; default the constraint's own).

    Returns
    -------
    numpy.ndarray (...)"""
    x = np.asarray(x, dtype=np.float64)
    if x.shape[-1:] != (3,):
        raise ValueError(f"x must have shape (..., 3), got {x.shape}")
    if not isinstance(constraint, Constraint):
        raise ValueError(f"constraint must be a spherevm Constraint (a surface), got {type(constraint).__name__}")
    return constraint.gaussian_curvature(x, radius if size is None else size)


def cell_curvature(state):
    """``K <A>`` at each cell's area centroid: the Gaussian curvature the cell sits on, in units of its
    replica's mean cell area (a State on the CPU).

    Parameters
    ----------
    state : State

    Returns
    -------
    numpy.ndarray (n_cells,)"""
    rep = state.cell_replica_np()
    x = np.asarray(state.constraint.cell_centroids(state, "area"))
    return gaussian_curvature(state.constraint, x, size=state.size_np()[rep]) * state.mean_cell_area[rep]


def torus_curvature_range(aspect, n_cells, mean_area=1.0):
    """Lowest and highest Gaussian curvature of the torus of aspect ratio ``R / r`` whose area
    ``4 pi^2 R r`` holds ``n_cells`` cells of ``mean_area``: ``-1 / (r (R - r))`` and ``1 / (r (R + r))``.

    Parameters
    ----------
    aspect : float or array
        ``R / r``, above 1.
    n_cells : int or array
    mean_area : float

    Returns
    -------
    (k_min, k_max)
        Broadcast over ``aspect`` and ``n_cells``."""
    a = np.asarray(aspect, dtype=np.float64)
    if not np.all(a > 1):
        raise ValueError(f"aspect must be above 1 (a ring torus), got {aspect}")
    r2 = np.asarray(n_cells, dtype=np.float64) * mean_area / (4 * np.pi ** 2 * a)
    return -1.0 / (r2 * (a - 1)), 1.0 / (r2 * (a + 1))


@dataclass
class Binned:
    """Per-bin statistics of :func:`binned_mean` (arrays of n_bins, but ``edges``).

    Parameters
    ----------
    edges : numpy.ndarray (n_bins + 1,)
    x : numpy.ndarray
        Mean of the binning value in each bin.
    mean, sem : numpy.ndarray
        Mean of the quantity and its standard error (NaN with fewer than two samples).
    count : numpy.ndarray
        Cells in the bin, or groups when grouped."""
    edges: np.ndarray
    x: np.ndarray
    mean: np.ndarray
    sem: np.ndarray
    count: np.ndarray


def binned_mean(x, y, bins=10, spacing: str = "quantile", groups=None) -> Binned:
    """Mean and standard error of a per-cell quantity ``y`` in bins of a per-cell value ``x``
    (the local Gaussian curvature, say). Cells where ``x`` or ``y`` is NaN are left out, and so are
    those outside explicit edges; the last bin includes its right edge.

    Parameters
    ----------
    x, y : array (n,)
    bins : int or array
        A number of bins (edges from ``spacing``) or the edges themselves (increasing).
    spacing : {"quantile", "linear"}
        For an int ``bins``: bins of equal counts (repeated edges, as where many cells share one x,
        are merged, so fewer bins may come back) or of equal width over the range of ``x``.
    groups : array (n,) of int, optional
        The tissue (replica) of each cell. Then each group's mean in a bin is one sample: ``mean``
        is the mean over groups, ``sem`` their standard deviation over sqrt(number of groups), and
        ``count`` the groups present (cells of one tissue are not independent samples).

    Returns
    -------
    Binned"""
    x, y = np.asarray(x, dtype=np.float64), np.asarray(y, dtype=np.float64)
    if x.ndim != 1 or x.shape != y.shape:
        raise ValueError(f"x and y must be 1-d of one length, got shapes {x.shape} and {y.shape}")
    if spacing not in ("quantile", "linear"):
        raise ValueError(f"spacing must be 'quantile' or 'linear', got {spacing!r}")
    ok = np.isfinite(x) & np.isfinite(y)
    if not ok.any():
        raise ValueError("x and y have no finite pair to bin")
    if np.ndim(bins) == 0:
        if int(bins) < 1:
            raise ValueError(f"bins must be at least 1, got {bins}")
        if spacing == "quantile":
            edges = np.unique(np.quantile(x[ok], np.linspace(0, 1, int(bins) + 1)))
        else:
            edges = np.linspace(x[ok].min(), x[ok].max(), int(bins) + 1)
    else:
        edges = np.asarray(bins, dtype=np.float64)
        if edges.ndim != 1 or edges.size < 2 or np.any(np.diff(edges) <= 0):
            raise ValueError(f"bins as edges must be at least two increasing values, got {bins}")
    if edges.size == 1:                                     # every x equal: one bin holding them all
        edges = np.array([edges[0], edges[0]])
    n_bins = edges.size - 1
    which = np.clip(np.searchsorted(edges, x, side="right") - 1, 0, n_bins - 1)
    ok &= (x >= edges[0]) & (x <= edges[-1])
    key, xs, ys = which[ok], x[ok], y[ok]
    if groups is not None:                                  # one sample per (bin, group): its means
        g = np.asarray(groups)
        if g.shape != x.shape:
            raise ValueError(f"groups must have the shape of x, {x.shape}, got {g.shape}")
        labels, g = np.unique(g, return_inverse=True)
        stride = labels.size
        pairs, member = np.unique(key * stride + g.reshape(x.shape)[ok], return_inverse=True)
        xs, ys = _bin_moments(member, xs, ys, pairs.size)[:2]
        key = pairs // stride
    x_mean, y_mean, var, n = _bin_moments(key, xs, ys, n_bins)
    with np.errstate(invalid="ignore", divide="ignore"):
        sem = np.where(n > 1, np.sqrt(var / n), np.nan)
    return Binned(edges=edges, x=x_mean, mean=y_mean, sem=sem, count=n.astype(np.int64))


def _bin_moments(key, x, y, n_bins):
    """Per bin: mean of x, mean of y, sample variance of y (ddof 1), count."""
    n = np.bincount(key, minlength=n_bins).astype(np.float64)
    with np.errstate(invalid="ignore", divide="ignore"):
        mx = np.bincount(key, x, n_bins) / n
        my = np.bincount(key, y, n_bins) / n
        var = np.bincount(key, (y - my[key]) ** 2, n_bins) / (n - 1)
    return mx, my, var, n
