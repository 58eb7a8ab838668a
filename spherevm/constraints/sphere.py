"""The sphere centred at the origin: geodesic perimeters and spherical-polygon areas."""
from __future__ import annotations

from itertools import zip_longest

import numpy as np

from ..device import array_module, weighted_bincount
from ..geometry import sphere as geo
from .base import CellMeasures, Constraint, DeviceSurface
from .cell_rows import fan_rows, fold
from .corners import corner_index, in_parallel
from .flat import FlatFacets

#: the metrics a Sphere measures with (docs/surfaces.md)
METRICS = ("geodesic", "flat")


class CellGeometry(CellMeasures):
    """Per-cell area and perimeter, the unit vertex directions, and the per-corner terms that the
    gradients reuse. ``center`` (the normalised vertex centroid of each cell, ``(n_cells, 3)``) is
    computed on first use: the forces do not need it."""

    def __init__(self, area, perimeter, unit, radius, corners=None, center=None, area_vector=None):
        self.area, self.perimeter, self.unit, self.radius = area, perimeter, unit, radius
        self.area_vector = area_vector
        self.corners = corners
        self._center = center


# Vectors are (3, n) arrays, one contiguous row per Cartesian component: elementwise vector
# arithmetic is one NumPy call over all components; dot and cross products work on row views.
def _cross(a, b):
    # into one output with one scratch row: large temporaries are costly (each a fresh allocation
    # the kernel maps and faults in; measured 1.6 ms with nine of them and a stack, 0.18 ms so,
    # for (3, 3, 16384)); the same products and differences, so the same numbers
    xp = array_module(a, b)
    shape = a.shape if a.shape == b.shape else np.broadcast_shapes(a.shape, b.shape)
    out, scratch = xp.empty(shape), xp.empty(shape[1:])
    for i, j, k in ((0, 1, 2), (1, 2, 0), (2, 0, 1)):
        xp.multiply(a[j], b[k], out=out[i])
        xp.multiply(a[k], b[j], out=scratch)
        out[i] -= scratch
    return out


def _dot(a, b):
    # one fused pass (einsum), 1.7x to 2.6x faster than three products and two sums
    return array_module(a, b).einsum("ij,ij->j", a, b)

#: the sphere's device code (geometry/surface.cuh's functions on the geodesic metric)
DEVICE_SURFACE = DeviceSurface('#include "constraints/sphere.cuh"', "SphereSurface")


