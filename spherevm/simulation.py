"""Simulation: owns the State and the operations, runs steps and minimisations."""
from __future__ import annotations

import os
from dataclasses import dataclass, field

import numpy as np

from . import shapes
from .device import read_replica_summary, replica_summary, resolve
from .operations import Operations
from .plugins.base import Minimizer, compute_all
from .validation import GPU_RUN_BYTES_PER_CELL, check_memory, integer


@dataclass
class _ForceCache:
    """What :meth:`Simulation.compute_forces` keeps for the current state, and the convergence
    summary read from it (:meth:`Simulation.replica_summary`: the device array, then its host copy)."""
    forces: object
    energy: object
    cell_energy: object
    summary: object = None
    summary_host: tuple = None


@dataclass
class MinimizeResult:
    """Outcome of :meth:`Simulation.minimize`, one entry per replica (NumPy arrays)."""
    converged: np.ndarray
    reason: np.ndarray          # "force", "energy", "max_steps" or an operation's halt reason
    energy: np.ndarray          # total energy per replica
    energy_per_cell: np.ndarray
    max_force: np.ndarray
    steps: np.ndarray
    mean_shape_index: np.ndarray = field(default=None)

    @property
    def all_converged(self) -> bool:
        return bool(np.all(self.converged))

    def table(self) -> str:
        """A plain-text table, one row per replica."""
        rows = ["replica   energy/cell  <P/sqrt(A)>     max|F|  converged  reason          steps"]
        for r in range(len(self.converged)):
            rows.append(f"{r:7d}  {self.energy_per_cell[r]:12.6e}  {self.mean_shape_index[r]:11.6f}  "
                        f"{self.max_force[r]:9.3e}  {'yes' if self.converged[r] else 'no':9s}  "
                        f"{self.reason[r]:14s}  {int(self.steps[r]):5d}")
        return "\n".join(rows)


