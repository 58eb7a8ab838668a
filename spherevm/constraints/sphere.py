"""The sphere centred at the origin: geodesic perimeters and spherical-polygon areas."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..device import array_module
from ..geometry import sphere as geo
from .base import Constraint


@dataclass
class CellGeometry:
    """Per-cell area, perimeter and fan apex (unit centroid), plus the unit vertex directions."""
    area: object
    perimeter: object
    apex: object
    unit: object
    radius: object  # per vertex


class Sphere(Constraint):
    """Sphere of radius R (per replica, stored in ``State.radius``) centred at the origin.

    Perimeters are sums of geodesic arcs ``R theta``; areas are fans of signed spherical triangles
    about the cell's normalised vertex centroid (the area does not depend on the apex, so the
    gradients hold it fixed). Normal: ``x/|x|``; ``P_N(x) = R x/|x|``.
    """

    name = "sphere"

    def normal(self, x):
        return geo.normalize(x)

    def project_normal(self, x, radius):
        xp = array_module(x)
        return xp.asarray(radius)[..., None] * geo.normalize(x)

    def geodesic_offset(self, x, direction, distance, radius):
        """Exact geodesic step: ``R (cos(s/R) x_hat + sin(s/R) direction)``."""
        xp = array_module(x)
        phi = (distance / radius)[..., None]
        return xp.asarray(radius)[..., None] * (xp.cos(phi) * geo.normalize(x) + xp.sin(phi) * direction)

    def distance_to_surface(self, x, radius):
        xp = array_module(x)
        return xp.sqrt((x * x).sum(axis=-1)) - radius

    def total_area_np(self, radius):
        return 4.0 * np.pi * np.asarray(radius, dtype=np.float64) ** 2

    # -------------------------------------------------------------- per-corner metric
    @staticmethod
    def _corners(state):
        """Corner arrays (V, 3): cell, next vertex, previous vertex."""
        xp = state.device.xp
        vn = state.vertex_neighbors
        return state.vertex_cells, vn, xp.roll(vn, -1, axis=1)

    def cell_geometry(self, state) -> CellGeometry:
        xp = state.device.xp
        pos = state.positions
        rv = xp.sqrt((pos * pos).sum(axis=1))
        unit = pos / rv[:, None]
        radius_v = state.radius[state.vertex_replica]
        cells, nxt, _ = self._corners(state)
        flat_cells = cells.reshape(-1)
        n = state.n_cells
        corner_unit = xp.repeat(unit, 3, axis=0)
        summed = xp.stack([xp.bincount(flat_cells, weights=corner_unit[:, i], minlength=n) for i in range(3)], axis=1)
        apex = geo.normalize(summed)
        u_next = unit[nxt]
        r3 = radius_v[:, None]
        lengths = r3 * geo.geodesic_length(unit[:, None, :], u_next)
        omegas = r3 * r3 * geo.solid_angle(apex[cells], unit[:, None, :], u_next)
        perimeter = xp.bincount(flat_cells, weights=lengths.reshape(-1), minlength=n)
        area = xp.bincount(flat_cells, weights=omegas.reshape(-1), minlength=n)
        return CellGeometry(area=area, perimeter=perimeter, apex=apex, unit=unit, radius=radius_v)

    def corner_gradients(self, state, geometry: CellGeometry):
        """Surface gradients (with respect to positions) of each corner's cell area and perimeter.

        Returns ``(dA, dP)``, both ``(V, 3, 3)``: ``dA[v, k]`` is the gradient of the area of cell
        ``vertex_cells[v, k]`` with respect to ``positions[v]``; likewise ``dP``.
        """
        xp = state.device.xp
        cells, nxt, prv = self._corners(state)
        u = geometry.unit
        a = u[:, None, :]
        apex = geometry.apex[cells]
        u_next, u_prev = u[nxt], u[prv]
        # fan triangles (apex, v, next) and (apex, prev, v) == (prev, v, apex): v in the middle slot
        g_area = geo.solid_angle_gradient(apex, a, u_next) + geo.solid_angle_gradient(u_prev, a, apex)
        g_per = geo.geodesic_length_gradient(a, u_next) + geo.geodesic_length_gradient(a, u_prev)
        # chain rule to positions: d(unit)/dr = (I - a a^T)/|r|, with |r| = R on the surface
        rv = xp.sqrt((state.positions ** 2).sum(axis=1))
        g_area = g_area - (g_area * a).sum(axis=-1)[..., None] * a
        scale_a = (geometry.radius ** 2 / rv)[:, None, None]
        scale_p = (geometry.radius / rv)[:, None, None]
        return scale_a * g_area, scale_p * g_per

    def edge_lengths(self, state, u, v):
        """Geodesic lengths of the edges (u[i], v[i])."""
        pos = state.positions
        return state.radius[state.vertex_replica[u]] * geo.geodesic_length(geo.normalize(pos[u]),
                                                                           geo.normalize(pos[v]))
