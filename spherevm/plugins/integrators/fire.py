"""FIRE energy minimisation (Bitzek et al., PRL 97, 170201, 2006) on the constraint surface."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from ...device import launch, segment_sums, weighted_bincount
from ...validation import integer, positive
from ...constraints.kernels import KERNEL_SURFACES, surface_kernels
from ...kernel_struct import KernelStruct
from ..base import raise_flagged_step
from ..minimizer import Minimizer
from ..fusion import FusedStage, overrides
from ..parameters import Parameter
from ..rows import saved_field

_KERNELS = Path(__file__).with_suffix(".cu")


class FIRE(Minimizer):
    """Fast Inertial Relaxation Engine with per-replica time step, mixing, counters and convergence.

    Each iteration, per replica, with forces F already tangent to the surface:

    1. power ``P = F . v`` (summed over the replica's vertices);
    2. if ``P > 0``: mix ``v <- (1 - alpha) v + alpha |v| F/|F|``, and after ``n_min`` positive
       steps in a row grow ``dt <- min(f_inc dt, dt_max)`` and shrink ``alpha <- f_alpha alpha``;
       else: ``v <- 0``, ``dt <- f_dec dt``, ``alpha <- alpha_start`` (unit mass);
    3. semi-implicit Euler: ``v <- v + dt F``, ``x <- P_N(x + dt v)``, then ``v <- P_T(x, v)``
       carries the velocity into the new tangent plane.

    Replicas that have stopped do not move, and their dt, alpha and counter stay as they were.

    Parameters
    ----------
    dt : float
        The initial time step; 0.02 is the step the docs, the CLI and the sweeps use (fastest on
        the rigidity protocol, docs/rigidity.md).
    dt_max, n_min, f_inc, f_dec, alpha_start, f_alpha : optional
        Bitzek's defaults: ``dt_max = 10 dt``, 5, 1.1, 0.5, 0.1, 0.99.
    force_tol, energy_tol, check_every : optional
        Convergence per replica (:class:`spherevm.plugins.minimizer.Minimizer`), in each replica's
        natural units (force ``kP sqrt(<A>)``, energy per cell ``kP <A>`` for the vertex model).
    max_step : float
        Units of sqrt(<A>) (default 1, a cell size: FIRE with ``dt_max = 10 dt`` takes legitimate
        steps of half a cell on a raw tiling). A vertex that would move farther, or to NaN, in one
        iteration stops the run with FloatingPointError naming the timestep, replica and vertex,
        before the move (CPU) or at the next check (GPU: the vertex stays in place), so no corrupt
        frame is written."""

    gpu_surfaces = KERNEL_SURFACES
    surface_needs = ("normal", "project_normal")

    dt = Parameter(positive)
    dt_max = Parameter(positive)
    n_min = Parameter(integer)
    f_inc = Parameter(positive)
    f_dec = Parameter(positive)
    alpha_start = Parameter(positive)
    f_alpha = Parameter(positive)
    max_step = Parameter(positive)

    def __init__(self, dt=0.02, dt_max=None, n_min=5, f_inc=1.1, f_dec=0.5, alpha_start=0.1, f_alpha=0.99,
                 force_tol=1e-10, energy_tol=1e-20, check_every=10, max_step=1.0):
        super().__init__(force_tol=force_tol, energy_tol=energy_tol, check_every=check_every)
        self.velocities = None
        self._dt_max_follows = dt_max is None       # dt_max = 10 dt, also after dt changes
        self.max_step = max_step
        self.dt = dt
        self.dt_max = 10 * self.dt if dt_max is None else dt_max
        self.n_min = n_min
        self.f_inc = f_inc
        self.f_dec = f_dec
        self.alpha_start = alpha_start
        self.f_alpha = f_alpha

    def check_parameters(self):
        """dt_max >= dt, f_inc >= 1, f_dec < 1, alpha_start < 1 and f_alpha <= 1."""
        if self.dt_max < self.dt:
            raise ValueError(f"dt_max must be >= dt={self.dt}, got {self.dt_max!r}")
        if self.f_inc < 1:
            raise ValueError(f"f_inc must be >= 1, got {self.f_inc!r}")
        if self.f_dec >= 1 or self.alpha_start >= 1 or self.f_alpha > 1:
            raise ValueError("FIRE needs f_dec < 1, alpha_start < 1 and f_alpha <= 1")

    def parameters_changed(self, name):
        """A new ``dt`` is the step every running replica takes next (HOOMD's FIRE: ``dt`` is the
        current step), and ``dt_max`` follows it while it was not given; a new ``dt_max`` caps the
        replicas' current steps. The other constants act from the next iteration on."""
        if name == "dt" and self._dt_max_follows:
            self.__dict__["dt_max"] = 10 * self.dt
        elif name == "dt_max":
            self._dt_max_follows = False
        if self._simulation is None or self.velocities is None:
            return
        xp = self._simulation.state.device.xp
        if name == "dt":
            self.replica_dt = xp.where(self.active_on_device(), self.dt, self.replica_dt)
        self.replica_dt = xp.minimum(self.replica_dt, self.dt_max)

    def attach(self, simulation):
        state = simulation.state
        self._move = self.implementation("move", state)
        self._reset_vertices = self.implementation("reset_vertices", state)
        super().attach(simulation)

    def reset_motion(self):
        """Zero velocities and restore dt, alpha and counters of every replica."""
        state = self._simulation.state
        xp = state.device.xp
        r = state.n_replicas
        self.velocities = xp.zeros_like(state.positions)
        self.replica_dt = xp.full(r, self.dt)
        self.alpha = xp.full(r, self.alpha_start)
        self.n_positive = xp.zeros(r, dtype=xp.int64)

    checkpoint_fields = ("velocities", "replica_dt", "alpha", "n_positive")

    def restore_state(self, data: dict):
        """As every Minimizer, and per replica 0 < dt <= dt_max, 0 <= alpha <= alpha_start (FIRE never
        leaves these ranges: give the parameters of the run that wrote the checkpoint), n_positive >= 0."""
        saved_field(self, data, "replica_dt", np.float64, above=0, high=self.dt_max)
        saved_field(self, data, "alpha", np.float64, low=0, high=self.alpha_start)
        saved_field(self, data, "n_positive", np.int64, low=0)
        super().restore_state(data)
    narrowable = True
    per_replica = Minimizer.per_replica + ("replica_dt", "alpha", "n_positive")
    per_vertex = ("velocities",)

    def narrow(self, selection):
        """Velocities follow the selected vertices; dt, alpha, counters the selected replicas. The
        others have stopped: their velocities are zeroed, as the next step would do."""
        saved = super().narrow(selection)
        saved["velocities"] = self._simulation.device.xp.zeros_like(saved["velocities"])
        return saved

    def reset_vertices(self, vertices):
        """Zero the velocities of the given vertices (after a topology change, for example)."""
        self._reset_vertices(vertices)

    def _reset_vertices_cpu(self, vertices):
        vertices = np.asarray(vertices)
        self.velocities[vertices[vertices >= 0]] = 0.0

    def _reset_vertices_gpu(self, vertices):
        import cupy as cp
        vertices = cp.asarray(vertices, dtype=cp.int32)      # the kernel reads int (T1 passes int32 already)
        module = surface_kernels(_KERNELS, self._simulation.state)[0]
        launch(module.get_function("fire_reset_vertices"), len(vertices),
               (self.velocities, vertices, np.int32(len(vertices))))

    def move(self, simulation, forces):
        self._move(simulation, forces)

    def _move_cpu(self, simulation, forces):
        state = simulation.state
        xp = state.device.xp
        rep = state.vertex_replica
        n = state.n_replicas
        v = self.velocities

        def per_replica(a, b):                 # sum over each replica's vertices of the row dots a.b
            return weighted_bincount(rep, weights=xp.einsum("ij,ij->i", a, b), minlength=n)

        power = per_replica(forces, v)
        v_norm = xp.sqrt(per_replica(v, v))
        f_norm = xp.sqrt(per_replica(forces, forces))
        uphill = power <= 0
        grow = ~uphill & (self.n_positive >= self.n_min)
        mix = xp.where(uphill, 0.0, self.alpha)
        scale = xp.where(f_norm > 0, mix * v_norm / xp.where(f_norm > 0, f_norm, 1.0), 0.0)
        keep = xp.where(uphill, 0.0, 1.0 - mix)

        # stopped replicas keep their dt, alpha and counter
        on = self.active
        self.replica_dt = xp.where(on & uphill, self.replica_dt * self.f_dec,
                                   xp.where(on & grow, xp.minimum(self.replica_dt * self.f_inc, self.dt_max),
                                            self.replica_dt))
        self.alpha = xp.where(on & uphill, self.alpha_start,
                              xp.where(on & grow, self.alpha * self.f_alpha, self.alpha))
        self.n_positive = xp.where(on, xp.where(uphill, 0, self.n_positive + 1), self.n_positive)

        # per vertex: v <- keep v + scale F, then v <- v + dt F, x <- P_N(x + dt v), v <- P_T(x, v)
        dt = xp.where(on, self.replica_dt, 0.0)
        per_vertex = xp.take(xp.stack((keep, scale, dt)), rep, axis=1)[..., None]
        v = per_vertex[0] * v + (per_vertex[1] + per_vertex[2]) * forces
        self._guard(simulation, per_vertex[2] * v, on[rep])
        size = state.constraint.size(state, rep)
        x = state.constraint.project_normal(state.positions + per_vertex[2] * v, size)
        v = state.constraint.project_tangent(x, v, size)
        if bool(on.all()):
            state.positions, self.velocities = x, v
        else:
            moving = on[rep, None]
            state.positions = xp.where(moving, x, state.positions)
            self.velocities = xp.where(moving, v, 0.0)
        simulation.state_changed()

    def _length_unit(self, state):
        """sqrt(<A>) per replica on the device (once per State)."""
        return state.cached((self, "length_unit"),
                            lambda: state.device.asarray(np.sqrt(np.asarray(state.mean_cell_area, dtype=np.float64))))

    def _guard(self, simulation, dx, moving):
        """Raise before a move in which a moving vertex would go farther than max_step sqrt(<A>)."""
        state = simulation.state
        xp = state.device.xp
        step = xp.sqrt((dx * dx).sum(axis=1)) / self._length_unit(state)[state.vertex_replica]
        bad = ~(step <= self.max_step) & moving          # catches NaN too
        if bool(bad.any()):
            v = int(state.device.to_numpy(xp.flatnonzero(bad))[0])
            r = int(state.vertex_replica_np()[v])
            raise FloatingPointError(
                f"FIRE: exploding step at timestep {simulation.timestep}: replica {r}, vertex {v} would move "
                f"{float(step[v]):.3g} sqrt(<A>) (max_step={self.max_step}); reduce dt (now {self.dt}, dt_max "
                f"{self.dt_max}) or check the forces for NaN; the state was not moved")

    def check(self, simulation):
        """Raise for the earliest exploding step the GPU kernel flagged (one small read-back)."""
        raise_flagged_step(getattr(self, "_error", None), simulation, lambda step, r, v: (
            f"FIRE: exploding step at timestep {step}: replica {r}, vertex {v} would move more than "
            f"max_step={self.max_step} sqrt(<A>) or became NaN; reduce dt (now {self.dt}) or check the forces"))

    def _move_gpu(self, simulation, forces):
        """Two kernels (fire.cu, compiled for the State's surface): the per-replica sums, each
        replica's control as soon as its sums are final, and the per-vertex move."""
        state = simulation.state
        module, size = surface_kernels(_KERNELS, state)
        nv = state.n_vertices
        active = self.active_on_device()
        sums, control = self._scratch(simulation)
        launch(module.get_function("fire_reduce"), nv,
               (forces, self.velocities, state.vertex_replica, np.int32(nv), *sums,
                *segment_sums(state, "vertices", 3), active, self.replica_dt, self.alpha, self.n_positive, *control,
                *self._control_constants()))
        launch(module.get_function("fire_move"), nv,
               (state.positions, self.velocities, forces, state.vertex_replica, size, active, *control,
                np.int32(nv), self._length_unit(state), np.float64(self.max_step),
                *simulation.kernel_timestep(), self._error_word()))
        simulation.state_changed()

    def _control_constants(self):
        """FIRE's constants as the control (fire.cuh's FireParams) takes them: n_min, f_inc, f_dec,
        alpha_start, f_alpha, dt_max."""
        return (np.int32(self.n_min), np.float64(self.f_inc), np.float64(self.f_dec), np.float64(self.alpha_start),
                np.float64(self.f_alpha), np.float64(self.dt_max))

    def _scratch(self, simulation):
        """``(sums, control)``: the per-replica F.v, |v|^2, |F|^2 and keep, scale, step of an
        iteration, three rows of a (3, replicas) array each. Kept with the State between iterations
        (allocations cost the host as much as a launch); inside a CUDA graph capture made anew, from
        the graph's pool."""
        state = simulation.state
        xp = state.device.xp

        def build():
            return tuple(xp.empty((3, state.n_replicas))), tuple(xp.empty((3, state.n_replicas)))
        return build() if simulation.capturing else state.cached((self, "scratch"), build)

    #: the fused stage's arguments (fire_stage.cuh): fire_reduce's and fire_move's without the State's
    FUSED_ARGS = KernelStruct("FireArgs", [
        ("vel", "double*"), ("dt", "double*"), ("alpha", "double*"), ("n_positive", "long long*"), ("n_min", "int"),
        ("f_inc", "double"), ("f_dec", "double"), ("alpha_start", "double"), ("f_alpha", "double"),
        ("dt_max", "double"), ("length_unit", "const double*"), ("max_step", "double"),
        ("error", "unsigned long long*")])

    def fused_stage(self, simulation, minimizing):
        """fire_stage.cuh: the terms of FIRE's sums, its control and move, fire.cu's functions. None
        outside a minimisation, and for a subclass that moves otherwise."""
        if not minimizing or overrides(self, FIRE, ("move", "_move_gpu", "step")):
            return None
        values = dict(vel=self.velocities, dt=self.replica_dt, alpha=self.alpha, n_positive=self.n_positive,
                      n_min=self.n_min, f_inc=self.f_inc, f_dec=self.f_dec, alpha_start=self.alpha_start,
                      f_alpha=self.f_alpha, dt_max=self.dt_max, length_unit=self._length_unit(simulation.state),
                      max_step=self.max_step, error=self._error_word())
        return FusedStage("move", "FireStage", '#include "plugins/integrators/fire_stage.cuh"', self.FUSED_ARGS,
                          values, sums=3, vertex_doubles=3)

    def capture_ready(self, simulation, steps):
        """Its kernels read nothing back and take the timestep from ``Simulation.kernel_timestep``;
        the key holds its per-vertex and per-replica arrays (replaced by a reset, a checkpoint or a
        narrowing). None where a convergence check (a read-back) would fall due inside the steps:
        ``Simulation.minimize`` ends each stretch at the next check."""
        if steps > self.steps_to_check():
            return None
        return tuple(a.data.ptr for a in (self.velocities, self.replica_dt, self.alpha, self.n_positive,
                                          self.active_on_device(), self._error_word()))

    def _error_word(self):
        """The device word fire_move flags an exploding step in (made once; :meth:`check` reads it)."""
        if getattr(self, "_error", None) is None:
            import cupy as cp
            self._error = cp.full(1, np.iinfo(np.uint64).max, dtype=cp.uint64)
        return self._error

    @property
    def loggables(self):
        sim = self._simulation
        return {"fire_dt": lambda s: sim.state.device.to_numpy(self.replica_dt)}

    def __repr__(self):
        return (f"FIRE(dt={self.dt}, dt_max={self.dt_max}, n_min={self.n_min}, f_inc={self.f_inc}, "
                f"f_dec={self.f_dec}, alpha_start={self.alpha_start}, f_alpha={self.f_alpha}, "
                f"force_tol={self.force_tol}, energy_tol={self.energy_tol}, check_every={self.check_every}, "
                f"max_step={self.max_step})")
