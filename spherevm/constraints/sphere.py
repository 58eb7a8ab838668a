"""The sphere centred at the origin: geodesic perimeters and spherical-polygon areas."""
from __future__ import annotations

import os
import numpy as np

from ..device import array_module
from ..geometry import sphere as geo
from .base import Constraint


class CellGeometry:
    """Per-cell area and perimeter, the unit vertex directions, and the per-corner terms that the
    gradients reuse. ``center`` (the normalised vertex centroid of each cell, ``(n_cells, 3)``) is
    computed on first use: the forces do not need it."""

    def __init__(self, area, perimeter, unit, radius, corners=None, center=None):
        self.area, self.perimeter, self.unit, self.radius = area, perimeter, unit, radius
        self.corners = corners
        self._center = center

    @property
    def center(self):
        if callable(self._center):
            self._center = self._center()
        return self._center


# Vectors are (3, n) arrays, one contiguous row per Cartesian component: elementwise vector
# arithmetic is one NumPy call over all components; dot and cross products work on row views.
def _cross(a, b):
    xp = array_module(a, b)
    return xp.stack((a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]))


def _dot(a, b):
    # one fused pass (einsum), 1.7x to 2.6x faster than three products and two sums
    return array_module(a, b).einsum("ij,ij->j", a, b)


_POOL = None
PARALLEL_MIN_VERTICES = 16384   # below this, one thread; blocks hold at least half as many vertices
BLOCK_VERTICES = 16384          # per block: its per-corner vectors (3 x 3 x 16384 doubles, 1.2 MB) stay in cache


