"""Torus: the surface exists with its projections; its metric is not implemented yet."""
from __future__ import annotations

import numpy as np

from ..device import array_module
from .base import Constraint


class Torus(Constraint):
    """Torus about the z axis: tube of radius ``minor_radius`` around a circle of ``major_radius``.

    ``(sqrt(x^2 + y^2) - R)^2 + z^2 = r^2`` with ``R > r > 0`` (a ring torus, no self-intersection).
    Normals and the projections P_T, P_N are available; geodesic lengths and polygon areas (and so
    vertex-model forces) are not implemented yet and raise NotImplementedError. Initial tilings of
    a torus also do not exist yet: its Euler characteristic is 0, not 2.
    """

    name = "torus"

    def __init__(self, major_radius: float, minor_radius: float):
        R, r = float(major_radius), float(minor_radius)
        if not np.isfinite(r) or r <= 0:
            raise ValueError(f"minor_radius must be positive and finite, got {minor_radius}")
        if not np.isfinite(R) or R <= r:
            raise ValueError(f"major_radius must be finite and larger than minor_radius={r}, got {major_radius}")
        self.major_radius, self.minor_radius = R, r

    def _tube_centre(self, x):
        xp = array_module(x)
        rho = xp.sqrt(x[..., 0] ** 2 + x[..., 1] ** 2)
        centre = xp.zeros_like(x)
        centre[..., 0] = self.major_radius * x[..., 0] / rho
        centre[..., 1] = self.major_radius * x[..., 1] / rho
        return centre

    def normal(self, x):
        d = x - self._tube_centre(x)
        return d / array_module(x).sqrt((d * d).sum(axis=-1))[..., None]

    def project_normal(self, x, radius=None):
        """Closest point on the torus (``radius`` is ignored: the torus carries its own size)."""
        return self._tube_centre(x) + self.minor_radius * self.normal(x)

    def distance_to_surface(self, x, radius=None):
        d = x - self._tube_centre(x)
        return array_module(x).sqrt((d * d).sum(axis=-1)) - self.minor_radius

    def total_area_np(self, radius=None):
        return 4.0 * np.pi ** 2 * self.major_radius * self.minor_radius

    def __repr__(self):
        return f"Torus(major_radius={self.major_radius}, minor_radius={self.minor_radius})"
