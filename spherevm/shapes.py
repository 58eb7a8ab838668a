"""Cell shapes and positions of a State: areas, perimeters, shape indices, centroids, and the
regular spherical polygons they are compared with.

Core cell geometry, below the plugins: the GSD writer, the Recorder and the Simulation's loggables
use it without importing :mod:`spherevm.analysis` (which re-exports it for users).
"""
from __future__ import annotations

import numpy as np

from .constraints.kernels import cell_measures, compiles

CENTROID_METHODS = ("area", "vertex")


# ======================================================================================== shapes
def cell_shapes(state):
    """Per-cell areas and perimeters (on the GPU from one kernel, the vertex model's own formulas:
    :func:`spherevm.constraints.kernels.cell_measures`).

    Parameters
    ----------
    state : State

    Returns
    -------
    (area, perimeter)
        NumPy arrays of length ``n_cells``."""
    if state.device.is_gpu and compiles(state.constraint):
        area, perimeter = cell_measures(state)
    else:
        g = state.constraint.cell_geometry(state)
        area, perimeter = g.area, g.perimeter
    return state.device.to_numpy(area), state.device.to_numpy(perimeter)


def shape_index_of(area, perimeter):
    """``P / sqrt(A)`` per cell; NaN for a cell of non-positive area (folded over, which the energy
    allows at kA = 0)."""
    return perimeter / np.sqrt(np.where(area > 0, area, np.nan))


def shape_index(state):
    """Per-cell shape index ``P / sqrt(A)`` (see :func:`shape_index_of`).

    Parameters
    ----------
    state : State

    Returns
    -------
    numpy.ndarray (n_cells,)"""
    return shape_index_of(*cell_shapes(state))


def mean_shape_index(state):
    """Mean shape index per replica, over the cells of positive area.

    Parameters
    ----------
    state : State

    Returns
    -------
    numpy.ndarray (n_replicas,)"""
    q = shape_index(state)
    ok = np.isfinite(q)
    rep = state.cell_replica_np()
    total = np.bincount(rep, weights=np.where(ok, q, 0.0), minlength=state.n_replicas)
    return total / np.maximum(np.bincount(rep, weights=ok, minlength=state.n_replicas), 1)


def regular_polygon_perimeter(n_sides: int, area: float, radius: float) -> float:
    """Perimeter of the regular spherical ``n_sides``-gon of the given area on a sphere of ``radius``
    (:func:`polygon_perimeter_at_curvature` at ``K = 1 / radius^2``)."""
    if not radius > 0 or not area > 0:
        raise ValueError(f"area and radius must be positive, got area={area}, radius={radius}")
    if area >= 2 * np.pi * radius ** 2:
        raise ValueError(f"area must be below a hemisphere, 2 pi R^2 = {2 * np.pi * radius ** 2:g}, got {area}")
    return float(polygon_perimeter_at_curvature(n_sides, 1.0 / radius ** 2, area))


#: Taylor coefficients of arcsin(sqrt(w)) / sqrt(w) = sum c_k w^k (also arcsinh(sqrt(-w)) / sqrt(-w))
_ASIN_SERIES = np.array([1.0, 1 / 6, 3 / 40, 5 / 112, 35 / 1152, 63 / 2816, 231 / 13312])


def _asin_ratio(w):
    """``arcsin(sqrt(w)) / sqrt(w)`` for w > 0, ``arcsinh(sqrt(-w)) / sqrt(-w)`` for w < 0: one
    analytic function of w, 1 at w = 0 (series for |w| < 1e-3, error below 1e-22)."""
    small = np.abs(w) < 1e-3
    safe = np.where(small, 1.0, w)
    root = np.sqrt(np.abs(safe))
    direct = np.where(safe > 0, np.arcsin(np.minimum(root, 1.0)), np.arcsinh(root)) / root
    return np.where(small, np.polynomial.polynomial.polyval(w, _ASIN_SERIES), direct)


