"""The fused small-tissue steps' contract: what an operation gives to take part in them.

:mod:`spherevm.tissue_steps` runs many cycles of the plan of a small tissue in one launch. The
kernel is assembled from the stages of the operations present, each returned by
:meth:`Operation.fused_stage <spherevm.plugins.base.Operation.fused_stage>`: its CUDA type, the
source that defines it, its argument struct (a :class:`~spherevm.kernel_struct.KernelStruct`,
declared to the kernel from this one definition) and the arguments' values now. The engine names no
operation: a user's plugin takes part exactly as the built-ins do (docs/plugins.md, "Making your
plugin fusable").

A stage's CUDA type, by role:

* ``"force"``: ``void cell(double A, double P, long c, Surface::Size s, double* coef, const double* pos,
  const int* row, int n) const`` (only where ``measures``: from the cell's area and perimeter, or its
  ``n`` vertices ``row`` at ``pos``, its ``cell_doubles`` coefficients into its region ``coef``,
  indexed by the global cell index); where ``neighbour_doubles``, ``void neighbours(const double*
  pos, const int* vc, const int* cell_vertices, const int* sides, int max_sides, long c,
  Surface::Size s, const double* coef, double* more) const``, a second per-cell part, run once every
  cell's ``cell`` is known everywhere (and after the pass's flips): it may read any cell's
  coefficients (its neighbours') and writes its ``neighbour_doubles`` into its region ``more``,
  which the vertex parts read for the three cells of their vertex only (a block of a cluster
  computes the neighbour parts of its own vertices' cells); and
  ``vec3 vertex(const double* pos, const int* vn, const int* vc, long v, Surface::Size s, const
  double* coef, KeptNorm norm) const`` (the force on vertex ``v``, tangent to the surface; a stage
  with ``neighbour_doubles`` takes ``more`` after ``coef``). The forces of the stages are summed in
  the order of ``sim.operations.forces``, as ``Simulation.compute_forces`` sums them. Where
  :meth:`Force.combined <spherevm.plugins.base.Force.combined>` computes two forces together,
  :meth:`Force.fused_combined <spherevm.plugins.base.Force.fused_combined>` gives the pair's stage:
  an ``extra`` stage, whose ``void add_gradient(vec3& g, const double* pos, const int* vn, const int*
  vc, long v, vec3 x, const double* coef, const double* more) const`` the other force's stage (one
  that ``takes_extra``: its ``vertex`` takes an ``Extra`` last, as the vertex model's) adds inside
  its vertex force, as the general kernels of the pair do.
* ``"move"``: a run's integrator (``minimizer = False``): ``vertex(next, F, v, vc, s, r, timestep)``
  and, where ``cell_phase``, ``cell(pos, cell_vertices, sides, max_sides, c, s, timestep)`` after every
  vertex moved; a minimiser (``minimizer = True``): its sums' ``terms``, ``control`` and ``vertex``
  (see ``plugins/integrators/fire_stage.cuh``).
* ``"pass"``: an updater's topology pass, ``detect`` and ``settle`` (see
  ``plugins/updaters/t1_stage.cuh``).

Every stage calls the same device functions as its operation's general kernels, so the fused
steps give the step-by-step path's bits.
"""
from __future__ import annotations

from dataclasses import dataclass, field

ROLES = ("force", "move", "pass")


@dataclass
class FusedStage:
    """An operation's part of the fused small-tissue steps.

    Parameters
    ----------
    role : str
        ``"force"``, ``"move"`` (the integrator) or ``"pass"`` (an updater's topology pass).
    struct : str
        The stage's CUDA type, e.g. ``"VertexModelStage"`` or ``"BrownianStage<1>"``; it is built
        from its arguments as ``Type{args}`` (a pass: ``Type(args, step_need)``).
    source : str
        CUDA that defines the type: ``#include`` lines (paths from the package's root) or code.
    arguments : spherevm.kernel_struct.KernelStruct
        The stage's argument struct (a member ``a`` of the type, by convention).
    values : dict
        The arguments' values now (CuPy arrays for pointers).
    cell_doubles : int
        A force's coefficients per cell in shared memory.
    measures : bool
        A force has a cell part, ``cell``, which takes each cell's area and perimeter (False: none).
    neighbour_doubles : int
        A force's second per-cell part, ``neighbours``: its doubles per cell in shared memory (0: none).
    takes_extra : bool
        A force's ``vertex`` takes an ``Extra`` (``vertex_model.cuh``): a stage joined into it adds its
        gradient there.
    extra : bool
        A force joined into another's vertex force (returned by ``Force.fused_combined``): it gives
        ``add_gradient`` instead of ``vertex``.
    sums : int
        A minimiser's per-replica sums (FIRE: 3).
    vertex_doubles : int
        A minimiser's per-vertex state kept in shared memory (FIRE's velocity: 3).
    finish : callable, optional
        ``finish(module, step_need, steps)`` after each launch (T1: the cell table's width and the
        flip log's pass count the step-by-step path would have).
    """

    role: str
    struct: str
    source: str
    arguments: object
    values: dict = field(default_factory=dict)
    cell_doubles: int = 0
    measures: bool = False
    neighbour_doubles: int = 0
    takes_extra: bool = False
    extra: bool = False
    sums: int = 0
    vertex_doubles: int = 0
    finish: object = None

    def __post_init__(self):
        if self.role not in ROLES:
            raise ValueError(f"a fused stage's role is one of {ROLES}, got {self.role!r}")

    def packed(self):
        """The arguments' values as the record the kernel takes."""
        return self.arguments.pack(**self.values)


def overrides(op, base, names) -> bool:
    """Whether ``op``'s class replaces any of the methods ``names`` of ``base`` (a subclass that
    computes something else must then give its own fused stage)."""
    return any(getattr(type(op), name) is not getattr(base, name) for name in names)