class Sphere(Constraint):
    """Sphere of radius R (per replica, stored in ``State.size``) centred at the origin.

    Perimeters are sums of geodesic arcs ``R theta``; areas are fans of signed spherical triangles
    about the cell's first vertex, with the triple product taken of differences so that small
    cells keep full relative accuracy. Area gradients come from the edges alone (each edge's end
    sweeps a thin triangle), with no fan apex. Normal: ``x/|x|``; ``P_N(x) = R x/|x|``.

    Parameters
    ----------
    metric : {"geodesic", "flat"}
        "geodesic" (default): the exact metric above. "flat": straight chords and flat vector areas
        (:class:`FlatSphere`, the metric every other surface uses; NumPy only).
    """

    name = "sphere"
    metric = "geodesic"
    drawing = "ball"
    rigid_motions = ("rotations",)

    def __new__(cls, *args, metric=None, **kwargs):
        if metric is not None and metric not in METRICS:
            raise ValueError(f"metric must be one of {METRICS}, got {metric!r}")
        return super().__new__(FlatSphere if cls is Sphere and metric == "flat" else cls)

    def __init__(self, metric=None):
        if metric is not None and metric != self.metric:
            raise ValueError(f"{type(self).__name__} measures with the {self.metric} metric, got metric={metric!r}")

    def normal(self, x, size=None):
        return geo.normalize(x)

    def project_tangent(self, x, v, size=None):
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

    def gaussian_curvature(self, x, radius):
        """``1 / R^2``."""
        if radius is None or not np.all(np.asarray(radius) > 0):
            raise ValueError(f"radius must be given and positive on a sphere, got {radius}")
        return np.broadcast_to(1.0 / np.asarray(radius, dtype=np.float64) ** 2, np.shape(x)[:-1]).copy()

    def polygon_area(self, points, radius) -> float:
        """The spherical polygon's area (:func:`spherevm.geometry.sphere.polygon_area`)."""
        return float(geo.polygon_area(geo.normalize(points), float(radius)))

    def device_surface(self):
        """SphereSurface (constraints/sphere.cuh), the geodesic metric; None under the flat metric."""
        return DEVICE_SURFACE if self.metric == "geodesic" else None

    def chord_length(self, length, radius):
        """``2 R sin(L / 2R)`` (capped at the diameter)."""
        xp = array_module(length, radius)
        return 2.0 * radius * xp.sin(xp.minimum(length / (2.0 * radius), xp.pi / 2))

    def distance_to_surface(self, x, radius):
        xp = array_module(x)
        return xp.sqrt((x * x).sum(axis=-1)) - radius

    def total_area_np(self, radius):
        return 4.0 * np.pi * np.asarray(radius, dtype=np.float64) ** 2

    def size_for_area(self, radius, area):
        """The radius of the sphere of area ``area``: sqrt(area / 4 pi)."""
        return np.sqrt(np.asarray(area, dtype=np.float64) / (4.0 * np.pi))

    def orientation_points(self, x, reference=None, size=None):
        """Unit vectors (a great circle's normal is ``a x b``)."""
        return x / np.linalg.norm(x, axis=-1)[..., None]

    def geodesic_distance(self, a, b, radius):
        """``R`` times the angle between ``a`` and ``b`` (``2 atan2(|a^ - b^|, |a^ + b^|)``)."""
        a = a / np.linalg.norm(a, axis=-1)[..., None]
        b = b / np.linalg.norm(b, axis=-1)[..., None]
        return radius * 2.0 * np.arctan2(np.linalg.norm(a - b, axis=-1), np.linalg.norm(a + b, axis=-1))

    def cover_error(self, state, areas, replica, total, surface) -> str:
        cells = np.flatnonzero(state.cell_replica_np() == replica)
        if abs(total + surface) <= 1e-9 * surface:
            return (f"cell {int(cells[0])} and every other cell is listed clockwise seen from outside (their areas "
                    "add up to -4 pi R^2); list cell vertices counter-clockwise")
        c = int(cells[np.argmin(areas[cells])])
        return (f"the cell areas add up to {total:.12g}, not the sphere's 4 pi R^2 = {surface:.12g}: cell {c} "
                f"(measured {areas[c]:.6g}) is larger than a hemisphere, which spherevm cannot measure (areas are "
                "fans of spherical triangles: such a cell gets A - 4 pi R^2), or cells overlap; use more cells, so "
                "that every cell is smaller than a hemisphere")

    def check_cell_areas(self, state, areas, surface):
        """A cell over a hemisphere is refused: its fan area would be A - 4 pi R^2."""
        crep = state.cell_replica_np()
        big = np.flatnonzero(areas > 0.5 * surface[crep])
        if len(big):
            c = int(big[0])
            raise ValueError(f"cell {c} covers {areas[c] / surface[crep[c]]:.3g} of its sphere, more than a "
                             "hemisphere: spherevm measures cells smaller than a hemisphere only; use more cells")

    # -------------------------------------------------------------- per-corner metric
    # Corner tables and vertex blocks: spherevm.constraints.corners.

    def cell_geometry(self, state, area_vectors: bool = False, metric: bool = True) -> CellGeometry:
        """Areas and perimeters (``metric``), area vectors (``area_vectors``), and the per-corner
        terms the gradients reuse.

        Perimeter: half-angles ``atan2(|b - d|, |b + d|)`` of the edges ``b -> d``. Area: the fan
        of signed triangles ``(a, b, d)`` about the cell's first vertex ``a``, each
        ``2 atan2(a.(b x d), 1 + a.b + a.d + b.d)`` (the area does not depend on the apex). Area
        vector, ``(n_cells, 3)``: the fan ``1/2 sum (x_j - x_0) x (x_{j+1} - x_0)`` about the cell's
        first vertex of the vertex positions (the vector area ``1/2 sum x_b x x_d``), from
        differences of the positions themselves: small cells keep full relative accuracy, also in
        differences of nearby normals (unit directions would add their rounding, about eps R/l
        relative). NumPy sums it in cell order (:mod:`spherevm.constraints.cell_rows`, blocks of
        cells run with the corner blocks); the GPU per corner, ``(x_b - x_0) x (x_d - x_b)`` for
        the edge ``b -> d``, with ``weighted_bincount``.
        """
        xp = state.device.xp
        n = state.n_cells
        comp, u, rv = self._unit_components(state)
        index = corner_index(state)
        fans = area_vectors and not state.device.is_gpu
        area_vector = xp.empty((3, n)) if fans else None

        def corners(block):
            lo, hi = block["lo"], block["hi"]
            part, sums = {}, {}
            if area_vectors:
                xd = comp.take(block["next"], axis=1).reshape(3, 3, -1)
                part["f"] = xd[:, :2] - xd[:, 1:]                       # x_{n_k} - x_{n_{k+1}}, k = 0, 1
                if not fans:
                    xb = comp[:, None, lo:hi]
                    r = xb - xp.take(comp, block["apex"], axis=1).reshape(3, 3, -1)
                    sums["area_vector"] = weighted_bincount(block["components"], weights=_cross(r, xd - xb).reshape(-1),
                                                            minlength=3 * n)
            if not metric:
                return part, sums
            d = xp.take(u, block["next"], axis=1).reshape(3, 3, -1)      # the next vertex
            a = xp.take(u, block["apex"], axis=1).reshape(3, 3, -1)
            ub = u[:, None, lo:hi]                                      # (3, 1, nb): b, for every slot
            m = ub - d
            m2 = _dot(m.reshape(3, -1), m.reshape(3, -1))
            q = xp.maximum(4.0 - m2, 0.0)                               # |b + d|^2 = 4 - |b - d|^2
            sm, sp = xp.sqrt(m2), xp.sqrt(q)
            half = xp.arctan2(sm, sp)                                   # theta / 2
            x = _cross(m, ub).reshape(3, -1)                            # b x d, from b - d
            num = _dot((a - ub).reshape(3, -1), x)                      # a.(b x d) = (a - b).(b x d)
            den = 0.5 * q + _dot(a.reshape(3, -1), (ub + d).reshape(3, -1))   # (1 + b.d) + a.(b + d)
            cells = block["cells"]
            sums.update(perimeter=weighted_bincount(cells, weights=half, minlength=n),
                        area=weighted_bincount(cells, weights=xp.arctan2(num, den), minlength=n))
            part.update(m=m.reshape(3, -1), x=x, q=q, two_sin=sm * sp)
            return part, sums

        def fan(rows):
            x = comp.take(rows["table"], axis=1, mode="clip")           # (3, 4h, rows): the diagonals' ends
            h = x.shape[1] // 4
            # two triangles at a time: y_j x y_{j+1} + y_{j+1} x y_{j+2} = y_{j+1} x (x_{j+2} - x_j), y = x - x_0
            d = xp.subtract(x[:, :2 * h], x[:, 2 * h:], out=x[:, :2 * h])
            twice = _cross(d[:, :h], d[:, h:]).sum(axis=1)
            xp.multiply(fold(twice, rows), 0.5, out=area_vector[:, rows["c0"]:rows["c1"]])

        jobs = [(corners, block) for block in index]
        if fans:      # each core a corner block and a block of fans in turn (measured a little faster)
            jobs = [job for pair in zip_longest(jobs, [(fan, rows) for rows in fan_rows(state)]) for job in pair if job]
        done = in_parallel(lambda job: job[0](job[1]), jobs, threads=len(index) > 1)
        parts = [part for (fn, _), part in zip(jobs, done) if fn is corners]
        R = state.size[state.cell_replica]
        geometry = CellGeometry(area=None, perimeter=None, unit=u.T, radius=state.size[state.vertex_replica],
                                corners=dict(index=index, parts=[p[0] for p in parts], u=u, rv=rv),
                                center=lambda: self.cell_centers(state, u))
        if metric:
            geometry.perimeter = (2.0 * R) * sum(p[1]["perimeter"] for p in parts)
            geometry.area = (2.0 * R * R) * sum(p[1]["area"] for p in parts)
        if area_vectors:
            geometry.area_vector = (area_vector if fans else
                                    0.5 * sum(p[1]["area_vector"] for p in parts).reshape(3, n)).T
        return geometry

    @staticmethod
    def _unit_components(state):
        """The positions and the unit vertex directions as (3, V) component arrays, and the
        distances ``|x|`` (V,)."""
        comp = state.device.xp.ascontiguousarray(state.positions.T)
        rv = state.device.xp.sqrt(_dot(comp, comp))
        return comp, comp / rv, rv

    def cell_centers(self, state, unit=None):
        """Normalised vertex centroid of each cell, ``(n_cells, 3)`` on the state's device."""
        xp = state.device.xp
        if unit is None:
            unit = self._unit_components(state)[1]
        cells = state.vertex_cells.reshape(-1)
        corner_unit = xp.repeat(unit, 3, axis=1)
        summed = xp.stack([weighted_bincount(cells, weights=c, minlength=state.n_cells) for c in corner_unit])
        return (summed / xp.sqrt(_dot(summed, summed))).T

    def cell_centroids(self, state, method: str):
        """``method="area"``: the centre of mass of the spherical polygon, pushed radially onto the
        sphere: ``integral of n dA = (R^2 / 2) sum_edges theta_e (a_e x b_e) / |a_e x b_e|`` over the
        edges ``a_e -> b_e`` taken counter-clockwise (exact), normalised; a folded cell (area <= 0)
        falls back to the vertex centroid. ``"vertex"``: ``R`` times :meth:`cell_centers`."""
        xp = state.device.xp
        pos = state.positions
        unit = pos / xp.sqrt((pos * pos).sum(axis=1))[:, None]
        cells = state.vertex_cells.reshape(-1)            # corner k of vertex v lies in cell vertex_cells[v, k]
        n = state.n_cells

        def per_cell(w):                                  # w: (V, 3 corners, 3 components)
            return xp.stack([weighted_bincount(cells, weights=w[..., i].reshape(-1), minlength=n) for i in range(3)],
                            axis=1)

        vertex_centroid = self.cell_centers(state)
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
        return state.size[state.cell_replica][:, None] * direction

    def cell_normals(self, state):
        """The cell centres: unit vectors, so their own normals."""
        return self.cell_centers(state)

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

    def shape_gradient(self, state, geometry: CellGeometry, d_area, d_perimeter, d_area_vector=None):
        """Surface gradient (V, 3) of ``sum_c d_area[c] A_c + d_perimeter[c] P_c + d_area_vector[c] . a_c``.

        With ``d_area = dE/dA``, ``d_perimeter = dE/dP`` and ``d_area_vector = dE/da`` (``(n_cells,
        3)``) this is the gradient of any energy of the cell areas, perimeters and area vectors
        (chain rule); the vertex model's forces are minus it (``d_area_vector`` None), the bending
        force's too (``d_area`` and ``d_perimeter`` None; ``geometry`` with ``area_vectors``). A
        coefficient that is None leaves its term out (as zeros would).

        Per vertex v with edges to n_k: ``sum_k (dA[k-1] - dA[k]) w(v, n_k) + (dP[k] + dP[k-1])
        dtheta(v, n_k)/dv`` on the unit sphere (see :meth:`_edge_factors`), with ``dA`` scaled by
        R^2 and ``dP`` by R; the area vector of cell k moves with x_v by ``f_k x / 2``, ``f_k =
        x_{n_k} - x_{n_{k+1}}``, which adds ``sum_k f_k x da[k] / 2``, two cross products since
        ``f_0 + f_1 + f_2 = 0``: ``(f_0 x (da[0] - da[2]) + f_1 x (da[1] - da[2])) / 2``. Projected
        on the tangent plane (and the unit-sphere terms divided by ``|x_v|``: ``x = |x| u``).
        """
        xp = state.device.xp
        g = geometry.corners
        R = state.size[state.cell_replica]
        weights = None
        if d_area is not None or d_perimeter is not None:   # a missing one of the two: zero coefficients
            zero = xp.zeros(state.n_cells)
            weights = xp.stack(((zero if d_area is None else d_area) * (R * R),
                                (zero if d_perimeter is None else d_perimeter) * R))
        vectors = None if d_area_vector is None else 0.5 * d_area_vector.T
        if weights is None and vectors is None:
            return xp.zeros((state.n_vertices, 3))
        out = xp.empty((state.n_vertices, 3))

        def block(pair):
            index, part = pair
            lo, hi = index["lo"], index["hi"]
            nc = 3 * (hi - lo)
            rv = g["rv"][lo:hi]
            s = 0.0
            if weights is not None:
                w = xp.take(weights, index["both"], axis=1)         # (2, 6nb): cell k, then cell k-1
                area, length = self._edge_factors(part)
                alpha = (w[0, nc:] - w[0, :nc]) * area
                beta = (w[1, :nc] + w[1, nc:]) * length
                s = (alpha * part["x"] + beta * part["m"]).reshape(3, 3, -1)
                s = s[:, 0] + s[:, 1] + s[:, 2]
            if vectors is not None:
                w = vectors.take(index["cells"], axis=1).reshape(3, 3, -1)
                t = _cross(part["f"], w[:, :2] - w[:, 2:]).sum(axis=1)   # f_0 x (da[0] - da[2]) + f_1 x (da[1] - da[2])
                s = s + rv * t                                       # in units of the unit sphere's terms
            u = g["u"][:, lo:hi]
            s -= _dot(s, u) * u                                      # onto the tangent plane
            out[lo:hi] = (s / rv).T

        in_parallel(block, list(zip(g["index"], g["parts"])))
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
        return state.size[state.vertex_replica[u]] * geo.geodesic_length(geo.normalize(pos[u]),
                                                                           geo.normalize(pos[v]))


class FlatSphere(FlatFacets, Sphere):
    """The sphere under the flat-facet metric, made by ``Sphere(metric="flat")``: edges are straight
    chords and cell areas flat vector areas (:mod:`spherevm.constraints.flat`), whose errors against
    the geodesic ones shrink as (cell size / R)^2 (docs/surfaces.md). Everything that is about the
    sphere itself rather than about measuring cells stays the sphere's: normals, projections,
    ``total_area_np`` (4 pi R^2, so <A> and the parameters keep their scale), and the signed
    geodesic areas that judge a tiling (:meth:`tiling_areas_np`, :meth:`triangle_area`: which points
    of the sphere each cell covers). The GPU kernels implement the geodesic metric only."""

    metric = "flat"

    def tiling_areas_np(self, state):
        """The cells' exact spherical areas: the flat ones do not add up to 4 pi R^2."""
        return state.device.to_numpy(Sphere.cell_geometry(self, state).area)

    def __repr__(self):
        return "Sphere(metric='flat')"
