"""The sphere centred at the origin: geodesic perimeters and spherical-polygon areas."""
from __future__ import annotations

import os
import weakref
from dataclasses import dataclass

import numpy as np

from ..device import array_module
from ..geometry import sphere as geo
from .base import Constraint


@dataclass
class CellGeometry:
    """Per-cell area, perimeter and fan apex (unit centroid), the unit vertex directions, and the
    per-corner fan terms that the gradients reuse (components as separate contiguous arrays)."""
    area: object
    perimeter: object
    apex: object
    unit: object
    radius: object          # per vertex
    corners: dict = None    # per-corner terms, see Sphere.cell_geometry


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
BLOCK_VERTICES = 32768          # per block: its per-corner temporaries (~0.8 MB each) stay in cache


def _vertex_blocks(state):
    """Contiguous vertex ranges for large NumPy states: at least one per CPU core (NumPy releases
    the GIL inside its loops, so blocks run on all cores at once) and small enough that a block's
    temporaries stay in cache (measured: 65,536 cells, 2 cores: 98 ms in 2 blocks, 72 ms in 4)."""
    nv = state.n_vertices
    workers = os.cpu_count() or 1
    if state.device.is_gpu or nv < PARALLEL_MIN_VERTICES:
        return [(0, nv)]
    count = max(min(workers, nv // (PARALLEL_MIN_VERTICES // 2)), -(-nv // BLOCK_VERTICES))
    edges = np.linspace(0, nv, count + 1).astype(int)
    return [(int(a), int(b)) for a, b in zip(edges[:-1], edges[1:])]


def _in_parallel(fn, blocks, xp, with_index=False):
    """[fn(lo, hi[, i]) for each block], on a thread pool when there are several blocks."""
    global _POOL
    args = [(lo, hi, i) if with_index else (lo, hi) for i, (lo, hi) in enumerate(blocks)]
    if len(blocks) == 1:
        return [fn(*args[0])]
    if _POOL is None:
        from concurrent.futures import ThreadPoolExecutor
        _POOL = ThreadPoolExecutor(max_workers=os.cpu_count(), thread_name_prefix="spherevm")
    return [f.result() for f in [_POOL.submit(fn, *a) for a in args]]


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
    # -------------------------------------------------------------- per-corner metric
    # Corner i = 3 v + k lies in cell c_i = vertex_cells[v, k]; its fan triangle is
    # (apex_c, u_v, u_next) with next = vertex_neighbors[v, k]. Everything is computed on flat
    # corner arrays, one contiguous array per Cartesian component, and summed per cell by bincount.

    def cell_geometry(self, state) -> CellGeometry:
        """Areas, perimeters, apexes; keeps each corner's fan numerator N and denominator D."""
        xp = state.device.xp
        n = state.n_cells
        comp = xp.ascontiguousarray(state.positions.T)
        rv = xp.sqrt(_dot(comp, comp))
        u = comp / rv
        cells = state.vertex_cells.reshape(-1)
        nxt = state.vertex_neighbors.reshape(-1)
        blocks = _vertex_blocks(state)

        def apex_sums(lo, hi):
            b = xp.repeat(u[:, lo:hi], 3, axis=1)                      # the corners' own vertex
            return b, [xp.bincount(cells[3 * lo:3 * hi], weights=c, minlength=n) for c in b]

        parts = _in_parallel(apex_sums, blocks, xp)
        summed = xp.stack([sum(p[1][i] for p in parts) for i in range(3)])
        apex_c = summed / xp.sqrt(_dot(summed, summed))

        def fan(block, part):
            lo, hi = block
            b = part[0]
            cl = cells[3 * lo:3 * hi]
            a = apex_c[:, cl]                                          # fan apex of the corner's cell
            d = u[:, nxt[3 * lo:3 * hi]]                               # the next vertex
            num = _dot(a, _cross(b, d))
            den = 1.0 + _dot(a, b + d) + _dot(b, d)                    # 1 + a.b + b.d + d.a
            minus = b - d
            m2 = _dot(minus, minus)
            # half-angles (the factors 2 are applied per cell): theta/2 = atan2(|b - d|, |b + d|), with
            # |b + d|^2 = 4 - |b - d|^2 for unit vectors (exact enough: the sum is never small here)
            lengths = xp.arctan2(xp.sqrt(m2), xp.sqrt(xp.maximum(4.0 - m2, 0.0)))
            omegas = xp.arctan2(num, den)
            sums = (xp.bincount(cl, weights=lengths, minlength=n), xp.bincount(cl, weights=omegas, minlength=n))
            return dict(a=a, b=b, d=d, num=num, den=den, minus=minus, m2=m2), sums

        fans = _in_parallel(lambda lo, hi, i: fan((lo, hi), parts[i]), blocks, xp, with_index=True)
        R = state.radius[state.cell_replica]
        perimeter = (2.0 * R) * sum(f[1][0] for f in fans)
        area = (2.0 * R * R) * sum(f[1][1] for f in fans)
        corner_blocks = [f[0] for f in fans]
        num = corner_blocks[0]["num"] if len(fans) == 1 else xp.concatenate([c["num"] for c in corner_blocks])
        den = corner_blocks[0]["den"] if len(fans) == 1 else xp.concatenate([c["den"] for c in corner_blocks])
        return CellGeometry(area=area, perimeter=perimeter, apex=apex_c.T, unit=u.T,
                            radius=state.radius[state.vertex_replica],
                            corners=dict(blocks=blocks, parts=corner_blocks, num=num, den=den, rv=rv, u=u))

    def _corner_terms(self, state, geometry, lo=0, hi=None, part=None):
        """Per-corner area gradient (fan triangles on both sides of the vertex, apex held fixed; not
        yet projected on the tangent plane, which callers do after summing over the corners) and the
        unit-sphere length gradient toward the next vertex (tangent), for vertices ``lo:hi``."""
        xp = state.device.xp
        g = geometry.corners
        hi = state.n_vertices if hi is None else hi
        if part is None:   # all corners, as one block
            part = {k: xp.concatenate([p[k] for p in g["parts"]], axis=-1)
                    for k in ("a", "b", "d", "num", "den", "minus", "m2")}
        a, b, d, num, den = part["a"], part["b"], part["d"], part["num"], part["den"]
        prev, pc = self._previous_corners(state)
        p = g["u"][:, prev[3 * lo:3 * hi]]
        num2, den2 = g["num"][pc[3 * lo:3 * hi]], g["den"][pc[3 * lo:3 * hi]]
        # d Omega(a, b, d)/db = 2 (D (d x a) - N (a + d)) / (N^2 + D^2); likewise for (p, b, a)
        s1 = 2.0 / (num * num + den * den)
        s2 = 2.0 / (num2 * num2 + den2 * den2)
        k1, k2, k3, k4 = s1 * den, s1 * num, s2 * den2, s2 * num2
        gA = k1 * _cross(d, a) - k2 * (a + d) + k3 * _cross(a, p) - k4 * (p + a)
        # d theta(b, d)/db = -t/|t|, t = (d - b) - ((d - b).b) b, |t|^2 = |d - b|^2 - ((d - b).b)^2;
        # written with minus = b - d: -t = minus - (minus.b) b; 0 for a zero-length edge
        minus = part["minus"]
        mb = _dot(minus, b)
        t2 = part["m2"] - mb * mb
        inv = 1.0 / xp.sqrt(xp.where(t2 > 0, t2, 1.0)) * (t2 > 0)
        gL = inv * (minus - mb * b)
        return gA, gL

    def shape_gradient(self, state, geometry: CellGeometry, d_area, d_perimeter):
        """Surface gradient (V, 3) of ``sum_c d_area[c] A_c + d_perimeter[c] P_c``.

        With ``d_area = dE/dA`` and ``d_perimeter = dE/dP`` this is the gradient of any energy of the
        cell areas and perimeters (chain rule); the vertex model's forces are minus it.
        """
        xp = state.device.xp
        g = geometry.corners
        out = xp.empty((state.n_vertices, 3))

        def block(lo, hi, i):
            gA, gL = self._corner_terms(state, geometry, lo, hi, g["parts"][i])
            cells = state.vertex_cells[lo:hi]
            wA = d_area[cells].reshape(-1)
            wP = d_perimeter[cells]
            wL = (wP + xp.roll(wP, 1, axis=1)).reshape(-1)   # edge v -> n_k borders cells k and k-1
            rv = g["rv"][lo:hi]
            radius = geometry.radius[lo:hi]
            sA, sP = radius * radius / rv, radius / rv

            def per_vertex(x):   # (3, 3n) corner values -> (3, n): the sum over each vertex's corners
                x = x.reshape(3, hi - lo, 3)
                return x[:, :, 0] + x[:, :, 1] + x[:, :, 2]

            area = per_vertex(wA * gA)
            u = g["u"][:, lo:hi]
            area -= _dot(area, u) * u                # project the area part on the tangent plane
            out[lo:hi] = (sA * area + sP * per_vertex(wL * gL)).T

        _in_parallel(block, g["blocks"], xp, with_index=True)
        return out

    def corner_gradients(self, state, geometry: CellGeometry):
        """Surface gradients (with respect to positions) of each corner's cell area and perimeter.

        Returns ``(dA, dP)``, both ``(V, 3, 3)``: ``dA[v, k]`` is the gradient of the area of cell
        ``vertex_cells[v, k]`` with respect to ``positions[v]``; likewise ``dP``. (The forces use
        :meth:`shape_gradient`, which sums these without building them.)
        """
        xp = state.device.xp
        gA, gL = self._corner_terms(state, geometry)
        nv = state.n_vertices
        rv = geometry.corners["rv"]
        b = geometry.corners["u"].T[:, None, :]
        dA = gA.T.reshape(nv, 3, 3)
        dA = (dA - (dA * b).sum(axis=2)[..., None] * b) * (geometry.radius ** 2 / rv)[:, None, None]
        lg = gL.T.reshape(nv, 3, 3)
        dP = (lg + xp.roll(lg, -1, axis=1)) * (geometry.radius / rv)[:, None, None]
        return dA, dP

    def _previous_corners(self, state):
        """For every corner (v, k): the previous vertex p and the index of p's corner in the same
        cell (whose next is v), whose fan triangle (apex, p, v) is v's other one in that cell.
        Cached per State and topology version (T1 flips bump it)."""
        cache = getattr(self, "_prev_cache", None)
        if cache is not None and cache[0]() is state and cache[1] == state.topology_version:
            return cache[2]
        xp = state.device.xp
        vn = state.vertex_neighbors
        prev = xp.roll(vn, -1, axis=1)
        v_ids = xp.arange(state.n_vertices, dtype=vn.dtype)[:, None]
        slot = (vn[prev] == v_ids[..., None]).argmax(axis=2)
        result = (prev.reshape(-1), (3 * prev + slot).reshape(-1))
        self._prev_cache = (weakref.ref(state), state.topology_version, result)
        return result

    def edge_lengths(self, state, u, v):
        """Geodesic lengths of the edges (u[i], v[i])."""
        pos = state.positions
        return state.radius[state.vertex_replica[u]] * geo.geodesic_length(geo.normalize(pos[u]),
                                                                           geo.normalize(pos[v]))
