"""Surfaces given implicitly, ``F(x) = 0``: the base class of the torus, the ellipsoid, the Gaussian
bump and a user's own surface.

A subclass gives ``F`` and ``grad F`` as functions of the points ``x`` (..., 3) and of the surface's
parameters ``size`` (..., k), one row per point, whose last axis holds the parameters named in
``size_names`` (a State keeps one row per replica, so one batched State holds surfaces of different
sizes). Everything else follows: the normal ``n = grad F / |grad F|``, ``P_T = I - n n^T``, the closest
point ``P_N`` (Newton iterations, or a closed form the subclass gives by overriding
:meth:`ImplicitSurface.project_normal`) and the flat-facet metric of
:mod:`spherevm.constraints.flat` (straight chords, vector areas, exact gradients). With
``periodic = True`` the first two parameters are a periodic box ``(Lx, Ly)`` in x and y: positions
are stored wrapped into it and edges are minimum images, as on the periodic plane.
"""
from __future__ import annotations

import numpy as np

from ..device import array_module
from ..geometry import flat
from ..geometry.sphere import _cross, _dot
from .base import Constraint
from . import implicit_device
from .flat import FlatFacets

#: the step, in units of the length scale, of the second difference that tells a smooth surface from
#: one whose gradient vanishes on it (:meth:`ImplicitSurface.check_regular`)
REGULARITY_STEP = 1e-4
#: the fewest cells of a random tiling of an implicit surface (flat facets measure larger cells
#: poorly, and small periodic networks are rarely simple)
MIN_TILING_CELLS = 16
#: cheap foot-point steps before the points still moving switch to Newton steps with the Hessian
#: (a step from a distance d shrinks the error by about d times the curvature: points a step off the
#: surface settle in two or three)
FOOT_POINT_STEPS = 6
#: the central-difference step of the Hessian, in length scales
HESSIAN_STEP = 1e-5


def rejection(rng, n, draw, accept):
    """``n`` samples of ``draw(m)`` (m at a time) kept with probability ``accept(samples)`` (<= 1),
    in the order drawn."""
    kept, count = [], 0
    while count < n:
        sample = draw(2 * n)
        sample = sample[rng.random(len(sample)) < accept(sample)]
        kept.append(sample)
        count += len(sample)
    return np.concatenate(kept)[:n]