def _vertex_blocks(state):
    """Contiguous vertex ranges for large NumPy states: at least one per CPU core (NumPy releases
    the GIL inside its loops, so blocks run on all cores at once) and small enough that a block's
    temporaries stay in cache (measured, 65,536 cells on 2 cores: 28-30 ms in blocks of 16,384
    vertices, 32-35 ms in blocks of 32,768 or 65,536)."""
    nv = state.n_vertices
    workers = os.cpu_count() or 1
    if state.device.is_gpu or nv < PARALLEL_MIN_VERTICES:
        return [(0, nv)]
    count = max(min(workers, nv // (PARALLEL_MIN_VERTICES // 2)), -(-nv // BLOCK_VERTICES))
    edges = np.linspace(0, nv, count + 1).astype(int)
    return [(int(a), int(b)) for a, b in zip(edges[:-1], edges[1:])]


def _in_parallel(fn, items):
    """``[fn(item) for item in items]``, on a thread pool when there are several items."""
    global _POOL
    if len(items) == 1:
        return [fn(items[0])]
    if _POOL is None:
        from concurrent.futures import ThreadPoolExecutor
        _POOL = ThreadPoolExecutor(max_workers=os.cpu_count(), thread_name_prefix="spherevm")
    return [f.result() for f in [_POOL.submit(fn, item) for item in items]]


class Sphere(Constraint):
    """Sphere of radius R (per replica, stored in ``State.radius``) centred at the origin.

    Perimeters are sums of geodesic arcs ``R theta``; areas are fans of signed spherical triangles
    about the cell's first vertex, with the triple product taken of differences so that small
    cells keep full relative accuracy. Area gradients come from the edges alone (each edge's end
    sweeps a thin triangle), with no fan apex. Normal: ``x/|x|``; ``P_N(x) = R x/|x|``.
    """

    name = "sphere"

    def normal(self, x):
        return geo.normalize(x)

    def project_tangent(self, x, v):
        """``v - (v.n) n`` with ``n = x/|x|`` (last axis of length 3)."""
        xp = array_module(x, v)
        c = xp.einsum("...i,...i->...", v, x) / xp.einsum("...i,...i->...", x, x)
        return v - c[..., None] * x

    def project_normal(self, x, radius):
        xp = array_module(x)
        return xp.asarray(radius)[..., None] * geo.normalize(x)

    def geodesic_offset(self, x, direction, distance, radius):
        """Exact geodesic step: ``R (cos(s/R) x_hat + sin(s/R) direction)``."""
        xp = array_module(x)
        phi = (distance / radius)[..., None]
        return xp.asarray(radius)[..., None] * (xp.cos(phi) * geo.normalize(x) + xp.sin(phi) * direction)

    def triangle_area(self, a, b, c, radius):
        """``R^2`` times the signed solid angle of the unit vectors (geometry.sphere.solid_angle)."""
        xp = array_module(radius)
        return xp.asarray(radius) ** 2 * geo.solid_angle(geo.normalize(a), geo.normalize(b), geo.normalize(c))

    def chord_length(self, length, radius):
        """``2 R sin(L / 2R)`` (capped at the diameter)."""
        xp = array_module(length, radius)
        return 2.0 * radius * xp.sin(xp.minimum(length / (2.0 * radius), xp.pi / 2))

    def distance_to_surface(self, x, radius):
        xp = array_module(x)
        return xp.sqrt((x * x).sum(axis=-1)) - radius

    def total_area_np(self, radius):
        return 4.0 * np.pi * np.asarray(radius, dtype=np.float64) ** 2

    # -------------------------------------------------------------- per-corner metric
    # Corner (v, k) lies in cell vertex_cells[v, k], where the boundary runs counter-clockwise from
    # v to n_k = vertex_neighbors[v, k]; the edge (v, n_k) borders cells k and k-1. Corner arrays
    # are slot-major, shape (3 components, 3 slots, vertices of the block): a vertex quantity
    # broadcasts over the slot axis and the sum over a vertex's corners adds three contiguous rows.

    def _corner_index(self, state):
        """Per vertex block, the slot-major corner tables: next vertex, the corner's cell, the cell
        before it (k - 1) and the cell's first vertex (its fan apex). Cached per State and topology
        version (T1 flips bump it)."""
        return state.cached((self, "corner_index"), lambda: self._build_corner_index(state), topology=True)

    @staticmethod
    def _build_corner_index(state):
        xp = state.device.xp
        vn, vc = state.vertex_neighbors.astype(np.intp), state.vertex_cells.astype(np.intp)
        first = state.cell_vertices[:, 0].astype(np.intp)
        result = []
        for lo, hi in _vertex_blocks(state):
            cells = xp.ascontiguousarray(vc[lo:hi].T).reshape(-1)
            before = xp.ascontiguousarray(xp.roll(vc[lo:hi], 1, axis=1).T).reshape(-1)
            result.append(dict(lo=lo, hi=hi, next=xp.ascontiguousarray(vn[lo:hi].T).reshape(-1),
                               cells=cells, apex=first[cells], both=xp.concatenate((cells, before))))
        return result

    def cell_geometry(self, state) -> CellGeometry:
        """Areas and perimeters, and the per-corner terms the gradients reuse.

        Perimeter: half-angles ``atan2(|b - d|, |b + d|)`` of the edges ``b -> d``. Area: the fan
        of signed triangles ``(a, b, d)`` about the cell's first vertex ``a``, each
        ``2 atan2(a.(b x d), 1 + a.b + a.d + b.d)`` (the area does not depend on the apex).
        """
        xp = state.device.xp
        n = state.n_cells
        u, rv = self._unit_components(state)
        index = self._corner_index(state)

        def corners(block):
            ub = u[:, None, block["lo"]:block["hi"]]                    # (3, 1, nb): b, for every slot
            d = xp.take(u, block["next"], axis=1).reshape(3, 3, -1)     # the next vertex
            m = ub - d
            m2 = _dot(m.reshape(3, -1), m.reshape(3, -1))
            q = xp.maximum(4.0 - m2, 0.0)                               # |b + d|^2 = 4 - |b - d|^2
            sm, sp = xp.sqrt(m2), xp.sqrt(q)
            half = xp.arctan2(sm, sp)                                   # theta / 2
            x = _cross(m, ub).reshape(3, -1)                            # b x d, from b - d
            a = xp.take(u, block["apex"], axis=1).reshape(3, 3, -1)
            num = _dot((a - ub).reshape(3, -1), x)                      # a.(b x d) = (a - b).(b x d)
            den = 0.5 * q + _dot(a.reshape(3, -1), (ub + d).reshape(3, -1))   # (1 + b.d) + a.(b + d)
            cells = block["cells"]
            sums = (xp.bincount(cells, weights=half, minlength=n),
                    xp.bincount(cells, weights=xp.arctan2(num, den), minlength=n))
            return dict(m=m.reshape(3, -1), x=x, q=q, two_sin=sm * sp), sums

        parts = _in_parallel(corners, index)
        R = state.radius[state.cell_replica]
        perimeter = (2.0 * R) * sum(p[1][0] for p in parts)
        area = (2.0 * R * R) * sum(p[1][1] for p in parts)
        return CellGeometry(area=area, perimeter=perimeter, unit=u.T,
                            radius=state.radius[state.vertex_replica],
                            corners=dict(index=index, parts=[p[0] for p in parts], u=u, rv=rv),
                            center=lambda: self.cell_centers(state, u))

    @staticmethod
    def _unit_components(state):
        """Unit vertex directions as a (3, V) component array, and the distances ``|x|`` (V,)."""
        comp = state.device.xp.ascontiguousarray(state.positions.T)
        rv = state.device.xp.sqrt(_dot(comp, comp))
        return comp / rv, rv

    def cell_centers(self, state, unit=None):
        """Normalised vertex centroid of each cell, ``(n_cells, 3)`` on the state's device."""
        xp = state.device.xp
        if unit is None:
            unit = self._unit_components(state)[0]
        cells = state.vertex_cells.reshape(-1)
        corner_unit = xp.repeat(unit, 3, axis=1)
        summed = xp.stack([xp.bincount(cells, weights=c, minlength=state.n_cells) for c in corner_unit])
        return (summed / xp.sqrt(_dot(summed, summed))).T

    @staticmethod
    def _edge_factors(part):
        """Per corner, on the unit sphere, the factors that turn ``b x d`` and ``b - d`` into the
        area term ``w(b, d) = (b x d)/(1 + b.d)`` (tangent at b) and the length term
        ``(b - d)/sin(theta)``, whose tangent part is the gradient of the edge angle theta(b, d)
        with respect to b (0 for a zero-length edge).

        The area of a cell changes, when its vertex b moves, by the two thin triangles its edges
        sweep: moving the end b of an arc of angle theta by a tangent step s sweeps
        ``tan(theta/2) (s . n)``, n the arc's unit normal at b. So the area gradient at b is
        ``w(b, p) - w(b, d)`` with ``w(b, d) = (b x d)/(1 + b.d) = tan(theta/2) n``, p and d the
        previous and next vertices (no fan apex involved).
        """
        xp = array_module(part["q"])
        return 2.0 / xp.maximum(part["q"], 1e-300), 2.0 / xp.maximum(part["two_sin"], 1e-150)

    def shape_gradient(self, state, geometry: CellGeometry, d_area, d_perimeter):
        """Surface gradient (V, 3) of ``sum_c d_area[c] A_c + d_perimeter[c] P_c``.

        With ``d_area = dE/dA`` and ``d_perimeter = dE/dP`` this is the gradient of any energy of the
        cell areas and perimeters (chain rule); the vertex model's forces are minus it.

        Per vertex v with edges to n_k: ``sum_k (dA[k-1] - dA[k]) w(v, n_k) + (dP[k] + dP[k-1])
        dtheta(v, n_k)/dv`` on the unit sphere (see :meth:`_edge_factors`), with ``dA`` scaled by
        R^2 and ``dP`` by R, projected on the tangent plane and divided by ``|x_v|`` (positions
        ``x = |x| u``).
        """
        xp = state.device.xp
        g = geometry.corners
        R = state.radius[state.cell_replica]
        weights = xp.stack((d_area * (R * R), d_perimeter * R))
        out = xp.empty((state.n_vertices, 3))

        def block(pair):
            index, part = pair
            lo, hi = index["lo"], index["hi"]
            nc = 3 * (hi - lo)
            w = xp.take(weights, index["both"], axis=1)             # (2, 6nb): cell k, then cell k-1
            area, length = self._edge_factors(part)
            alpha = (w[0, nc:] - w[0, :nc]) * area
            beta = (w[1, :nc] + w[1, nc:]) * length
            s = (alpha * part["x"] + beta * part["m"]).reshape(3, 3, -1)
            s = s[:, 0] + s[:, 1] + s[:, 2]
            u = g["u"][:, lo:hi]
            s -= _dot(s, u) * u                                      # onto the tangent plane
            out[lo:hi] = (s / g["rv"][lo:hi]).T

        _in_parallel(block, list(zip(g["index"], g["parts"])))
        return out

    def corner_gradients(self, state, geometry: CellGeometry):
        """Surface gradients (with respect to positions) of each corner's cell area and perimeter.

        Returns ``(dA, dP)``, both ``(V, 3, 3)``: ``dA[v, k]`` is the gradient of the area of cell
        ``vertex_cells[v, k]`` with respect to ``positions[v]``; likewise ``dP``. (The forces use
        :meth:`shape_gradient`, which sums these without building them.)
        """
        xp = state.device.xp
        g = geometry.corners
        terms = []
        for part in g["parts"]:
            area, length = self._edge_factors(part)
            terms.append((area * part["x"], length * part["m"]))
        # slot-major (3, 3, nb) blocks -> (V, slot, component)
        area, length = ([xp.concatenate([t[j].reshape(3, 3, -1) for t in terms], axis=2).transpose(2, 1, 0)
                         for j in (0, 1)])
        u = g["u"].T[:, None, :]
        length = length - (length * u).sum(axis=2)[..., None] * u
        scale = (geometry.radius / g["rv"])[:, None, None]      # R / |x|
        # cell k at v is bounded by the edges to n_k (v -> n_k) and n_{k+1} (n_{k+1} -> v)
        dA = (xp.roll(area, -1, axis=1) - area) * (scale * geometry.radius[:, None, None])
        dP = (length + xp.roll(length, -1, axis=1)) * scale
        return dA, dP

    def edge_lengths(self, state, u, v):
        """Geodesic lengths of the edges (u[i], v[i])."""
        pos = state.positions
        return state.radius[state.vertex_replica[u]] * geo.geodesic_length(geo.normalize(pos[u]),
                                                                           geo.normalize(pos[v]))