def polygon_perimeter_at_curvature(n_sides: int, curvature, area=1.0):
    """Perimeter of the regular geodesic ``n_sides``-gon of ``area`` on the surface of constant
    Gaussian curvature ``K`` (sphere K > 0, plane K = 0, hyperbolic plane K < 0).

    ``P = sqrt(4 n A g) f(w)`` with ``beta = pi/n``, ``delta = K A / (2n)``,
    ``g = sin(beta - delta/2) sinc(delta/2) / cos(beta - delta)``, ``w = g delta / 2`` and
    ``f(w) = arcsin(sqrt w)/sqrt w`` (``arcsinh(sqrt -w)/sqrt -w`` for w < 0): analytic through
    K = 0, where it is ``sqrt(4 n A tan(pi/n))``. Derivation in docs/results.md ("Curvature gradients").

    Parameters
    ----------
    n_sides : int
        At least 3.
    curvature : float or array
        Gaussian curvature K; ``K * area`` must lie in ``(-(n - 2) pi, 2 pi)`` (ideal polygon to
        hemisphere).
    area : float or array
        Positive; broadcast with ``curvature``.

    Returns
    -------
    float or numpy.ndarray
        The broadcast shape of ``curvature`` and ``area``."""
    n = int(n_sides)
    if n < 3:
        raise ValueError(f"n_sides must be >= 3, got {n_sides}")
    k, a = np.broadcast_arrays(np.asarray(curvature, dtype=np.float64), np.asarray(area, dtype=np.float64))
    if not np.all(np.isfinite(a) & (a > 0)):
        raise ValueError(f"area must be positive and finite, got {area}")
    ka = k * a
    if not np.all((ka > -(n - 2) * np.pi) & (ka < 2 * np.pi)):
        raise ValueError(f"curvature * area must lie in ({-(n - 2) * np.pi:.6g}, {2 * np.pi:.6g}) for a regular "
                         f"{n}-gon (ideal polygon to hemisphere), got curvature={curvature}, area={area}")
    beta, delta = np.pi / n, ka / (2 * n)
    g = np.sin(beta - delta / 2) * np.sinc(delta / (2 * np.pi)) / np.cos(beta - delta)
    p = np.sqrt(4 * n * a * g) * _asin_ratio(g * delta / 2)
    return float(p) if p.ndim == 0 else p


def pentagon_perimeter_at_curvature(curvature, area=1.0):
    """The pentagon bound at any Gaussian curvature K: perimeter of the regular pentagon of
    ``area`` on the surface of constant curvature K (:func:`polygon_perimeter_at_curvature`, n = 5);
    3.81194 at K = 0 and unit area, lower where K > 0, higher where K < 0.

    Parameters
    ----------
    curvature : float or array
        K, with ``K * area`` in ``(-3 pi, 2 pi)``.
    area : float or array

    Returns
    -------
    float or numpy.ndarray"""
    return polygon_perimeter_at_curvature(5, curvature, area)


def pentagon_perimeter(n_cells) -> float:
    """The paper's bound: perimeter of a unit-area regular spherical pentagon, R = sqrt(N / 4 pi).

    Parameters
    ----------
    n_cells : int or array
        Cells on the sphere.

    Returns
    -------
    float or numpy.ndarray"""
    n = np.asarray(n_cells)
    if np.any(n < 4):
        raise ValueError(f"n_cells must be >= 4, got {n_cells}")
    return pentagon_perimeter_at_curvature(4 * np.pi / n)


def planar_pentagon_perimeter() -> float:
    """Perimeter of the flat regular pentagon of unit area, ``sqrt(20 tan(pi/5)) = 3.81194``: the
    N-independent value of the pentagon bound on the periodic plane."""
    return float(np.sqrt(20.0 * np.tan(np.pi / 5.0)))


def surface_pentagon_perimeter(n_cells, surface: str = "sphere"):
    """The unit-area regular pentagon's perimeter on ``surface`` with N cells: the spherical one
    (:func:`pentagon_perimeter`) or, on any other (the plane; an implicit surface's spec, measured
    with flat facets), the flat one (the same for every N)."""
    if surface != "sphere":
        n = np.asarray(n_cells)
        value = planar_pentagon_perimeter()
        return value if n.ndim == 0 else np.full(n.shape, value)
    return pentagon_perimeter(n_cells)


# ======================================================================================== centroids
def cell_centroids(state, method: str = "area"):
    """Cell positions on the surface, ``(n_cells, 3)`` NumPy float64
    (:meth:`~spherevm.constraints.Constraint.cell_centroids`): on the sphere each at distance R from
    the centre; on a periodic plane wrapped into the box, ``z = 0`` (each polygon unwrapped from its
    first vertex).

    ``method="area"`` (default): the centre of mass of the cell's area, on the sphere pushed
    radially onto it. It is continuous through a T1, while the vertex centroid jumps by about
    ``|r_edge - r_cell| / n`` (0.08 sqrt(<A>) for a hexagon) at every T1, which an MSD's cage
    plateau would feel. A folded cell (non-positive area, allowed at kA = 0) falls back to the
    vertex centroid. ``method="vertex"``: the mean of the vertices (on the sphere ``R`` times the
    normalised mean of the unit vertex directions).

    Parameters
    ----------
    state : State
        Any surface that gives cell centroids (Sphere, PeriodicPlane), either device.
    method : {"area", "vertex"}

    Returns
    -------
    numpy.ndarray (n_cells, 3)"""
    if method not in CENTROID_METHODS:
        raise ValueError(f"method must be one of {CENTROID_METHODS}, got {method!r}")
    return np.asarray(state.device.to_numpy(state.constraint.cell_centroids(state, method)), dtype=np.float64)
