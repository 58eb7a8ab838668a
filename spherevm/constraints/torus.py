"""The ring torus about the z axis: closed-form normals and closest points, the flat-facet metric."""
from __future__ import annotations

import numpy as np

from ..device import array_module
from .implicit import MIN_TILING_CELLS, ImplicitSurface, rejection

#: random tilings: the tube must be at least this many cell sides around, (2 pi r)^2 / <A> >= 9, so
#: n_cells >= 9 R / r
MIN_CELLS_AROUND_TUBE = 3.0


class Torus(ImplicitSurface):
    """Torus about the z axis: a tube of radius ``minor_radius`` r around the circle of radius
    ``major_radius`` R in the plane z = 0, ``F = (rho - R)^2 + z^2 - r^2`` (``rho = sqrt(x^2 +
    y^2)``), a ring torus (R > r > 0). Area 4 pi^2 R r, Euler characteristic 0.

    The normal ``(x - c)/|x - c|`` and the closest point ``c + r (x - c)/|x - c|``, with ``c = R
    (x, y, 0)/rho`` the nearest point of the core circle, are closed forms. (R, r) are per replica
    (``size``); the instance's values are the shape a tiling starts from
    (:func:`spherevm.init.random_tiling` scales both by one factor).

    Parameters
    ----------
    major_radius, minor_radius : float
        R > r > 0."""

    name = "torus"
    size_names = ("major_radius", "minor_radius")
    euler_characteristic = 0
    cuda_file, cuda_projection = "torus.cuh", True

    def __init__(self, major_radius: float = 3.0, minor_radius: float = 1.0):
        self.shape = tuple(self.check_size([major_radius, minor_radius])[0])
        self.major_radius, self.minor_radius = self.shape

    def check_parameters(self, R, r):
        bad = ~(np.asarray(R) > np.asarray(r))
        if bad.any():
            raise ValueError(f"major_radius must be larger than minor_radius (a ring torus), got major_radius="
                             f"{np.asarray(R)[bad][0]:g} and minor_radius={np.asarray(r)[bad][0]:g}")

    #: rotations about its axis map the torus onto itself
    rigid_motions = ("z-rotations",)

    def _core(self, x, R):
        """The nearest point of the core circle (radius ``R``, z = 0) and ``x`` minus it."""
        xp = array_module(x)
        rho = xp.sqrt(x[..., 0] ** 2 + x[..., 1] ** 2)
        c = xp.zeros_like(x)
        c[..., 0] = R * x[..., 0] / rho
        c[..., 1] = R * x[..., 1] / rho
        return c, x - c

    def F(self, x, size):
        R, r = self.parameters(size)
        rho = array_module(x).sqrt(x[..., 0] ** 2 + x[..., 1] ** 2)
        return (rho - R) ** 2 + x[..., 2] ** 2 - r * r

    def grad_F(self, x, size):
        R, _ = self.parameters(size)
        return 2.0 * self._core(x, R)[1]

    def project_normal(self, x, size):
        """``c + r (x - c)/|x - c|`` (closed form)."""
        xp = array_module(x)
        R, r = self.parameters(xp.asarray(size))
        c, d = self._core(x, R)
        return c + (r / xp.sqrt((d * d).sum(axis=-1)))[..., None] * d

    def distance_to_surface(self, x, size):
        xp = array_module(x)
        R, r = self.parameters(xp.asarray(size))
        d = self._core(x, R)[1]
        return xp.sqrt((d * d).sum(axis=-1)) - r

    def length_scale(self, size):
        """The minor radius r."""
        return size[..., 1]

    def gaussian_curvature(self, x, size=None):
        """``(rho - R) / (r^2 rho)``, ``rho`` the distance from the axis: from ``1 / (r (R + r))`` on the
        outer equator to ``-1 / (r (R - r))`` on the inner."""
        x = np.asarray(x, dtype=np.float64)
        R, r = self.parameters(np.asarray(self.shape if size is None else size, dtype=np.float64))
        rho = np.hypot(x[..., 0], x[..., 1])
        return (rho - R) / (r * r * rho)

    def replica_spacing(self, size, cell_width) -> float:
        """2.5 times the largest outer radius R + r (tori drawn side by side do not touch)."""
        s = np.asarray(size).reshape(-1, 2)
        return 2.5 * float((s[:, 0] + s[:, 1]).max())

    def minimum_cells(self, size) -> int:
        """``9 R / r`` (the tube three cells around), at least 16."""
        return max(MIN_TILING_CELLS, int(np.ceil(MIN_CELLS_AROUND_TUBE ** 2 * size[0] / size[1])))

    def tiling_points(self, rng, n, size):
        """Angles (phi, theta) about the axis and the tube, theta kept with probability ``(R + r cos
        theta) / (R + r)`` (uniform by area), in the plane ``(R phi, r theta)`` of box ``2 pi (R, r)``."""
        R, r = size
        angles = rejection(rng, n, lambda m: rng.random((m, 2)) * 2 * np.pi,
                           lambda a: (R + r * np.cos(a[:, 1])) / (R + r))
        plane = angles * np.array([R, r])
        return self.from_plane(plane, size), plane, 2 * np.pi * np.asarray(size)

    def from_plane(self, xy, size):
        """The torus's points at ``(R phi, r theta)``: ``((R + r cos theta) cos phi, (R + r cos theta)
        sin phi, r sin theta)`` (counter-clockwise in the plane is counter-clockwise from outside)."""
        R, r = size
        phi, theta = xy[:, 0] / R, xy[:, 1] / r
        rho = R + r * np.cos(theta)
        return np.stack([rho * np.cos(phi), rho * np.sin(phi), r * np.sin(theta)], axis=1)

    def total_area_np(self, size):
        """4 pi^2 R r per row of ``size``."""
        s = np.asarray(size, dtype=np.float64)
        return 4.0 * np.pi ** 2 * s[..., 0] * s[..., 1]