class ImplicitSurface(FlatFacets, Constraint):
    """A surface ``F(x, size) = 0`` measured with the flat-facet metric. Subclass it and give
    :meth:`F`, :meth:`grad_F`, ``size_names``, ``euler_characteristic`` and :meth:`total_area_np`
    (and, optionally, a closed-form :meth:`project_normal` and :meth:`length_scale`).

    The closest point of ``x`` is found by iterating ``p <- p + P_T(p) (x - p) - F(p) grad F / |grad
    F|^2`` from ``p = x``: each step moves along the level set towards ``x`` and onto ``F = 0`` (a
    Newton step in the normal direction), so the fixed point is the point of the surface where ``x -
    p`` is normal to it. Points still moving after ``FOOT_POINT_STEPS`` take Newton steps on the
    closest-point equations ``p - x + lambda grad F = 0, F = 0`` (the Hessian by differences of grad
    F). The iterations stop when a step is below ``tolerance`` times the length scale (1e-14), or
    raise after ``max_iterations``.
    """

    name = "implicit"
    metric = "flat"
    #: the per-replica parameters, the last axis of ``size``; ``size_shape`` follows from them
    size_names = ()
    size_shape = (0,)
    #: True: the first two parameters are a periodic box (Lx, Ly) in x and y
    periodic = False
    max_iterations = 60
    tolerance = 1e-14
    #: flat facets cut corners: their areas add up to less than the surface's, by a relative
    #: O(<A> curvature^2); a tiling covers the surface once when the sum is the area to within half
    #: of it (twice over it would be twice the area)
    cover_tolerance = 0.5
    #: the GPU (constraints/implicit_device.py): CUDA code defining F and grad F, as a string or the
    #: path of a .cuh file (relative to the class's module); True: it defines project too
    cuda_code = None
    cuda_file = None
    cuda_projection = False
    #: the names of the values the CUDA code reads as ``p[0], p[1], ...`` (:meth:`device_parameters`);
    #: None: ``size_names``, the parameters themselves. A periodic surface's first two are its box
    device_parameter_names = None

    def __init_subclass__(cls, **kwargs):
        super().__init_subclass__(**kwargs)
        cls.size_shape = (len(cls.size_names),)
        names = cls.device_parameter_names
        if names is not None and cls.periodic and tuple(names[:2]) != tuple(cls.size_names[:2]):
            raise TypeError(f"{cls.__name__}: a periodic surface's first two device parameters are its box "
                            f"{tuple(cls.size_names[:2])}, got {tuple(names[:2])}")

    # ------------------------------------------------------------------ what a subclass gives
    def F(self, x, size):
        """The implicit function at the points ``x`` (..., 3), ``size`` (..., k) per point."""
        raise NotImplementedError(f"{type(self).__name__} must define F(x, size)")

    def grad_F(self, x, size):
        """``grad F`` (..., 3) at the points ``x``."""
        raise NotImplementedError(f"{type(self).__name__} must define grad_F(x, size)")

    def device_parameters(self, size):
        """The values the CUDA code reads as ``p``, per row of ``size`` (n, k): ``size`` itself, unless the
        class names others in ``device_parameter_names`` and derives them here once per size, rather
        than in every evaluation of F and grad F (reciprocals, wavenumbers: a division costs tens of
        multiplications on a GPU). Returns an (n, m) array, m = len(device_parameter_names) or k."""
        return size

    def device_surface(self):
        """``Implicit<Shape>`` of this class's CUDA code (:func:`implicit_device.device_surface`);
        ValueError, saying what to add, if it has none."""
        return implicit_device.device_surface(self)

    def has_device_code(self) -> bool:
        return implicit_device.shape_code(type(self)) is not None

    def kernel_size(self, state):
        """Per replica the parameters, the length scale and half the area (:func:`implicit_device.kernel_size`)."""
        return implicit_device.kernel_size(self, state)

    def length_scale(self, size):
        """A length per row of ``size`` (tolerances scale with it): the largest parameter."""
        return array_module(size).abs(size).max(axis=-1)

    def parameters(self, size):
        """The columns of ``size`` (..., k), one array each, in the order of ``size_names``."""
        return tuple(size[..., i] for i in range(len(self.size_names)))

    def check_size(self, size) -> np.ndarray:
        """``size`` as a float64 array (n, k), or ValueError naming the parameter that is out of
        range (each must be positive and finite; subclasses check more in :meth:`check_parameters`)."""
        s = np.asarray(size, dtype=np.float64)
        k = len(self.size_names)
        if s.shape[-1:] != (k,) or s.ndim > 2:
            raise ValueError(f"{self!r} takes the parameters {self.size_names} per replica: size must have shape "
                             f"({k},) or (n_replicas, {k}), got {s.shape}")
        s = s.reshape(-1, k)
        for i, name in enumerate(self.size_names):
            bad = ~(np.isfinite(s[:, i]) & (s[:, i] > 0))
            if bad.any():
                raise ValueError(f"{name} must be positive and finite, got {s[bad, i][0]}")
        self.check_parameters(*s.T)
        return s

    def check_parameters(self, *columns):
        """Raise ValueError if the parameters (one array each) do not make this surface."""

    def size(self, state, index):
        """The parameters of the given replicas (rows of ``state.size``); ValueError if the State
        lives on a surface of another kind."""
        if type(state.constraint) is not type(self):
            raise ValueError(f"the State lives on {state.constraint!r}, not on a {type(self).__name__}: give each "
                             "surface its own States")
        return super().size(state, index)

    # ------------------------------------------------------------------ pointwise
    def normal(self, x, size=None):
        """``grad F / |grad F|``; ValueError where the gradient vanishes."""
        g = self._gradient(x, self._required(size))
        return g / array_module(g).sqrt(_dot(g, g))[..., None]

    def _required(self, size):
        if size is None:
            raise TypeError(f"{self!r}: normals and tangent projections need the surface's parameters (size)")
        return array_module(size).asarray(size)

    def _gradient(self, x, size):
        g = self.grad_F(x, size)
        g2 = _dot(g, g)
        bad = ~(g2 > 0)
        if bad.any():
            xp = array_module(x)
            first = np.asarray(xp.broadcast_to(x, g.shape)[bad][0].tolist())
            raise ValueError(f"{self!r}: grad F vanishes at {int(bad.sum())} of {bad.size} points (first at "
                             f"{first.tolist()}): normals and projections need a smooth surface, grad F != 0 on it")
        return g

    def unwrap(self, x, reference, size):
        """On a periodic surface the image of ``x`` nearest ``reference`` in x and y; else ``x``."""
        if not self.periodic:
            return x
        box = size[..., :2]
        out = x.copy()
        d = x[..., :2] - reference[..., :2]
        out[..., :2] = reference[..., :2] + d - box * array_module(d).rint(d / box)
        return out

    def nearest_images(self, d, size):
        """Component-major differences ``d`` ``(3, ..., V)`` (the flat-facet metric's corner arrays;
        ``size`` per vertex ``(V, k)``) taken to their nearest images in x and y, in place."""
        if self.periodic:
            box = size[:, :2].T.reshape((2,) + (1,) * (d.ndim - 2) + (-1,))
            d[:2] -= box * array_module(d).rint(d[:2] / box)
        return d

    def wrap(self, x, size):
        """Positions with x and y wrapped into the periodic box (a copy; ``x`` itself if not periodic)."""
        if not self.periodic:
            return x
        xp = array_module(x)
        box = size[..., :2]
        out = x.copy()
        w = x[..., :2] - box * xp.floor(x[..., :2] / box)
        out[..., :2] = xp.where(w >= box, w - box, w)
        return out

    def hoomd_box(self, size):
        """On a periodic surface the largest replica's box in x and y and, in z, twice the largest
        parameter (a height field's heights lie within it), centred on the origin; else the default
        cube (None)."""
        if not self.periodic:
            return None
        s = np.asarray(size, dtype=np.float64).reshape(-1, len(self.size_names))
        lx, ly = s[:, :2].max(axis=0)
        return 3, np.array([lx, ly, 2.0 * s.max(), 0.0, 0.0, 0.0])

    def particle_origin(self, size):
        """On a periodic surface the middle of the largest box in x and y (HOOMD's box is centred on
        the origin, the State's starts there); else the origin."""
        if not self.periodic:
            return np.zeros(3)
        lx, ly = np.asarray(size, dtype=np.float64).reshape(-1, len(self.size_names))[:, :2].max(axis=0)
        return np.array([lx / 2, ly / 2, 0.0])

    def outside_box(self, x, size):
        """Mask of the points not stored inside the periodic box (none on a closed surface)."""
        if not self.periodic:
            return array_module(x).zeros(x.shape[:-1], dtype=bool)
        return ((x[..., :2] < 0) | (x[..., :2] >= size[..., :2])).any(axis=-1)

    def project_normal(self, x, size):
        """P_N: the closest point of the surface (see the class docstring), wrapped into the box on a
        periodic surface. RuntimeError, naming the surface, the number of points and the largest step
        left, if the iterations do not converge; ValueError if grad F vanishes."""
        xp = array_module(x)
        x = xp.asarray(x, dtype=xp.float64)
        size = xp.asarray(size)
        size = xp.broadcast_to(size, x.shape[:-1] + size.shape[-1:]).reshape(-1, size.shape[-1])
        target = x.reshape(-1, 3)
        p, lam = target.copy(), xp.zeros(len(target))
        limit = self.tolerance * self.length_scale(size)
        todo = xp.arange(len(p))
        for iteration in range(self.max_iterations):
            q, s, t = p[todo], size[todo], target[todo]
            if iteration < FOOT_POINT_STEPS:
                g = self._gradient(q, s)
                step = t - q - ((_dot(t - q, g) + self.F(q, s)) / _dot(g, g))[:, None] * g
            else:
                step, lam[todo] = self._newton_step(q, s, t, lam[todo], iteration == FOOT_POINT_STEPS)
            p[todo] = q + step
            todo = todo[xp.sqrt(_dot(step, step)) > limit[todo]]
            if len(todo) == 0:
                break
        else:
            self.check_regular(p[todo], size[todo])
            raise RuntimeError(f"{self!r}: projecting {len(p)} points onto the surface did not converge in "
                               f"{self.max_iterations} iterations: {len(todo)} points moved more than "
                               f"{self.tolerance:g} length scales in the last (they are too far from the surface)")
        self.check_regular(p, size)
        return self.wrap(p, size).reshape(x.shape)

    def _newton_step(self, p, size, x, lam, start):
        """One Newton step ``(dp, lambda)`` on ``p - x + lambda grad F(p) = 0, F(p) = 0`` (the Hessian of
        F by central differences of grad F); ``start``: lambda from ``x - p`` first."""
        xp = array_module(p)
        g = self._gradient(p, size)
        if start:
            lam = -_dot(x - p, g) / _dot(g, g)
        hessian = self.hessian_F(p, size)
        jac = xp.zeros((len(p), 4, 4))
        jac[:, :3, :3] = xp.eye(3) + lam[:, None, None] * hessian
        jac[:, :3, 3] = jac[:, 3, :3] = g
        rhs = -xp.concatenate([p - x + lam[:, None] * g, self.F(p, size)[:, None]], axis=1)
        delta = xp.linalg.solve(jac, rhs[..., None])[..., 0]
        return delta[:, :3], lam + delta[:, 3]

    def check_regular(self, p, size):
        """ValueError if grad F vanishes at the surface points ``p``: the second difference of F
        across the surface, ``F(p + e n) + F(p - e n) - 2 F(p)`` (``e`` = REGULARITY_STEP length
        scales), exceeds the first, ``e |grad F|`` (a smooth surface has a ratio of about e times its
        curvature; F squared, whose gradient is zero on the surface, an unbounded one)."""
        g = self._gradient(p, size)
        xp = array_module(p)
        norm = xp.sqrt(_dot(g, g))
        e = REGULARITY_STEP * xp.broadcast_to(self.length_scale(size), norm.shape)
        step = (e / norm)[..., None] * g
        second = xp.abs(self.F(p + step, size) + self.F(p - step, size) - 2 * self.F(p, size))
        bad = ~(second <= e * norm)
        if bad.any():
            first = np.asarray(xp.broadcast_to(p, g.shape)[bad][0].tolist())
            raise ValueError(f"{self!r}: grad F vanishes on the surface at {int(bad.sum())} of {bad.size} points (first "
                             f"near {first.tolist()}): F must cross zero with a nonzero gradient (not F^2)")

    def distance_to_surface(self, x, size):
        """``F / |grad F|``: the signed distance to first order."""
        xp = array_module(x)
        size = xp.asarray(size)
        g = self._gradient(x, size)
        return self.F(x, size) / xp.sqrt(_dot(g, g))

    def triangle_area(self, a, b, c, size):
        """Signed flat area of the triangles ``(a, b, c)`` (``b``, ``c`` nearest images of ``a``),
        positive when counter-clockwise seen from the side the normal at ``a`` points to."""
        b, c = self.unwrap(b, a, size), self.unwrap(c, a, size)
        return flat.signed_area(0.5 * _cross(b - a, c - a), self.normal(a, size))

    # ------------------------------------------------------------------ cells
    def _unwrapped_rows(self, state):
        """``(x, valid, size)``: each cell's vertices ``(C, W, 3)`` unwrapped about its first (padding
        repeats it), the real slots ``(C, W)`` and the cells' parameters ``(C, k)``."""
        xp = state.device.xp
        cv, sides = state.cell_vertices, state.cell_sides
        valid = xp.arange(cv.shape[1])[None, :] < sides[:, None]
        size = self.size(state, state.cell_replica)
        x = state.positions[xp.where(valid, cv, cv[:, :1])]
        return self.unwrap(x, x[:, :1], size[:, None]), valid, size

    def cell_centroids(self, state, method: str):
        """Each cell's centre projected onto the surface, ``(n_cells, 3)``: of its vertices
        (``method="vertex"``; unwrapped about its first) or of its flat area (``"area"``: the fan of
        triangles about the first vertex, each at its centroid weighted by its area signed as the
        cell's; the vertex centre where that area is not positive)."""
        xp = state.device.xp
        x, valid, size = self._unwrapped_rows(state)
        centre = xp.where(valid[..., None], x, 0.0).sum(axis=1) / state.cell_sides[:, None]
        if method == "area":
            r = x - x[:, :1]
            nxt = xp.roll(r, -1, axis=1)
            fan = xp.where(valid[..., None], 0.5 * _cross(r, xp.where(valid[..., None], nxt, 0.0)), 0.0)
            normal = self.normal(centre, size)
            w = _dot(fan, normal[:, None])
            total = w.sum(axis=1)
            moment = (w[..., None] * (r + nxt) / 3).sum(axis=1)
            good = total > 0
            centre = xp.where(good[:, None], x[:, 0] + moment / xp.where(good, total, 1.0)[:, None], centre)
        return self.project_normal(centre, size)

    def cell_centers(self, state):
        """Each cell's vertex centroid (vertices unwrapped about its first) projected onto the
        surface, ``(n_cells, 3)``."""
        return self.cell_centroids(state, "vertex")

    def orientation_points(self, x, reference=None, size=None):
        """``(u, v, 1)``: the points unwrapped to ``reference`` and drawn in an orthonormal frame of
        the plane tangent at ``reference`` (:meth:`tangent_frame`), so that ``(a x b) . c`` is twice
        the signed area of the triangle a, b, c there; a point without reference is its own
        frame's origin, ``(0, 0, 1)``."""
        out = np.ones(x.shape[:-1] + (3,))
        if reference is None:
            out[..., :2] = 0.0
            return out
        e1, e2 = self.tangent_frame(self.normal(reference, size))
        r = self.unwrap(x, reference, size) - reference
        out[..., 0], out[..., 1] = _dot(r, e1), _dot(r, e2)
        return out

    @staticmethod
    def tangent_frame(n):
        """Two unit vectors ``(e1, e2)`` completing the unit normals ``n`` (..., 3) to right-handed
        orthonormal frames (``e1`` from the coordinate axis least aligned with ``n``)."""
        seed = np.eye(3)[np.argmin(np.abs(n), axis=-1)]
        e1 = seed - _dot(seed, n)[..., None] * n
        e1 /= np.sqrt(_dot(e1, e1))[..., None]
        return e1, _cross(n, e1)

    def edge_points(self, state, sides):
        """Each cell's edges as ``(start, stop)`` points ``(u, v, 1)`` (corners of cell 0 first, in
        slot order; host arrays): the vertices, unwrapped about the cell's first, in the frame of the
        plane tangent at the cell's centre (the crossing tests of :mod:`spherevm.simplicity`)."""
        to_np = state.device.to_numpy
        x, valid, _ = (to_np(a) for a in self._unwrapped_rows(state))
        e1, e2 = self.tangent_frame(to_np(self.cell_normals(state)))
        r = x - x[:, :1]
        uv = np.stack([_dot(r, e1[:, None]), _dot(r, e2[:, None]), np.ones(r.shape[:2])], axis=-1)
        col = np.arange(uv.shape[1])[None, :]
        nxt = np.where(col + 1 < sides[:, None], col + 1, 0)
        return uv[valid], np.take_along_axis(uv, nxt[..., None], axis=1)[valid]

    def open_cells(self, state):
        """On a periodic surface the cells whose minimum-image edges do not add up to zero (an edge
        reached half the box), with the slot of the edge longest along the box; else none."""
        empty = np.zeros(0, dtype=np.int64)
        if not self.periodic:
            return empty, empty
        to_np = state.device.to_numpy
        x, valid = to_np(state.positions)[to_np(state.cell_vertices)], to_np(state.cell_vertices) >= 0
        sides = to_np(state.cell_sides)
        col = np.arange(x.shape[1])[None, :]
        following = np.take_along_axis(x, np.where(col + 1 < sides[:, None], col + 1, 0)[..., None], axis=1)
        box = self.size_np(state)[state.cell_replica_np(), None, :2]
        e = np.where(valid[..., None], self.unwrap(following, x, box) - x, 0.0)[..., :2]
        bad = np.flatnonzero((np.abs(e.sum(axis=1)) / box[:, 0] > 1e-9).any(axis=1))
        return bad, np.argmax((np.abs(e[bad]) / box[bad]).max(axis=2), axis=1)

    def hessian_F(self, x, size):
        """The Hessian of F (..., 3, 3) at ``x``: here by central differences of grad F (steps of
        HESSIAN_STEP length scales; a subclass with a closed form gives it)."""
        xp = array_module(x)
        e = HESSIAN_STEP * self.length_scale(size)[..., None]
        return xp.stack([(self.grad_F(x + e * unit, size) - self.grad_F(x - e * unit, size)) / (2 * e)
                         for unit in xp.eye(3)], axis=-1)

    def gaussian_curvature(self, x, size=None):
        """``K = -det([[H, g], [g^T, 0]]) / |g|^4`` (g = grad F, H its Hessian) at the points ``x``;
        ``size`` per point or one (default: the instance's own parameters, ``shape``)."""
        x = np.asarray(x, dtype=np.float64)
        size = np.broadcast_to(np.asarray(self.shape if size is None else size, dtype=np.float64),
                               x.shape[:-1] + (len(self.size_names),))
        g, h = self._gradient(x, size), self.hessian_F(x, size)
        bordered = np.zeros(x.shape[:-1] + (4, 4))
        bordered[..., :3, :3] = h
        bordered[..., :3, 3] = bordered[..., 3, :3] = g
        return -np.linalg.det(bordered) / _dot(g, g) ** 2

    def polygon_area(self, points, size) -> float:
        """The flat signed area of one polygon (unwrapped), as :meth:`cell_geometry` measures cells."""
        return float(flat.signed_area(flat.vector_area(points), self.normal(points, size).sum(axis=0)))

    def displacement(self, state, u, v):
        """``x[v] - x[u]`` (n, 3), the nearest image on a periodic surface (T1's short-edge test)."""
        x = state.positions
        return self.unwrap(x[v], x[u], self.size(state, state.vertex_replica[u])) - x[u]

    def cell_normals(self, state):
        """The surface normal at each cell's centre, ``(n_cells, 3)``."""
        return self.normal(self.cell_centers(state), self.size(state, state.cell_replica))

    # ------------------------------------------------------------------ pictures and trajectories
    def draw_points(self, points, size):
        """Points put on the surface for drawing, kept near their unwrapped places (periodic)."""
        return self.unwrap(self.project_normal(points, size), points, size)

    def unwrap_path(self, centroids, size):
        """On a periodic surface frame 0 as stored, then the cumulative minimum images of the
        frame-to-frame displacements in x and y (z as stored); else the points themselves."""
        out = np.array(centroids, dtype=np.float64, copy=True)
        if self.periodic and len(out) > 1:
            box = np.asarray(size)[..., :2]
            step = np.diff(out[..., :2], axis=0)
            step -= box * np.rint(step / box)
            out[1:, :, :2] = out[0, :, :2] + np.cumsum(step, axis=0)
        return out

    def geodesic_distance(self, a, b, size):
        """The straight distance ``|b - a|`` in the embedding space (of unwrapped points): MSD and
        F_s on an implicit surface measure displacements as chords, not along the surface."""
        return np.linalg.norm(b - a, axis=-1)

    # ------------------------------------------------------------------ random tilings (spherevm.init_surface)
    def minimum_cells(self, size) -> int:
        """The fewest cells a random tiling of this surface (parameters ``size``, (k,)) may have."""
        return MIN_TILING_CELLS

    def tiling_points(self, rng, n, size):
        """``(points, plane, box)``: ``n`` points uniform by area on the surface of parameters
        ``size`` (k,) drawn from ``rng``; and, on a surface tiled through a periodic plane, the points'
        coordinates there ``(n, 2)`` and that plane's box (else None, None: the convex hull of the
        points' directions is triangulated, as on the sphere). Here the periodic height field's:
        (x, y) uniform in the box, kept with probability ``|grad F| / |dF/dz|`` over
        :meth:`area_density_bound`."""
        if not self.periodic:
            raise NotImplementedError(f"{type(self).__name__} does not provide random tilings (tiling_points)")
        box = np.asarray(size[:2])

        def density(xy):
            g = self.grad_F(self.from_plane(xy, size), size)
            return np.sqrt(_dot(g, g)) / np.abs(g[:, 2])
        bound = self.area_density_bound(size)
        xy = rejection(rng, n, lambda m: rng.random((m, 2)) * box, lambda xy: density(xy) / bound)
        return self.from_plane(xy, size), xy, box

    def area_density_bound(self, size) -> float:
        """An upper bound of the area element of a periodic height field per unit of box area,
        ``|grad F| / |dF/dz|`` (random tilings draw by it): here 1.1 times its largest value on a
        256 x 256 grid (a subclass that knows a bound gives it)."""
        grid = (np.stack(np.meshgrid(np.arange(256), np.arange(256)), axis=-1).reshape(-1, 2) + 0.5) / 256
        g = self.grad_F(self.from_plane(grid * np.asarray(size[:2]), size), size)
        return 1.1 * float((np.sqrt(_dot(g, g)) / np.abs(g[:, 2])).max())

    def from_plane(self, xy, size):
        """The points of the surface at the plane coordinates ``xy`` (n, 2) of :meth:`tiling_points`:
        here the height field's points above them (Newton steps in z from z = 0)."""
        x = np.zeros((len(xy), 3))
        x[:, :2] = xy
        for _ in range(self.max_iterations):
            step = self.F(x, size) / self.grad_F(x, size)[:, 2]
            x[:, 2] -= step
            if np.all(np.abs(step) <= self.tolerance * self.length_scale(size)):
                return x
        raise RuntimeError(f"{self!r}: lifting {len(xy)} points onto the height field did not converge")

    def __repr__(self):
        values = ", ".join(f"{n}={v:g}" for n, v in zip(self.size_names, getattr(self, "shape", ())))
        return f"{type(self).__name__}({values})"
