"""Which CUDA surface a constraint is compiled as (its device code, Constraint.device_surface, at the
head of each module; geometry/surface.cuh), and the kernels of the geometry layer
(geometry/cell_measures.cu): every cell's area and perimeter in one launch, which
:func:`spherevm.shapes.cell_shapes` uses on the GPU instead of the per-corner array arithmetic of
``cell_geometry`` (a few dozen CuPy launches: 2.3 ms for 1,024 x 32 cells on an H200, where this
kernel takes microseconds), and the run's closed-cell check on periodic surfaces."""
from __future__ import annotations

from pathlib import Path

from ..device import launch, load_module
from .implicit import ImplicitSurface
from .plane import OPEN_TOLERANCE, PeriodicPlane
from .sphere import Sphere


class _Metric(type):
    """Makes ``isinstance`` ask for the metric too (as abc.ABCMeta lets classes answer it)."""

    def __instancecheck__(cls, constraint):
        return isinstance(constraint, Sphere) and constraint.metric == "geodesic"


class GeodesicSphere(metaclass=_Metric):
    """The sphere the kernels compile: ``isinstance(c, GeodesicSphere)`` holds for a :class:`Sphere`
    measuring with its geodesic metric (the default), not for ``Sphere(metric="flat")``, whose metric
    runs on device="cpu" only: operations listing KERNEL_SURFACES in ``gpu_surfaces`` refuse it."""


#: The surfaces whose constraints give device code (Constraint.device_surface): one kernel source per
#: operation serves them all (``gpu_surfaces`` of the built-in operations). A user's ImplicitSurface
#: without CUDA code for F and grad F is refused by its ``device_surface``, saying what to add.
KERNEL_SURFACES = (GeodesicSphere, PeriodicPlane, ImplicitSurface)
#: the surfaces Bending's kernels (plugins/forces/bending.cu) compile for: the sphere, and the
#: implicit surfaces through their flat-facet coefficients; its fused stage: the sphere's
BENDING_SURFACES = (GeodesicSphere, ImplicitSurface)
FUSED_BENDING_SURFACES = (GeodesicSphere,)
_CELL_MEASURES = Path(__file__).parent.parent / "geometry" / "cell_measures.cu"


def compiles(constraint) -> bool:
    """Whether the kernels compile for ``constraint``: one of KERNEL_SURFACES that gives device code."""
    return isinstance(constraint, KERNEL_SURFACES) and constraint.has_device_code()


def keeps_directions(constraint) -> bool:
    """Whether the compiled Surface keeps each vertex's unit direction in shared memory
    (``Surface::directions`` of geometry/surface.cuh: the sphere's, not the plane's)."""
    return isinstance(constraint, GeodesicSphere)


def surface_kernels(cu_file, state, defines=()):
    """``(module, size)``: the kernels of ``cu_file`` compiled for ``state``'s surface (its device
    code first, and the macros ``defines``) and the per-replica size array they take
    (``Constraint.kernel_size``: ``radius`` on the sphere, ``box`` on the plane, an implicit
    surface's parameters with its length scale and half its area)."""
    surface = state.constraint.device_surface()
    module = load_module(cu_file, tuple(defines), prelude=surface.prelude, options=surface.options)
    return module, state.constraint.kernel_size(state)


def cell_measures(state):
    """``(area, perimeter)`` of every cell, CuPy arrays, from the vertex model's own formulas
    (``Surface::cell_measures``: the sphere's fan as one product of factors, the plane's shoelace
    sum), for a GPU State on a surface of KERNEL_SURFACES."""
    xp = state.device.xp
    area, perimeter = xp.empty(state.n_cells), xp.empty(state.n_cells)
    module, size = surface_kernels(_CELL_MEASURES, state)
    launch(module.get_function("cell_measures"), state.n_cells,
           (state.positions, state.cell_vertices, state.cell_sides, state.cell_replica, size,
            xp.int32(state.n_cells), xp.int32(state.max_sides), area, perimeter))
    return area, perimeter


def flags_open_cells(state) -> bool:
    """Whether :func:`flag_open_cells` tests ``state``'s cells on the device: a GPU State on the
    periodic plane or a periodic implicit surface with device code (on a closed surface no cell can
    open: it has no images)."""
    con = state.constraint
    periodic = isinstance(con, PeriodicPlane) or isinstance(con, ImplicitSurface) and con.periodic
    return state.device.is_gpu and periodic and compiles(con)


def flag_open_cells(state, word):
    """Set ``word`` (a one-element uint64 CuPy array) to 1 if a cell of a GPU State on a periodic
    surface does not close under the minimum image: its minimum-image edges add up to more than
    ``OPEN_TOLERANCE`` times its box side (geometry/cell_measures.cu's ``open_cells``, one thread a cell)."""
    xp = state.device.xp
    module, size = surface_kernels(_CELL_MEASURES, state)
    launch(module.get_function("open_cells"), state.n_cells,
           (state.positions, state.cell_vertices, state.cell_sides, state.cell_replica, size,
            xp.int32(state.n_cells), xp.int32(state.max_sides), xp.float64(OPEN_TOLERANCE), word))
