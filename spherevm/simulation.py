"""Simulation: owns the State and the operations, runs steps and minimisations."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import shapes, simplicity
from .checkpoints import Checkpoints
from .device import read_replica_summary, replica_summary, resolve
from .graphs import StepGraphs
from .operations import Operations
from .minimization import Minimization, MinimizeResult
from .plan import Plan
from .plugins.base import compute_all
from .plugins.minimizer import Minimizer
from .runs import RunRecords, stepping
from .validation import GPU_RUN_BYTES_PER_CELL, check_memory, integer


@dataclass
class _ForceCache:
    """The forces of the current state and their convergence summary (device array, host copy)."""
    forces: object
    energy: object
    cell_energy: object
    summary: object = None
    summary_host: tuple = None


class Simulation(Checkpoints, RunRecords):
    """A State plus the operations acting on it (HOOMD-blue style).

    Parameters
    ----------
    device : {"auto", "cpu", "gpu"} or Device
        Where the State lives; "auto" takes the GPU when CuPy sees one.
    seed : int
        Seed of every random stream of the run (Brownian noise, divisions, ...); docs/index.md
        shows a whole script."""

    def __init__(self, device="auto", seed: int = 0):
        self.device = resolve(device)
        self.seed = integer("seed", seed, maximum=2**32 - 1)   # the Philox key is one 32-bit word
        self.timestep = 0
        self._state = None
        self._cache = None
        self._pending = {}          # operation state from a checkpoint, by key, until picked up
        self._updated_at = None     # the timestep at which the updaters last ran
        self._held_back = False     # ... in a minimisation, which held back those with in_minimize False
        #: inside CUDA graphs: the device's timestep (:class:`spherevm.plan.DeviceClock`), else None
        self.device_clock = None
        #: ``(real path, step)`` of the GSD frame the State was last restored from, else None
        self.restored_from = None
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
            self.restore_saved_state(op, key, keyed=True)

    def require_state(self):
        """Raise RuntimeError saying how to set one if the Simulation has no State yet."""
        if self._state is None:
            raise RuntimeError("set sim.state first, for example sim.state = spherevm.init.random_tiling(64)")

    @property
    def capturing(self) -> bool:
        """Whether steps now run in CUDA-graph mode (:mod:`spherevm.graphs`): operations then read
        nothing back and take the timestep from :meth:`kernel_timestep`."""
        return self.device_clock is not None

    def kernel_timestep(self):
        """The timestep as two kernel arguments ``(step0, step_add)``, a device array: the kernel
        takes ``step0 + *step_add``. Step by step ``(timestep, 0)``; in CUDA graphs ``(the step's
        place in the graph, a device counter the graph advances by its length)``, so a replayed
        step draws its own Philox numbers."""
        clock = self.device_clock
        if clock is not None:
            return np.uint64(self.timestep - clock.start), clock.counter
        if self._zero_step is None:
            self._zero_step = self.device.xp.zeros(1, dtype=np.uint64)
        return np.uint64(self.timestep), self._zero_step

    def state_changed(self):
        """Operations call this after moving vertices or changing topology: cached forces go stale."""
        self._cache = None

    # ------------------------------------------------------------------ forces and logging
    def compute_forces(self):
        """The summed forces ``(V, 3)`` and the energy per replica, on the State's device, cached.

        Returns
        -------
        (forces, energy)"""
        self.require_state()
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
        """The largest vertex force magnitude per replica, on the State's device.

        Returns
        -------
        array"""
        return self._summary()[:self._state.n_replicas].view(np.float64)

    def replica_summary(self):
        """What a convergence check reads, in NumPy from one read-back; cached with the forces.

        Returns
        -------
        (max_force, energy, first_bad_vertex, open_flag)
            Per replica: the largest vertex force, the energy; the first non-finite vertex (-1: none),
            and 1 if the device found an open cell (GPU, periodic plane; else 0)."""
        summary = self._summary()
        if self._cache.summary_host is None:
            self._cache.summary_host = read_replica_summary(summary, self._state.n_vertices, self._state.n_replicas)
        return self._cache.summary_host

    def _summary(self):
        """:func:`spherevm.device.replica_summary` of the current forces, cached with them."""
        forces, energy = self.compute_forces()
        if self._cache.summary is None:
            state = self._state
            self._cache.summary = self._with_open_flag(
                replica_summary(state.positions, state.vertex_replica, state.n_replicas, forces, energy))
        return self._cache.summary

    def _with_open_flag(self, summary):
        """The summary with its last word set on the device if a cell is open (GPU, periodic plane:
        :func:`spherevm.simplicity.flag_open_cells`), read back with the rest at a check."""
        simplicity.flag_open_cells(self._state, summary[-1:])
        return summary

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
            "tps": lambda s: s.tps,
            "walltime": lambda s: s.walltime,
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
        """The current value of loggable ``name`` (one of :attr:`loggables`).

        Parameters
        ----------
        name : str

        Returns
        -------
        numpy.ndarray or float
            One value per replica, or a scalar."""
        table = self.loggables
        if name not in table:
            raise ValueError(f"unknown loggable {name!r}; available: {sorted(table)}")
        return table[name](self)

    # ------------------------------------------------------------------ stepping (the executors' API)
    def update(self, minimizing=False):
        """Run the updaters of this timestep, unless they ran at it already (a ``minimize`` stops
        right after they ran; a resumed one, or a restart from its last frame, must not run them
        twice). ``minimizing``: those that sit minimisations out (``Updater.in_minimize`` False:
        growth) are held back; a ``run`` that goes on at the same timestep runs them."""
        if self._updated_at != self.timestep:
            self.run_updaters(minimizing)
        elif self._held_back and not minimizing:
            self.run_updaters(held_only=True)

    def run_updaters(self, minimizing=False, held_only=False):
        """Run the updaters whose trigger fires now: every one, those with ``in_minimize`` while
        ``minimizing``, or (``held_only``) those a minimisation held back at this timestep."""
        self._updated_at, self._held_back = self.timestep, minimizing
        for u in self.operations.updaters:
            runs = not u.in_minimize if held_only else (u.in_minimize or not minimizing)
            if runs and u.trigger(self.timestep):
                u.update(self, self.timestep)

    def updated_now(self) -> bool:
        """Whether the updaters already ran at the current timestep."""
        return self._updated_at == self.timestep

    def integrate(self):
        """The forces and the integrator's step (if its trigger fires), then the timestep advances."""
        integrator = self.operations.integrator
        if integrator.trigger(self.timestep):
            forces, _ = self.compute_forces()
            integrator.step(self, forces)
        self.timestep += 1

    def advanced(self, steps: int, minimizing: bool):
        """An executor ran ``steps`` whole cycles of the plan on the device (the timestep and the
        minimiser's iteration count advance on the host; the updaters count as run at the last
        timestep, those not ``in_minimize`` held back when ``minimizing``; topology and forces go
        stale)."""
        self.timestep += steps
        integrator = self.operations.integrator
        if isinstance(integrator, Minimizer):
            integrator.iteration += steps
        if minimizing:
            self._updated_at, self._held_back = self.timestep, True
        else:
            self._updated_at, self._held_back = self.timestep - 1, False
        self._state.topology_changed()
        self.state_changed()

    def write(self, final=False):
        """Run the writers whose trigger fires now (``final``: also those whose ``final`` is set, at
        the end of a run or minimisation), each at most once per timestep."""
        ts = self.timestep
        due = [w for w in self.operations.writers
               if (w.trigger(ts) or (final and w.final)) and w.last_written != ts]
        if due and self.operations.integrator is not None:
            self.operations.integrator.check(self)   # a step the GPU flagged: no frame of a broken state
        for w in due:
            w.write(self, ts)
            w.last_written = ts

    @stepping
    def run(self, steps: int, check_every=None, progress=None, graphs=None, fused=None, write_at_start=True):
        """Advance ``steps`` timesteps: updaters, forces, integrator, writers on each.

        Parameters
        ----------
        steps : int
            Number of timesteps.
        check_every, progress : int, callable, optional
            Steps between checks (default 1 on the CPU, 100 on the GPU), where ``progress(done, total)``
            is called; a NaN position stops the run with FloatingPointError naming step and vertex.
        graphs, fused : bool, optional
            Run stretches as CUDA graphs (:mod:`spherevm.graphs`), small tissues' steps fused
            (:mod:`spherevm.tissue_steps`), the same trajectory bit for bit. None: where they apply;
            True: insist (ValueError naming what cannot); False: never (docs/performance.md);
            :meth:`explain` says which runs each operation.
        write_at_start : bool
            First run the writers whose trigger fires at the current timestep, unless they wrote it
            already (default); False skips them (HOOMD-blue's default)."""
        self.require_state()
        steps = integer("steps", steps)
        if self.operations.integrator is None:
            raise RuntimeError("set sim.operations.integrator before run()")
        if check_every is None:
            check_every = 100 if self.device.is_gpu else 1
        check_every = integer("check_every", check_every, minimum=1)
        plan = Plan(self)
        runner = StepGraphs.for_run(plan, steps, graphs, fused)
        if write_at_start:
            self.write()   # the frame a run starts from (writers skip timesteps they already wrote)
        try:
            done = 0
            while done < steps:
                n = runner.stretch(done, steps, check_every) if runner is not None else 1
                if runner is None or not runner.advance(n):
                    for _ in range(n):
                        plan.cycle()
                done += n
                if done % check_every == 0 or done == steps:
                    self.check_finite()
                    if progress is not None:
                        if runner is not None:      # user code looks at (and may change) the State
                            runner.pause()
                            runner.forget()
                        progress(done, int(steps))
                if runner is not None and any(w.trigger(self.timestep) for w in plan.writers):
                    runner.pause()
                self.write()
            if runner is not None:
                runner.pause()
            self.write(final=True)   # the state the run ends in, for writers that ask for it
        finally:
            if runner is not None:
                runner.pause()
            self.flush()

    def explain(self, minimize: bool = False, steps: int = 1000) -> str:
        """Which executor (step by step, CUDA graphs, fused) would run each operation of a
        ``run(steps)`` (``minimize``: of a ``minimize(max_steps=steps)``) now, and why.

        Parameters
        ----------
        minimize : bool
        steps : int

        Returns
        -------
        str
            The order of a step, then one line per operation.
        """
        self.require_state()
        plan = Plan(self, minimizing=minimize)
        return plan.explain(*StepGraphs.reasons(plan, steps))

    def check_finite(self):
        """Raise FloatingPointError naming the first vertex with a non-finite position (or the
        integrator's own error, such as an exploding step flagged on the GPU), and ValueError naming
        the edge of a cell that no longer closes (:func:`spherevm.simplicity.check_closed`; on the
        GPU flagged by the device in the summary this check reads anyway, and named on the host only
        then)."""
        if self.operations.integrator is not None:
            self.operations.integrator.check(self)
        state = self._state
        if self._cache is not None and self._cache.summary is not None:   # read with the forces already (a check)
            v, opened = self.replica_summary()[2:]
        else:
            v, opened = read_replica_summary(self._with_open_flag(replica_summary(
                state.positions, state.vertex_replica, state.n_replicas)), state.n_vertices, state.n_replicas)[2:]
        if v >= 0:
            r = int(state.vertex_replica_np()[v])
            raise FloatingPointError(f"non-finite position at timestep {self.timestep}: replica {r}, vertex {v}; "
                                     "reduce dt or check the forces (the last good frame is on disk)")
        if opened or not simplicity.closed_on_device(state):   # cells that no longer close (periodic surfaces)
            if opened:           # T1 passes inside CUDA graphs edit the tables without the host's caches knowing
                state.topology_changed()
            try:
                simplicity.check_closed(state)
            except ValueError as exc:
                raise ValueError(f"at timestep {self.timestep}: {exc}") from None

    def narrow(self, keep):
        """Step only replicas ``keep`` (of the stepped State) from now on (a minimisation's finished
        replicas cost nothing more); returns what :meth:`widen` needs."""
        selection = self._state.selection(keep)
        part = self._state.select(selection)
        saved = [op.narrow(selection) for op in self.operations]   # they still see the wider State
        wider, self._state, self._cache = self._state, part, None
        return selection, wider, saved

    def widen(self, selection, wider, saved):
        """Undo one :meth:`narrow`: the narrow State's replicas go back into the wider one."""
        wider.write_back(selection, self._state)
        self._state, self._cache = wider, None
        for op, data in zip(self.operations, saved):
            op.widen(selection, data)

    def flush(self):
        for w in self.operations.writers:
            if hasattr(w, "flush"):
                w.flush()

    @stepping
    def minimize(self, force_tol=None, energy_tol=None, max_steps: int = 100_000, check_every=None,
                 progress=None, narrow: bool = True, resume: bool = False, graphs=None,
                 fused=None) -> MinimizeResult:
        """Minimise every replica with the Minimizer integrator (FIRE by default) until each converges,
        is halted or ``max_steps`` iterations pass; growth updaters (``in_minimize`` False) sit it out.

        Parameters
        ----------
        force_tol, energy_tol, check_every : optional
            Set the minimiser's own (:class:`spherevm.plugins.minimizer.Minimizer`); None keeps them.
        max_steps : int
            Iteration limit; replicas still running then stop with reason ``"max_steps"``.
        progress : callable, optional
            ``progress(step, n_done, n_replicas)``, called at every check.
        narrow : bool
            Once at most half run, step a State of those alone (same numbers; no writers, ``narrowable`` ops).
        resume : bool
            False: start afresh (FIRE's velocities, dt, alpha reset). True: go on for ``max_steps`` more
            (``minimize(1000)`` then ``minimize(1000, resume=True)`` is bitwise ``minimize(2000)``).
        graphs, fused : bool, optional
            As in :meth:`run`, for the iterations between two checks (the same minimisation bit for bit).

        Returns
        -------
        MinimizeResult"""
        from .plugins.integrators import FIRE   # the default minimiser
        self.require_state()
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
        n_cells = self._state.cells_per_replica
        plan = Plan(self, minimizing=True)
        runner = StepGraphs.for_minimize(plan, max_steps, graphs, fused)
        self.write()   # the frame a minimisation starts from
        Minimization(plan, runner, limit, narrow, progress).run()
        self.write(final=True)   # the state the minimisation ends in, for writers that ask for it
        self.flush()
        _, energy = self.compute_forces()
        e = self.device.to_numpy(energy)
        running = fire.reason == "running"
        return MinimizeResult(converged=fire.replica_converged.copy(),
                              reason=np.where(running, "max_steps", fire.reason).astype(str), energy=e,
                              energy_per_cell=e / n_cells, max_force=self.device.to_numpy(self.max_force()),
                              steps=np.where(running, int(limit), fire.steps),
                              mean_shape_index=shapes.mean_shape_index(self._state))
