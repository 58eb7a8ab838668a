"""The interface every constraint surface implements."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np


#: the size keys of :attr:`Constraint.size_key` and the size names each stands for
SIZE_KEYS = {"radius": ("radius",), "box": ("Lx", "Ly")}


class CellMeasures:
    """Base of what ``cell_geometry`` returns: ``center``, each cell's centre ``(n_cells, 3)``, is
    computed on first use from the callable a subclass keeps in ``_center`` (the forces do not
    need it)."""

    _center = None

    @property
    def center(self):
        if callable(self._center):
            self._center = self._center()
        return self._center


@dataclass(frozen=True)
class DeviceSurface:
    """A surface's device code: CUDA ``source`` defining ``struct``, the functions
    geometry/surface.cuh lists, which every kernel module compiled for the surface starts with
    (:func:`spherevm.constraints.kernels.surface_kernels`); ``coef_width``: the doubles per cell of
    the vertex model's coefficients its ``vertex_force`` reads; ``options``: compiler options of
    every module compiled for it."""

    source: str
    struct: str
    coef_width: int = 2
    options: tuple = ()

    @property
    def prelude(self) -> str:
        """The text a kernel module starts with: the source, then the struct named as ``SVM_SURFACE``."""
        return f"{self.source}\n#define SVM_SURFACE {self.struct}\n"


class Constraint:
    """A surface that holds the vertices and measures lengths and areas on itself.

    Projection operators (the paper's formalism): ``project_tangent(x, v)`` is P_T, the part of
    ``v`` tangent to the surface at ``x``; ``project_normal(x, radius)`` is P_N, the closest point
    of the surface. Forces need the metric: per-cell areas, perimeters and centroids
    (``cell_geometry``) and the surface gradient of any function of them (``shape_gradient``).
    ``radius`` is the per-vertex (or per-replica) size parameter of the surface: each replica has
    its own, ``State.size``, shaped by :attr:`size_shape` and named by :attr:`size_names`.

    A surface that does not implement some of these yet (a stub) says so before anything runs:
    operations list the methods they need in ``surface_needs`` and :meth:`require` refuses them at
    attach time, naming what is missing.
    """

    name = "constraint"
    #: the shape of one replica's size parameters: ``()`` for one number (a sphere's radius),
    #: ``(2,)`` for two (a periodic box's Lx, Ly); ``State.size`` is ``(n_replicas, *size_shape)``
    size_shape = ()
    #: what each size parameter is, in order (one name per entry of ``size_shape``, one for ``()``)
    size_names = ("radius",)
    #: V - E + F of every network on this surface (2 on a sphere, 0 on a torus or periodic plane)
    euler_characteristic = 2
    #: how far, relative to the surface's area, the cells' areas (``tiling_areas_np``) may add up
    #: from it in a tiling that covers the surface once (:mod:`spherevm.simplicity`)
    cover_tolerance = 1e-9

    @property
    def size_key(self) -> str:
        """The name a replica's size goes by in files and as a State keyword: ``"radius"`` for a
        size named ``("radius",)``, ``"box"`` for ``("Lx", "Ly")`` (the GSD chunks and keywords of
        the sphere and the plane), else ``"size"``."""
        return next((k for k, names in SIZE_KEYS.items() if names == tuple(self.size_names)), "size")

    def check_size(self, size):
        """Raise ValueError unless ``size`` (``(n_replicas, *size_shape)``, NumPy) is a valid size
        of this surface: here every entry positive and finite."""
        bad = ~(np.isfinite(size) & (size > 0))
        if bad.any():
            raise ValueError(f"{self.size_key} must be positive and finite, got {size[bad][0]}")

    def size(self, state, index):
        """The surface size of the given replicas (per vertex when ``index`` is vertex_replica)."""
        return state.size[index]

    def size_np(self, state):
        """Every replica's surface size as a NumPy array, ``(n_replicas, *size_shape)``."""
        return state.size_np()

    # ------------------------------------------------------------------ the GPU
    def device_surface(self):
        """This surface's device code (:class:`DeviceSurface`) for the CUDA kernels, or None where
        it runs on device="cpu" only (here)."""
        return None

    def has_device_code(self) -> bool:
        """Whether :meth:`device_surface` gives code (the kernels compile for this surface)."""
        return self.device_surface() is not None

    def kernel_size(self, state):
        """The per-replica size array the kernels take (``Surface::size``): the State's own here."""
        return state.size

    # ------------------------------------------------------------------ files and pictures
    def display_extent(self, size) -> float:
        """A length the cube box of a GSD frame must hold about the origin besides the vertices
        (``size`` per replica, NumPy): the largest size parameter here (a sphere's radius)."""
        return float(np.max(size))

    def hoomd_box(self, size):
        """``(dimensions, (6,) HOOMD box)`` of a GSD frame for ``size`` (NumPy, per replica), or
        None for the default: a cube about the origin holding every vertex."""
        return None

    def particle_origin(self, size):
        """Where the State's origin sits in a GSD file's particle coordinates, ``(3,)``."""
        return np.zeros(3)

    #: how :mod:`spherevm.render` draws a replica: "mesh" (its cells as 3D polygons), "ball" (the
    #: hemisphere facing the camera of a sphere about the origin) or "box" (a periodic box in 2D)
    drawing = "mesh"

    def draw_points(self, points, size):
        """Points of a picture or mesh (cell edges cut into pieces, fan triangles) put on the
        surface for drawing (``size`` per point): :meth:`project_normal` here; a periodic surface
        keeps them unwrapped."""
        return self.project_normal(points, size)

    def replica_spacing(self, size, cell_width) -> float:
        """The distance along x between replicas drawn side by side (export), given each replica's
        ``size`` (NumPy) and the widest cell's extent along x: 2.5 of the largest size here
        (a sphere's radius: half a diameter between spheres)."""
        return 2.5 * float(np.max(size))

    def length_scale(self, size):
        """A length per entry of ``size`` (tolerances scale with it): the radius itself here."""
        return size

    # ------------------------------------------------------------------ trajectories (spherevm.analysis)
    #: the surface's rigid motions, which move a whole tissue without deforming it (noise makes it
    #: diffuse along them): "rotations" (about the origin, removed by Kabsch), "z-rotations" (about
    #: the z axis only) or "translations"; none here (a surface that none of these maps onto itself)
    rigid_motions = ()

    def unwrap_path(self, centroids, size):
        """Points ``(T, n, 3)`` over time made continuous across a periodic boundary (``size`` per
        point, ``(n, *size_shape)``): the points themselves on a surface without images."""
        return centroids

    def geodesic_distance(self, a, b, size):
        """The distance along the surface between points ``a`` and ``b`` (``size`` per point)."""
        raise NotImplementedError(f"{type(self).__name__} does not yet provide geodesic distances")

    def unwrap(self, x, reference, size):
        """The image of ``x`` nearest ``reference`` (periodic surfaces); ``x`` itself otherwise."""
        return x

    def normal(self, x, size=None):
        """The unit outward normal at the points ``x`` (..., 3); ``size`` per point (a surface whose
        shape depends on its size needs it: the torus, the ellipsoid)."""
        raise NotImplementedError(f"{type(self).__name__}.normal is not implemented yet")

    def project_tangent(self, x, v, size=None):
        """P_T: the part of ``v`` tangent to the surface at ``x`` (``size`` as in :meth:`normal`)."""
        n = self.normal(x, size)
        return v - (v * n).sum(axis=-1)[..., None] * n

    def project_normal(self, x, radius):
        raise NotImplementedError(f"{type(self).__name__}.project_normal is not implemented yet")

    def geodesic_offset(self, x, direction, distance, radius):
        """The point at ``distance`` from ``x`` along the unit tangent ``direction`` (projected back)."""
        return self.project_normal(x + distance[..., None] * direction, radius)

    def chord_length(self, length, radius):
        """Straight-line distance between the ends of a geodesic of ``length``: monotonic in
        ``length``, so short-edge tests (T1) compare chords and need no trigonometry."""
        raise NotImplementedError(f"{type(self).__name__}.chord_length is not implemented yet")

    def distance_to_surface(self, x, radius):
        raise NotImplementedError(f"{type(self).__name__}.distance_to_surface is not implemented yet")

    def total_area_np(self, radius):
        raise NotImplementedError(f"{type(self).__name__}.total_area is not implemented yet")

    def size_for_area(self, size, area):
        """Each replica's size (rows of ``size``, NumPy) with its shape kept and its surface's total
        area ``area`` (per replica): every parameter times sqrt(area / total area), for surfaces whose
        parameters are all lengths (the plane's box, an implicit surface's; the sphere's radius)."""
        size = np.asarray(size, dtype=np.float64)
        factor = np.sqrt(np.asarray(area, dtype=np.float64) / self.total_area_np(size))
        return size * factor.reshape((-1,) + (1,) * (size.ndim - 1))

    def cell_geometry(self, state, area_vectors: bool = False, metric: bool = True):
        """Per-cell areas and perimeters (``metric``) and area vectors (``area_vectors``,
        ``(n_cells, 3)``), with what :meth:`shape_gradient` reuses."""
        raise NotImplementedError(f"{type(self).__name__} does not yet provide cell areas and perimeters "
                                  "(only Sphere does); vertex-model forces need them")

    def shape_gradient(self, state, geometry, d_area, d_perimeter, d_area_vector=None):
        """Surface gradient (V, 3) of ``sum_c d_area[c] A_c + d_perimeter[c] P_c + d_area_vector[c] . a_c``
        (a term whose coefficients are None is left out)."""
        raise NotImplementedError(f"{type(self).__name__} does not yet provide area and perimeter gradients "
                                  "(only Sphere does); vertex-model forces need them")

    def triangle_area(self, a, b, c, size):
        """Signed area of the geodesic triangle ``(a, b, c)`` (rows of points; ``size`` per row),
        positive when counter-clockwise seen from outside (T1 refuses flips that fold a cell)."""
        raise NotImplementedError(f"{type(self).__name__} does not yet provide triangle areas (Sphere and "
                                  "PeriodicPlane do)")

    def cell_normals(self, state):
        """The unit surface normal at each cell's centre, ``(n_cells, 3)`` (active cell directors
        live in the tangent plane there)."""
        raise NotImplementedError(f"{type(self).__name__} does not yet provide cell normals")

    def edge_lengths(self, state, u, v):
        raise NotImplementedError(f"{type(self).__name__} does not yet provide geodesic lengths (only Sphere does)")

    def cell_centroids(self, state, method: str):
        """Each cell's position on the surface, ``(n_cells, 3)`` (device array): the centre of its
        area (``method="area"``) or of its vertices (``"vertex"``), see
        :func:`spherevm.shapes.cell_centroids`."""
        raise NotImplementedError(f"{type(self).__name__} does not yet provide cell centroids")

    def gaussian_curvature(self, x, size):
        """The Gaussian curvature K at the points ``x`` (..., 3) of the surface (``size``: its
        parameters, per point or one), NumPy; the points are taken as given."""
        raise NotImplementedError(f"{type(self).__name__} does not yet provide its Gaussian curvature")

    def polygon_area(self, points, size) -> float:
        """The signed area of one polygon ``points`` (n, 3), unwrapped about its first vertex, as this
        surface measures a cell (``size``: its replica's parameters): division's and extrusion's
        daughters (:mod:`spherevm.growth`)."""
        raise NotImplementedError(f"{type(self).__name__} does not yet provide polygon areas")

    def tiling_points(self, rng, n, size):
        """Points uniform by area for a random tiling (:mod:`spherevm.init_surface`), see
        :meth:`spherevm.constraints.ImplicitSurface.tiling_points`."""
        raise NotImplementedError(f"{type(self).__name__} does not provide random tilings through "
                                  "init.random_tiling(surface=...)")

    def cell_areas_np(self, state):
        return state.device.to_numpy(self.cell_geometry(state).area)

    def tiling_areas_np(self, state):
        """The cells' signed areas as the tiling checks (:mod:`spherevm.simplicity`) add them up
        against ``total_area_np``: the metric's own (``cell_areas_np``) where they tile the surface
        exactly."""
        return self.cell_areas_np(state)

    # ------------------------------------------------------------------ tiling checks (spherevm.simplicity)
    def orientation_points(self, x, reference=None, size=None):
        """Points ``x`` (..., 3) as 3-vectors whose triple products give orientations (``(a x b) . c``
        the side of ``c`` from the arc or segment ``a b``), unwrapped to the images nearest
        ``reference`` (with ``size`` per row) on a periodic surface where given. The crossing
        tests of :mod:`spherevm.simplicity` and the fold rule run where a surface gives them."""
        raise NotImplementedError(f"{type(self).__name__} does not yet provide orientation points")

    def edge_points(self, state, sides):
        """Each cell's edges as ``(start, stop)`` :meth:`orientation_points`, ``(corners, 3)`` each,
        cell 0's corners first in slot order (``sides``: the cell sides, NumPy)."""
        to_np = state.device.to_numpy
        pos, cv = to_np(state.positions), to_np(state.cell_vertices)
        col = np.arange(cv.shape[1])[None, :]
        valid = col < sides[:, None]
        nxt = np.where(col + 1 < sides[:, None], np.roll(cv, -1, axis=1), cv[:, :1])
        unit = self.orientation_points(pos)
        return unit[cv[valid]], unit[nxt[valid]]

    def open_cells(self, state):
        """Cells whose edges do not add up to zero and the slot of the edge that jumped (a periodic
        surface's minimum image): ``(cells, slots)``, none on a surface without images."""
        return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64)

    def cover_error(self, state, areas, replica, total, surface) -> str:
        """Why the cells' ``areas`` of ``replica`` add up to ``total``, not the surface's ``surface``."""
        return (f"the cells cover an area {total:.12g}, but the surface's is {surface:.12g}; some cell is listed "
                "clockwise, folded, overlaps another or is too large for the surface's metric")

    def check_cell_areas(self, state, areas, surface):
        """Raise ValueError naming a cell whose area this surface cannot measure (``surface``: each
        replica's area); every cell passes here."""

    def missing(self, names) -> list:
        """Those of the method ``names`` this surface does not implement (still the base's)."""
        return [n for n in names if getattr(type(self), n) is getattr(Constraint, n)]

    def require(self, names, who: str):
        """Raise NotImplementedError if any of ``names`` is missing, naming ``who`` needs it."""
        absent = self.missing(names)
        if absent:
            raise NotImplementedError(f"{who} needs {', '.join(absent)} of the surface, which {self!r} does not "
                                      "implement yet; use a Sphere")

    def __repr__(self):
        return f"{type(self).__name__}()"