class Simulation:
    """A State plus the operations acting on it (HOOMD-blue style).

    >>> sim = Simulation(device="cpu")
    >>> sim.state = spherevm.init.random_tiling(64)
    >>> sim.operations.forces.append(spherevm.plugins.forces.VertexModel.dimensionless(kr=0, p0=3.8))
    >>> sim.operations.integrator = spherevm.plugins.integrators.FIRE(dt=0.05)
    >>> result = sim.minimize(force_tol=1e-10)
    """

    def __init__(self, device="auto", seed: int = 0):
        self.device = resolve(device)
        self.seed = integer("seed", seed, maximum=2**32 - 1)   # the Philox key is one 32-bit word
        self.timestep = 0
        self._state = None
        self._cache = None
        self._pending = {}          # operation state from a checkpoint, by key, until picked up
        self._updated_at = None     # the timestep at which the updaters last ran
        self._held_back = False     # ... in a minimisation, which held back those with in_minimize False
        self._step_counter = None   # inside CUDA graphs: the device's timestep (spherevm.graphs) ...
        self._step_offset = 0       # ... plus this step's place in the graph
        self._zero_step = None
        self.operations = Operations(self)

    # ------------------------------------------------------------------ state
    @property
    def state(self):
        return self._state

    @state.setter
    def state(self, value):
        """Set the State; the Simulation works on its own copy (on its device)."""
        from .state import State
        if not isinstance(value, State):
            raise TypeError(f"state must be a spherevm.State, got {type(value).__name__}")
        self._set_state(value, pending={})

    def _set_state(self, value, pending, updated_at=None, held_back=False):
        if self.device.is_gpu:        # refuse at once what the GPU cannot hold, not at the first kernel
            check_memory(f"a run of {value.n_cells} cells on the GPU", host_bytes=0.0,
                         device_bytes=float(value.n_cells) * GPU_RUN_BYTES_PER_CELL, gpu=True)
        self._state = value.copy() if value.device is self.device else value.to(self.device)
        self._cache = None
        self._pending = dict(pending)
        self._updated_at, self._held_back = updated_at, held_back
        for key, op in list(self.operations.keyed()):
            op.attach(self)
            self._restore_pending(op, key, keyed=True)

    def _restore_pending(self, op, where, keyed=False):
        """Hand ``op`` (just attached) its saved state from the checkpoint, if there is one."""
        key = where if keyed else op.checkpoint_key(where)
        data = self._pending.pop(key, None)
        if data is not None:
            op.restore_state(data)

    def create_state_from_gsd(self, path, frame: int = -1, validate: bool = True):
        """Set the State, the timestep and the saved state of the operations from a GSD frame
        (HOOMD's ``Simulation.create_state_from_gsd``), restored exactly on this Simulation's device.

        Every operation attached now or later picks up its saved state (FIRE's velocities, dt,
        alpha, counters and convergence; Active's directors; T1's counters and flip-back memory)
        when it attaches, by its checkpoint key (``Operation.checkpoint_key``): running on gives
        bitwise the uninterrupted run. ``validate``: see :func:`spherevm.gsdio.read_state`.
        See docs/file-format.md, *Checkpoints*."""
        from . import gsdio
        with gsdio.Reader(path) as reader:
            state = reader.state(frame, device=self.device, validate=validate)
            step = reader.step(frame)
            saved = reader.checkpoint(frame)
        sim = saved.pop("simulation", {})
        if "seed" in sim and int(sim["seed"][0]) != self.seed:
            import warnings
            warnings.warn(f"{path}: the checkpoint was written by a Simulation with seed={int(sim['seed'][0])}, "
                          f"this one has seed={self.seed}; the random numbers will differ from the original run",
                          stacklevel=2)
        updated = int(sim["updated_at"][0]) if "updated_at" in sim else -1
        held = bool(sim["held_back"][0]) if "held_back" in sim else False
        self.timestep = step
        self._restored_from = (os.path.realpath(path), step)   # a GSD writer into this file appends
        self._set_state(state, pending=saved.get("op", {}), updated_at=None if updated < 0 else updated,
                        held_back=held)

    def checkpoint(self) -> dict:
        """What a checkpoint frame holds besides the State: ``{chunk suffix: NumPy array}``, with
        ``op/<key>/<field>`` for every operation's :meth:`~spherevm.plugins.base.Operation.state_to_save`
        and ``simulation/<field>`` for the Simulation's own (seed, the timestep its updaters last ran,
        whether a minimisation held some back then)."""
        out = {"simulation/seed": np.array([self.seed], dtype=np.int64),
               "simulation/updated_at": np.array([-1 if self._updated_at is None else self._updated_at],
                                                 dtype=np.int64),
               "simulation/held_back": np.array([int(self._held_back)], dtype=np.int64)}
        for key, op in self.operations.keyed():
            for field_name, value in op.state_to_save().items():
                out[f"op/{key}/{field_name}"] = value
        for key, data in self._pending.items():   # not picked up yet: keep it for a later restart
            for field_name, value in data.items():
                out.setdefault(f"op/{key}/{field_name}", value)
        return out

    def _require_state(self):
        if self._state is None:
            raise RuntimeError("set sim.state first, for example sim.state = spherevm.init.random_tiling(64)")

    @property
    def capturing(self) -> bool:
        """Whether steps now run in CUDA-graph mode (:mod:`spherevm.graphs`): operations then read
        nothing back and take the timestep from :meth:`kernel_timestep`."""
        return self._step_counter is not None

    def kernel_timestep(self):
        """The timestep as two kernel arguments ``(step0, step_add)``, a device array: the kernel
        takes ``step0 + *step_add``. Step by step ``(timestep, 0)``; in CUDA graphs ``(the step's
        place in the graph, a device counter the graph advances by its length)``, so a replayed
        step draws its own Philox numbers."""
        if self._step_counter is not None:
            return np.uint64(self._step_offset), self._step_counter
        if self._zero_step is None:
            self._zero_step = self.device.xp.zeros(1, dtype=np.uint64)
        return np.uint64(self.timestep), self._zero_step

    def state_changed(self):
        """Operations call this after moving vertices or changing topology: cached forces go stale."""
        self._cache = None

    # ------------------------------------------------------------------ forces and logging
    def compute_forces(self):
        """Summed forces ``(V, 3)`` and energy per replica on the device, cached until the state changes."""
        self._require_state()
        if self._cache is None:
            if not self.operations.forces:   # free vertices: zero force, zero energy
                xp = self.device.xp
                zero = xp.zeros(self._state.n_replicas)
                self._cache = _ForceCache(xp.zeros_like(self._state.positions), zero, xp.zeros(self._state.n_cells))
                return self._cache.forces, self._cache.energy
            results = compute_all(self.operations.forces, self._state)
            forces, energy = results[0].forces, results[0].energy
            for res in results[1:]:
                forces = forces + res.forces
                energy = energy + res.energy
            cells = [res.cell_energy for res in results]
            cell_energy = None if any(c is None for c in cells) else sum(cells[1:], cells[0])
            self._cache = _ForceCache(forces, energy, cell_energy)
        return self._cache.forces, self._cache.energy

    def cell_energy(self):
        """Per-cell energy summed over the forces (device array), or None if a force does not report it."""
        self.compute_forces()
        return self._cache.cell_energy

    def max_force(self):
        """Largest vertex force magnitude per replica (device array)."""
        return self._summary()[:self._state.n_replicas].view(np.float64)

    def replica_summary(self):
        """``(max_force, energy, first_bad_vertex)`` in NumPy, from one device-to-host copy (a
        convergence check reads all three): the largest vertex force magnitude and the energy per
        replica, and the first vertex whose position is not finite (-1 if none). Cached with the
        forces until the state changes."""
        summary = self._summary()
        if self._cache.summary_host is None:
            self._cache.summary_host = read_replica_summary(summary, self._state.n_vertices, self._state.n_replicas)
        return self._cache.summary_host

    def _summary(self):
        """:func:`spherevm.device.replica_summary` of the current forces, cached with them."""
        forces, energy = self.compute_forces()
        if self._cache.summary is None:
            state = self._state
            self._cache.summary = replica_summary(state.positions, state.vertex_replica, state.n_replicas, forces,
                                                  energy)
        return self._cache.summary

    @property
    def loggables(self) -> dict:
        """Every loggable quantity by name: ``f(sim)`` returning a scalar or per-replica array."""
        to_np = self.device.to_numpy
        out = {
            "timestep": lambda s: s.timestep,
            "energy": lambda s: to_np(s.compute_forces()[1]),
            "energy_per_cell": lambda s: to_np(s.compute_forces()[1]) / s.state.cells_per_replica,
            "max_force": lambda s: to_np(s.max_force()),
            "mean_shape_index": lambda s: shapes.mean_shape_index(s.state),
        }
        owner = dict.fromkeys(out, "the Simulation")
        for op in self.operations:
            for name, fn in op.loggables.items():
                if name in owner:
                    raise ValueError(f"loggable {name!r} of {type(op).__name__} is already provided by {owner[name]}; "
                                     "give it another name (prefix it with the plugin's name)")
                owner[name], out[name] = type(op).__name__, fn
        return out

    def log(self, name: str):
        """The current value of a loggable quantity (NumPy)."""
        table = self.loggables
        if name not in table:
            raise ValueError(f"unknown loggable {name!r}; available: {sorted(table)}")
        return table[name](self)

    # ------------------------------------------------------------------ running
    def _update_once(self, minimizing=False):
        """The updaters of this timestep, unless they ran at it already (a ``minimize`` stops right
        after they ran; a resumed one, or a restart from its last frame, must not run them twice).
        ``minimizing``: those that sit minimisations out (``Updater.in_minimize`` False: growth) are
        held back; a ``run`` that goes on at the same timestep runs them."""
        if self._updated_at != self.timestep:
            self._update(minimizing)
        elif self._held_back and not minimizing:
            self._update(held_only=True)

    def _update(self, minimizing=False, held_only=False):
        """Run the updaters whose trigger fires now: every one, those with ``in_minimize`` while
        ``minimizing``, or (``held_only``) those a minimisation held back at this timestep."""
        self._updated_at, self._held_back = self.timestep, minimizing
        for u in self.operations.updaters:
            runs = not u.in_minimize if held_only else (u.in_minimize or not minimizing)
            if runs and u.trigger(self.timestep):
                u.update(self, self.timestep)

    def _integrate(self):
        integrator = self.operations.integrator
        if integrator.trigger(self.timestep):
            forces, _ = self.compute_forces()
            integrator.step(self, forces)
        self.timestep += 1

    def _write(self, final=False):
        """Run the writers whose trigger fires now (``final``: also those whose ``final`` is set, at
        the end of a run or minimisation), each at most once per timestep."""
        ts = self.timestep
        due = [w for w in self.operations.writers
               if (w.trigger(ts) or (final and getattr(w, "final", False))) and getattr(w, "_last_written", None) != ts]
        if due and self.operations.integrator is not None:
            self.operations.integrator.check(self)   # a step the GPU flagged: no frame of a broken state
        for w in due:
            w.write(self, ts)
            w._last_written = ts

    def run(self, steps: int, check_every=None, progress=None, graphs=None, fused=None):
        """Advance ``steps`` timesteps: updaters, forces, integrator, writers on each.

        Every ``check_every`` steps (default: every step on the CPU, every 100 on the GPU, where a
        check is a device-to-host read) the positions are checked: a NaN stops the run with
        FloatingPointError naming the step, replica and vertex; writers have flushed every frame
        before, so the last good frame stays on disk. ``progress(done, total)`` is called at checks.

        ``graphs``: run the steps between checks and writes as CUDA graphs (:mod:`spherevm.graphs`;
        the same trajectory bit for bit, several times faster for small tissues). None (default): on
        the GPU when every operation can, the run has at least ``graphs.MIN_STEPS`` steps and the
        State at most ``graphs.MAX_VERTICES`` vertices; True: always (ValueError naming what
        cannot); False: never.

        ``fused``: with graphs on, Brownian dynamics of small tissues run a stretch of steps in one
        launch, a thread block per tissue (:mod:`spherevm.tissue_steps`; the same trajectory bit for
        bit). None (default): wherever ``tissue_steps.why_not`` finds nothing against it; False:
        graph replays of the general kernels.
        """
        from .graphs import StepGraphs
        self._require_state()
        steps = integer("steps", steps)
        if self.operations.integrator is None:
            raise RuntimeError("set sim.operations.integrator before run()")
        if check_every is None:
            check_every = 100 if self.device.is_gpu else 1
        check_every = integer("check_every", check_every, minimum=1)
        runner = StepGraphs.for_run(self, steps, graphs, fused)
        self._write()   # the frame a run starts from (writers skip timesteps they already wrote)
        try:
            done = 0
            while done < steps:
                n = runner.stretch(done, steps, check_every) if runner is not None else 1
                if runner is None or not runner.advance(n):
                    for _ in range(n):
                        self._update_once()
                        self._integrate()
                done += n
                if done % check_every == 0 or done == steps:
                    self.check_finite()
                    if progress is not None:
                        if runner is not None:      # user code looks at (and may change) the State
                            runner.pause()
                            runner.forget()
                        progress(done, int(steps))
                if runner is not None and any(w.trigger(self.timestep) for w in self.operations.writers):
                    runner.pause()
                self._write()
            if runner is not None:
                runner.pause()
            self._write(final=True)   # the state the run ends in, for writers that ask for it
        finally:
            if runner is not None:
                runner.pause()
            self.flush()

    def check_finite(self):
        """Raise FloatingPointError naming the first vertex with a non-finite position (or the
        integrator's own error, such as an exploding step flagged on the GPU)."""
        if self.operations.integrator is not None:
            self.operations.integrator.check(self)
        state = self._state
        if self._cache is not None and self._cache.summary is not None:   # read with the forces already (a check)
            v = self.replica_summary()[2]
        else:
            v = read_replica_summary(replica_summary(state.positions, state.vertex_replica, state.n_replicas),
                                     state.n_vertices, state.n_replicas)[2]
        if v >= 0:
            r = int(state.vertex_replica_np()[v])
            raise FloatingPointError(f"non-finite position at timestep {self.timestep}: replica {r}, vertex {v}; "
                                     "reduce dt or check the forces (the last good frame is on disk)")

    def _narrow(self, keep):
        """Step only replicas ``keep`` (of the stepped State) from now on; returns what _widen needs."""
        selection = self._state.selection(keep)
        part = self._state.select(selection)
        saved = [op.narrow(selection) for op in self.operations]   # they still see the wider State
        wider, self._state, self._cache = self._state, part, None
        return selection, wider, saved

    def _widen(self, selection, wider, saved):
        """Undo one :meth:`_narrow`: the narrow State's replicas go back into the wider one."""
        wider.write_back(selection, self._state)
        self._state, self._cache = wider, None
        for op, data in zip(self.operations, saved):
            op.widen(selection, data)

    def flush(self):
        for w in self.operations.writers:
            if hasattr(w, "flush"):
                w.flush()

    def minimize(self, force_tol=None, energy_tol=None, max_steps: int = 100_000, check_every=None,
                 progress=None, narrow: bool = True, resume: bool = False, graphs=None,
                 fused=None) -> MinimizeResult:
        """Minimise every replica with the Minimizer integrator (FIRE if none is set) until each
        converges, is halted or ``max_steps`` iterations have passed.

        ``resume=False`` (default): the minimiser starts afresh (FIRE's velocities, dt, alpha,
        counters, convergence and iteration count reset; halting operations forget their history).
        ``resume=True``: it goes on from where it stands (after an earlier ``minimize``, a ``run``
        or a checkpoint restored with ``create_state_from_gsd``), for ``max_steps`` more
        iterations: ``minimize(1000)`` then ``minimize(1000, resume=True)`` is bitwise
        ``minimize(2000)`` (when ``check_every`` divides 1000: the first call checks convergence at
        its last iteration).

        Updaters run at every iteration (T1 exchanges), except those that change what the tissue
        is (``Updater.in_minimize`` False: Division, Extrusion, RadiusSchedule): a minimisation
        finds the inherent state of the tissue at its N and R, and those go on in the next ``run``.

        ``force_tol``, ``energy_tol`` and ``check_every`` set the minimiser's own (see
        :class:`spherevm.plugins.base.Minimizer`); None keeps them. ``progress`` is an optional
        callable ``progress(step, n_done, n_replicas)`` called at every convergence check.

        ``narrow``: once at most half of the replicas in the stepped State are still running, step
        a State of those alone (finished ones cost nothing more; each replica's arithmetic is the
        same), and put everything back at the end. Done only when no writer is attached and every
        operation is ``narrowable`` (see :class:`spherevm.plugins.base.Operation`). While narrowed,
        ``sim.state`` (and what a ``progress`` callback logs) holds the running replicas only.

        ``graphs``: run the iterations between two convergence checks as CUDA graphs, as
        :meth:`run` does (:mod:`spherevm.graphs`; the same minimisation bit for bit). None (default):
        on the GPU when every operation can, no writer is attached, ``max_steps`` is at least
        ``graphs.MIN_STEPS`` and the State has at most ``graphs.MAX_VERTICES`` vertices; True:
        always (ValueError naming what cannot); False: never. A ``progress`` callback sees the State
        as step by step, but must not change the operations' parameters (the graphs hold them).

        ``fused``: with graphs on, FIRE minimisations of small tissues run the iterations between
        two checks in one launch, a thread block per tissue (:mod:`spherevm.tissue_steps`; the same
        minimisation bit for bit). None (default): wherever ``tissue_steps.why_not`` finds nothing
        against it; False: graph replays of the general kernels.
        """
        from .graphs import StepGraphs
        from .plugins.integrators import FIRE   # the default minimiser
        self._require_state()
        if not self.operations.forces:
            raise RuntimeError("no force in sim.operations.forces; append one, e.g. "
                               "spherevm.plugins.forces.VertexModel.dimensionless(kr=1, p0=3.8)")
        max_steps = integer("max_steps", max_steps)
        if self.operations.integrator is None:
            self.operations.integrator = FIRE()
        fire = self.operations.integrator
        if not isinstance(fire, Minimizer):
            raise TypeError(f"minimize() needs a spherevm.plugins.Minimizer integrator such as FIRE, "
                            f"found {type(fire).__name__}")
        fire.configure(force_tol=force_tol, energy_tol=energy_tol, check_every=check_every)
        if not resume:
            fire.reset()
            for op in self.operations:
                op.reset_halted()
        limit = fire.iteration + max_steps
        narrow = narrow and not self.operations.writers and all(op.narrowable for op in self.operations)
        n_rep, n_cells = self._state.n_replicas, self._state.cells_per_replica
        narrowed = []
        runner = StepGraphs.for_minimize(self, max_steps, graphs, fused)
        self._write()
        try:
            while True:
                self._update_once(minimizing=True)
                if fire.check_due() or (fire.iteration >= limit and fire._checked_at != fire.iteration):
                    fire.check_convergence(self)
                if fire._checked_at == fire.iteration:
                    self.check_finite()   # NaN, or an exploding step the GPU kernel flagged
                    running = int((~fire.stopped).sum())
                    if progress is not None:
                        if runner is not None:
                            runner.pause()
                        progress(fire.iteration, n_rep - running, n_rep)
                    if running == 0 or fire.iteration >= limit:
                        break
                    if narrow and 2 * running <= len(fire.stopped):
                        if runner is not None:
                            runner.pause()
                        narrowed.append(self._narrow(np.flatnonzero(~fire.stopped)))
                if runner is not None:   # the iterations up to the next check (or the limit) in graphs
                    if runner.advance(min(fire.steps_to_check(), limit - fire.iteration, runner.max_stretch())):
                        continue
                    runner = None        # an operation cannot: step by step from here
                self._integrate()
                self._write()
        finally:
            if runner is not None:
                runner.pause()
            while narrowed:
                self._widen(*narrowed.pop())
            for u in self.operations.updaters:
                if not u.in_minimize:
                    u.after_minimize(self)
        self._write(final=True)   # the state the minimisation ends in, for writers that ask for it
        self.flush()
        _, energy = self.compute_forces()
        e = self.device.to_numpy(energy)
        running = fire.reason == "running"
        return MinimizeResult(converged=fire.replica_converged.copy(),
                              reason=np.where(running, "max_steps", fire.reason).astype(str), energy=e,
                              energy_per_cell=e / n_cells, max_force=self.device.to_numpy(self.max_force()),
                              steps=np.where(running, int(limit), fire.steps),
                              mean_shape_index=shapes.mean_shape_index(self._state))
