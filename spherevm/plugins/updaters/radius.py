"""The surface's size as a schedule: fixed, growing with N at constant <A>, or (a sphere) a user's
function of the radius."""
from __future__ import annotations

import numpy as np

from ..base import Updater
from ..parameters import Parameter
from ..rows import saved_field
from .division import _rate


def _radius_mode(name, value):
    if not callable(value) and value not in ("fixed", "constant_area"):
        raise ValueError(f"mode must be 'fixed', 'constant_area' or a callable f(simulation) -> R, got {value!r}")
    return value


def _target_area(name, value):
    if value is None:
        return None
    value = _rate(name, value)
    if value == 0:
        raise ValueError("area must be > 0")
    return value


class RadiusSchedule(Updater):
    """Set each replica's surface size every time the trigger fires, rescaling its vertex positions
    with it (``x -> x R_new / R_old`` on the sphere: shapes are kept, every length scales). On any
    surface whose parameters are all lengths (the sphere's radius, the plane's box, the torus's
    radii, the ellipsoid's axes, a height field's box and heights) every length scales alike
    (:meth:`Constraint.size_for_area <spherevm.constraints.base.Constraint.size_for_area>`).

    Put it after the updaters that change N (Division, Extrusion) so the new N is seen in the same
    step. Both devices. Sits minimisations out, as Division does.

    Parameters
    ----------
    mode : {"fixed", "constant_area"} or callable
        "fixed": never change the size (dividing cells then lower <A> = area / N); "constant_area":
        the size whose area is ``N area`` (on the sphere ``R = sqrt(N area / 4 pi)``), so that <A>
        stays ``area`` as N changes; on a sphere, a callable ``f(simulation) -> R`` (a scalar or one
        per replica).
    area : float, optional
        For "constant_area" (default: each replica's <A> when the schedule attaches).
    trigger : Trigger or int"""

    narrowable = True
    in_minimize = False
    per_replica = ("target_area", "counts")
    surface_needs = ("total_area_np",)

    mode = Parameter(_radius_mode)
    area = Parameter(_target_area)

    def __init__(self, mode="constant_area", area=None, trigger=1):
        super().__init__(trigger)
        self.target_area = None
        self.mode = mode
        self.area = area

    def parameters_changed(self, name):
        """A new ``area`` is every replica's target <A> from the next pass on."""
        if name == "area" and self.area is not None and self.target_area is not None:
            self.target_area = np.full(len(self.target_area), self.area)

    def attach(self, simulation):
        super().attach(simulation)
        con = simulation.state.constraint
        if callable(self.mode) and con.size_key != "radius":
            raise ValueError(f"RadiusSchedule with a radius function needs a surface sized by one radius per replica "
                             f"(a Sphere), got {con!r} sized by {', '.join(con.size_names)}; use mode='constant_area'")
        state = simulation.state
        self.target_area = (np.full(state.n_replicas, self.area) if self.area is not None
                            else np.array(state.mean_cell_area, dtype=np.float64))
        self.counts = np.full(state.n_replicas, -1, dtype=np.int64)   # N at the last "constant_area" pass

    def state_to_save(self) -> dict:
        """The target <A> per replica and the cell counts of the last "constant_area" pass."""
        return {"area": self.target_area.copy(), "counts": self.counts.copy()}

    def restore_state(self, data: dict):
        """``counts`` always; ``area`` unless the script gives one (the default, each replica's <A> at
        the first attach, is state: after growth the <A> of the restored sphere is only rounded)."""
        n = self._simulation.state.n_replicas
        area = saved_field(self, data, "area", np.float64, (n,), above=0)
        self.counts = saved_field(self, data, "counts", np.int64, (n,), low=-1).copy()
        if self.area is None:
            self.target_area = area.copy()

    def target(self, simulation):
        """The size each replica should have now (NumPy, rows of ``state.size``)."""
        state = simulation.state
        if self.mode == "fixed":
            return state.size_np()
        if self.mode == "constant_area":
            return state.constraint.size_for_area(state.size_np(), state.cells_per_replica * self.target_area)
        n, given = state.n_replicas, self.mode(simulation)
        try:
            r = np.asarray(state.device.to_numpy(given), dtype=np.float64)     # a CuPy array too
        except (TypeError, ValueError):
            r = np.full(n, np.nan)          # not numbers: refused below, as a bad radius
        if r.ndim > 1 or r.size not in (1, n):
            raise ValueError(f"RadiusSchedule: the radius function returned shape {r.shape}; it must return a "
                             f"scalar or one radius per replica ({n})")
        if not np.all(np.isfinite(r)) or np.any(r <= 0):
            raise ValueError(f"RadiusSchedule: the radius function returned {given!r}; radii must be positive "
                             "and finite")
        return np.broadcast_to(r.reshape(-1), (n,)).copy()

    def update(self, simulation, timestep):
        state = simulation.state
        if self.mode == "constant_area":      # R is a function of N: nothing to do (not even a rounding
            if np.array_equal(self.counts, state.cells_per_replica):     # of R) until N changes
                return
            self.counts = state.cells_per_replica.copy()
        old, new = state.size_np(), self.target(simulation)
        if np.array_equal(old, new):
            return
        xp = state.device.xp
        first = (slice(None),) + (0,) * (new.ndim - 1)            # every length scales alike: the first's ratio
        scale = xp.asarray(new[first] / old[first])[state.vertex_replica]
        size = xp.asarray(new)
        state.positions = state.constraint.project_normal(state.positions * scale[:, None], size[state.vertex_replica])
        state.size = size
        state.clear_cache()          # cached parameters that depend on <A> (dimensionless forces) go stale
        simulation.state_changed()

    def __repr__(self):
        mode = self.mode if isinstance(self.mode, str) else "callable"
        return f"RadiusSchedule(mode={mode!r})"
