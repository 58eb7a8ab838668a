"""Cell areas, perimeters and shape indices; the regular spherical pentagon bound."""
from __future__ import annotations

import numpy as np


def cell_shapes(state):
    """Per-cell areas and perimeters, as NumPy arrays of length ``n_cells``."""
    g = state.constraint.cell_geometry(state)
    return state.device.to_numpy(g.area), state.device.to_numpy(g.perimeter)


def shape_index(state):
    """Per-cell shape index ``P / sqrt(A)``; NaN for a cell of non-positive area (folded over,
    which the energy allows at kA = 0)."""
    area, perimeter = cell_shapes(state)
    return perimeter / np.sqrt(np.where(area > 0, area, np.nan))


def mean_shape_index(state):
    """Mean shape index per replica, over the cells of positive area."""
    q = shape_index(state)
    ok = np.isfinite(q)
    rep = state.cell_replica_np()
    total = np.bincount(rep, weights=np.where(ok, q, 0.0), minlength=state.n_replicas)
    return total / np.maximum(np.bincount(rep, weights=ok, minlength=state.n_replicas), 1)


def regular_polygon_perimeter(n_sides: int, area: float, radius: float) -> float:
    """Perimeter of the regular spherical ``n_sides``-gon of the given area on a sphere of ``radius``.

    Interior angle from the angle excess ``alpha = (A/R^2 + (n-2) pi)/n``; side from the right
    triangle centre-vertex-midpoint, ``cos(s/2) = cos(pi/n) / sin(alpha/2)``.
    """
    n = int(n_sides)
    if n < 3:
        raise ValueError(f"n_sides must be >= 3, got {n_sides}")
    if not radius > 0 or not area > 0:
        raise ValueError(f"area and radius must be positive, got area={area}, radius={radius}")
    if area >= 2 * np.pi * radius ** 2:
        raise ValueError(f"area must be below a hemisphere, 2 pi R^2 = {2 * np.pi * radius ** 2:g}, got {area}")
    alpha = (area / radius ** 2 + (n - 2) * np.pi) / n
    half_side = np.arccos(np.clip(np.cos(np.pi / n) / np.sin(alpha / 2), -1.0, 1.0))
    return float(2 * n * half_side * radius)


def pentagon_perimeter(n_cells) -> float:
    """The paper's bound: perimeter of a unit-area regular spherical pentagon, R = sqrt(N / 4 pi).

    Accepts a scalar or an array of cell numbers (returns an array then).
    """
    n = np.asarray(n_cells)
    if np.any(n < 4):
        raise ValueError(f"n_cells must be >= 4, got {n_cells}")
    values = [regular_polygon_perimeter(5, 1.0, np.sqrt(k / (4 * np.pi))) for k in np.atleast_1d(n)]
    return values[0] if n.ndim == 0 else np.array(values)
