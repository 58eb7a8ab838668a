"""Overdamped Brownian and self-propelled (active) dynamics on the constraint surface."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from ... import random as rng
from ...device import launch
from ...validation import non_negative, positive
from ...constraints.kernels import KERNEL_SURFACES, surface_kernels
from ...kernel_struct import KernelStruct
from ..base import Integrator, raise_flagged_step
from ..fusion import FusedStage, overrides
from ..parameters import Parameter

_KERNELS = Path(__file__).with_suffix(".cu")


class Brownian(Integrator):
    """Overdamped Brownian dynamics, the paper's Methods.

    ``dr = P_T(r, mu dt F + eta)``, ``<eta_a eta_b> = 2 mu T dt delta_ab`` per Cartesian component,
    then ``r <- P_N(r + dr)``. Noise is Philox (``spherevm.random``) keyed by (simulation seed,
    stream 0) and counted by (timestep, global vertex id), so CPU and GPU draw the same numbers.

    Parameters
    ----------
    dt : float
        Time step, > 0.
    T : float or array (n_replicas,)
        Temperature, >= 0 (one per replica: a temperature series in one ensemble).
    mu : float
        Mobility.
    max_step : float
        Units of sqrt(<A>): a larger displacement of any vertex stops the run with the step,
        replica and vertex named."""

    dt = Parameter(positive)
    T = Parameter(non_negative)
    mu = Parameter(lambda name, value: float(non_negative(name, value, per_item="a scalar")))
    max_step = Parameter(positive)

    def __init__(self, dt, T=0.0, mu=1.0, max_step=0.5):
        super().__init__()
        self.dt = dt
        self.T = T
        self.mu = mu
        self.max_step = max_step

    gpu_surfaces = KERNEL_SURFACES
    surface_needs = ("normal", "project_normal", "total_area_np")

    def attach(self, simulation):
        super().attach(simulation)
        self._step = self.implementation("step", simulation.state)
        self.check_parameters()

    def check_parameters(self):
        """A per-replica T must have one value per replica of the attached State."""
        if self._simulation is not None and self.T.ndim == 1:
            n = self._simulation.state.n_replicas
            if len(self.T) != n:
                raise ValueError(f"T has {len(self.T)} values but the state has {n} replicas")

    def _drift(self, simulation, forces):
        """Deterministic velocity of every vertex: mu F (Active adds self-propulsion)."""
        return self.mu * forces

    _mode = 0          # CUDA kernel: 0 no self-propulsion, 1 cell directors, 2 vertex directors

    def step(self, simulation, forces):
        self._step(simulation, forces)

    def _step_cpu(self, simulation, forces):
        state = simulation.state
        xp = state.device.xp
        con = state.constraint
        amp = self._per_replica(state)[1][state.vertex_replica]
        eta = xp.asarray(rng.normal(simulation.seed, rng.STREAM_BROWNIAN, simulation.timestep,
                                    np.arange(state.n_vertices), 3))
        dr = con.project_tangent(state.positions, self.dt * self._drift(simulation, forces) + amp[:, None] * eta,
                                 con.size(state, state.vertex_replica))
        self._guard(simulation, dr)
        state.positions = con.project_normal(state.positions + dr, con.size(state, state.vertex_replica))
        self._after_move(simulation)
        simulation.state_changed()

    def _after_move(self, simulation):
        pass

    def _error_flag(self):
        """The device word in which kernels flag the earliest exploding step (:meth:`check` reads it)."""
        if getattr(self, "_error", None) is None:
            import cupy as cp
            self._error = cp.full(1, np.iinfo(np.uint64).max, dtype=cp.uint64)
        return self._error

    def _step_gpu(self, simulation, forces):
        """One kernel per step (brownian.cu, compiled for the State's surface), plus one per cell for
        cell directors."""
        state = simulation.state
        self._error_flag()
        module, size = surface_kernels(_KERNELS, state)
        unit, amp = self._per_replica(state)
        directors = self.directors if self._mode else self._error   # mode 0 reads no directors
        rot_amp = float(np.sqrt(2.0 * self.Dr * self.dt)) if self._mode else 0.0
        step0, step_add = simulation.kernel_timestep()
        launch(module.get_function("brownian_move"), state.n_vertices,
               (state.positions, forces, state.vertex_replica, state.vertex_cells, size, amp, unit,
                directors, np.int32(self._mode), np.float64(self.mu), np.float64(self.dt),
                np.float64(getattr(self, "v0", 0.0)), np.float64(rot_amp), np.float64(self.max_step),
                np.uint32(simulation.seed), step0, step_add, np.int32(state.n_vertices), self._error))
        if self._mode == 1:
            launch(module.get_function("active_cell_directors"), state.n_cells,
                   (state.positions, state.cell_vertices, state.cell_sides, self.directors, np.int32(state.n_cells),
                    np.int32(state.max_sides), np.float64(rot_amp), np.uint32(simulation.seed), step0, step_add,
                    state.cell_replica, size))
        simulation.state_changed()

    def capture_ready(self, simulation, steps):
        """Its kernels take the timestep through ``Simulation.kernel_timestep``: CUDA graphs may hold them."""
        return ()

    #: the fused stage's arguments (brownian_stage.cuh), brownian_move's without the State's
    FUSED_ARGS = KernelStruct("BrownianArgs", [
        ("amp", "const double*"), ("length_unit", "const double*"), ("directors", "double*"), ("mu", "double"),
        ("dt", "double"), ("v0", "double"), ("rot_amp", "double"), ("max_step", "double"), ("seed", "unsigned int"),
        ("error", "unsigned long long*")])

    def fused_stage(self, simulation, minimizing):
        """brownian_stage.cuh: each vertex's move (and, with cell directors, each cell's director
        after it), brownian.cu's functions. None in a minimisation, and for a subclass that moves
        otherwise."""
        if minimizing or overrides(self, Brownian, ("step", "_step_gpu", "_per_replica")):
            return None
        unit, amp = self._per_replica(simulation.state)
        values = dict(amp=amp, length_unit=unit, directors=self.directors if self._mode else None, mu=self.mu,
                      dt=self.dt, v0=getattr(self, "v0", 0.0),
                      rot_amp=float(np.sqrt(2.0 * self.Dr * self.dt)) if self._mode else 0.0,
                      max_step=self.max_step, seed=simulation.seed, error=self._error_flag())
        return FusedStage("move", f"BrownianStage<{self._mode}>",
                          '#include "plugins/integrators/brownian_stage.cuh"', self.FUSED_ARGS, values)

    def _per_replica(self, state):
        """sqrt(<A>) and the noise amplitude sqrt(2 mu T dt) per replica, on the device (computed
        once per State)."""
        def build():
            T = np.broadcast_to(self.T, (state.n_replicas,))
            return (state.device.asarray(np.sqrt(state.mean_cell_area)),
                    state.device.asarray(np.sqrt(2.0 * self.mu * T * self.dt)))
        return state.cached((self, "per_replica"), build)

    def check(self, simulation):
        """Raise for the earliest exploding step the GPU kernel flagged (one small read-back)."""
        raise_flagged_step(getattr(self, "_error", None), simulation, lambda step, r, v: (
            f"exploding step at timestep {step}: replica {r}, vertex {v} moved more than max_step="
            f"{self.max_step} sqrt(<A>) or became NaN; reduce dt (now {self.dt}) or check the forces"))

    def _guard(self, simulation, dr):
        state = simulation.state
        xp = state.device.xp
        scale = self._per_replica(state)[0][state.vertex_replica]
        step = xp.sqrt((dr * dr).sum(axis=1)) / scale
        bad = ~(step <= self.max_step)          # catches NaN too
        if bool(bad.any()):
            v = int(state.device.to_numpy(xp.flatnonzero(bad))[0])
            r = int(state.vertex_replica_np()[v])
            raise FloatingPointError(
                f"exploding step at timestep {simulation.timestep}: replica {r}, vertex {v} would move "
                f"{float(step[v]):.3g} sqrt(<A>) (max_step={self.max_step}); reduce dt (now {self.dt}) or "
                "check the forces for NaN")

    def __repr__(self):
        return f"{type(self).__name__}(dt={self.dt}, T={self.T}, mu={self.mu})"


def _tangent_directions(normal, angle):
    """Unit tangent vectors at the unit normals ``normal`` (NumPy, (n, 3)), at ``angle`` from the
    tangent basis ``e1 = n x (x or y), e2 = n x e1``."""
    e1 = np.cross(normal, np.where(np.abs(normal[:, [0]]) < 0.9, [[1.0, 0, 0]], [[0, 1.0, 0]]))
    e1 /= np.linalg.norm(e1, axis=1)[:, None]
    e2 = np.cross(normal, e1)
    return np.cos(angle)[:, None] * e1 + np.sin(angle)[:, None] * e2


def _director_mode(name, value):
    if value not in ("cell", "vertex"):
        raise ValueError(f"directors must be 'cell' or 'vertex', got {value!r}")
    return value


class Active(Brownian):
    """Self-propelled vertex-model dynamics: velocity ``mu F + v0 p`` plus optional noise T.

    Each step a director rotates about the local surface normal by a Gaussian angle of variance
    ``2 Dr dt`` (Philox stream 1, counted by cell or vertex id); after the vertices move it is
    projected on the tangent plane at its new base point and renormalised (parallel transport to
    first order). Initial directors are uniform random angles in the tangent plane (stream 2). At a
    division the mother keeps her director and the daughter draws a new one, as cellGPU's active
    cells do (Philox stream 3, draw 2; with vertex directors the two new vertices draw theirs,
    stream 4); a T2's merged vertex keeps its own.

    Parameters
    ----------
    dt : float
        Time step, > 0.
    v0 : float
        Self-propulsion speed.
    Dr : float
        Rotational diffusion constant of the directors.
    mu, T, max_step
        As in :class:`Brownian`.
    directors : {"cell", "vertex"}
        "cell" (the active vertex model of the planar GPU code): every cell carries a unit
        director in the tangent plane at its centroid, and a vertex moves with the mean of its three
        cells' directors, projected on its own tangent plane. "vertex": each vertex carries its own."""

    v0 = Parameter(lambda name, value: float(non_negative(name, value, per_item="a scalar")))
    Dr = Parameter(lambda name, value: float(non_negative(name, value, per_item="a scalar")))
    mode = Parameter(_director_mode, fixed="the directors are drawn for it at attach; build a new Active "
                                           "and set it as the integrator")

    def __init__(self, dt, v0, Dr, mu=1.0, T=0.0, directors="cell", max_step=0.5):
        self.directors = None
        super().__init__(dt, T=T, mu=mu, max_step=max_step)
        self.v0 = v0
        self.Dr = Dr
        self.mode = directors

    @property
    def _mode(self):
        """The CUDA kernel's mode: 1 cell directors, 2 vertex directors."""
        return 1 if self.mode == "cell" else 2

    checkpoint_fields = ("directors",)   # a restart takes them back instead of drawing new ones

    def _bases(self, state):
        """Unit normals at the directors' base points: cell centres or vertices."""
        con = state.constraint
        if self.mode == "cell":
            return con.cell_normals(state)
        return con.normal(state.positions, con.size(state, state.vertex_replica))

    def attach(self, simulation):
        super().attach(simulation)
        state = simulation.state
        normal = state.device.to_numpy(self._bases(state))
        n = len(normal)
        angle = rng.TWO_PI * rng.uniform(simulation.seed, rng.STREAM_DIRECTOR_INIT, 0, np.arange(n), 1)[:, 0]
        self.directors = state.device.asarray(_tangent_directions(normal, angle))

    def resized(self, change):
        """Directors follow their cells (or vertices); a daughter cell (a created vertex) draws a
        new one, see the class docstring."""
        sim = self._simulation
        state = sim.state
        if self.mode == "cell":
            source, born = change.cell_source, np.flatnonzero(change.new_cells)
            stream, ids, draw = rng.STREAM_DIVISION, source[born], 2
        else:
            source, born = change.vertex_source, np.flatnonzero(change.vertex_source < 0)
            stream, ids, draw = rng.STREAM_VERTEX_BIRTH, born, 0
        dev = state.device
        self.directors = self.directors[dev.asarray(np.maximum(source, 0))]
        if len(born):
            angle = rng.TWO_PI * rng.uniform(sim.seed, stream, sim.timestep, ids, draw + 1)[:, draw]
            normal = dev.to_numpy(self._bases(state)[dev.asarray(born)])
            self.directors[dev.asarray(born)] = dev.asarray(_tangent_directions(normal, angle))

    def _drift(self, simulation, forces):
        state = simulation.state
        p = self.directors
        if self.mode == "cell":
            p = p[state.vertex_cells].mean(axis=1)
            p = state.constraint.project_tangent(state.positions, p, state.constraint.size(state, state.vertex_replica))
        return self.mu * forces + self.v0 * p

    def _after_move(self, simulation):
        state = simulation.state
        xp = state.device.xp
        normal = self._bases(state)
        d = self.directors - (self.directors * normal).sum(axis=1)[:, None] * normal
        d = d / xp.sqrt((d * d).sum(axis=1))[:, None]
        if self.Dr > 0:
            theta = np.sqrt(2.0 * self.Dr * self.dt) * xp.asarray(
                rng.normal(simulation.seed, rng.STREAM_ACTIVE, simulation.timestep, np.arange(len(d)), 1))
            d = xp.cos(theta) * d + xp.sin(theta) * xp.cross(normal, d)
        self.directors = d

    @property
    def loggables(self):
        return {}

    def __repr__(self):
        return (f"Active(dt={self.dt}, v0={self.v0}, Dr={self.Dr}, mu={self.mu}, T={self.T}, "
                f"directors={self.mode!r})")
