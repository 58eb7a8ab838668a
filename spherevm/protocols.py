"""The paper's finite-temperature protocol: relax, equilibrate, then record the glassy dynamics."""
from __future__ import annotations

import csv
import warnings
from dataclasses import dataclass

import numpy as np

from . import analysis, init
from .plugins.forces import VertexModel
from .plugins.integrators import FIRE, Brownian
from .plugins.updaters import T1
from .plugins.writers import GSD
from .simulation import Simulation
from .state import State
from .validation import check_run_memory, integer


@dataclass
class DynamicsResult:
    """MSD and self-overlap of a run (lags in time units), averaged over replicas and per replica.

    ``tau_alpha`` is read off the replica-averaged Q_s; ``tau_alpha_per_replica`` off each replica's.
    ``production_start`` is the timestep production began at (after relaxation and equilibration):
    the GSD's first frame and the origin of every lag (a lag of t is timestep production_start + t/dt).
    """
    lag: np.ndarray
    msd: np.ndarray
    self_overlap: np.ndarray
    msd_per_replica: np.ndarray            # (n_lags, n_replicas)
    self_overlap_per_replica: np.ndarray   # (n_lags, n_replicas)
    tau_alpha: float
    tau_alpha_per_replica: np.ndarray
    simulation: Simulation
    production_start: int = 0

    def write_csv(self, path):
        """Columns: time, msd, self_overlap (lengths in units of sqrt(<A>))."""
        with open(path, "w", newline="") as f:
            w = csv.writer(f)
            w.writerow(["time", "msd", "self_overlap"])
            for row in zip(self.lag, self.msd, self.self_overlap):
                w.writerow([f"{x:.10g}" for x in row])


def glassy_dynamics(n_cells, p0, kr, T, dt=0.01, steps=10_000, replicas=1, seed=0, device="auto",
                    relax_steps=10_000, equilibrate_steps=None, b=0.5, points_per_decade=10, out=None,
                    frames=50, t1=True, progress=None, surface: str = "sphere",
                    extra_forces=(), restart=None, initial_state=None, graphs=None) -> DynamicsResult:
    """Overdamped Brownian dynamics of random tilings, measured as in the paper (Fig. 3).

    1. **relax**: FIRE (+ T1) from a random tiling for at most ``relax_steps`` steps, so the run
       starts from an inherent state rather than from the random Voronoi tiling;
    2. **equilibrate**: ``equilibrate_steps`` Brownian steps at temperature ``T`` (default
       ``steps // 10``), discarded;
    3. **production**: ``steps`` Brownian steps, cell centroids recorded at log-spaced times; MSD and
       self-overlap Q_s (window ``b``) in the co-rotating frame (global rotation removed; on the
       plane, the centre-of-mass drift), and
       tau_alpha where Q_s reaches 1/e (NaN if it does not within the run).

    ``T`` may hold one temperature per replica: a whole temperature series runs as one ensemble.
    ``graphs``: passed to :meth:`Simulation.run` for the Brownian stages (None: CUDA graphs on a GPU,
    the same trajectories several times faster for small tissues; False: step by step).
    ``out``: GSD trajectory of the production run (``frames`` frames, log-spaced); its first frame
    is at the end of relaxation and equilibration, not at step 0 (``configuration/step`` counts
    every step of the run, so the Philox noise never repeats and a restart goes on bitwise): the
    result's ``production_start`` is that step. ``progress``:
    ``progress(stage, done, total)``. ``extra_forces``: Force instances added to the vertex model
    (e.g. ``Bending(B)``), in every stage. Time unit: 1/(mu kP) with mu = 1; dt in that unit.

    ``surface="plane"``: random periodic Voronoi tilings (:func:`spherevm.init.random_planar_tiling`,
    square box of side sqrt(N), <A> = 1, N >= 8) instead of the sphere's; MSD and Q_s then use the
    unwrapped centroids with each replica's centre-of-mass drift removed instead of its rotation
    (docs/plane.md).

    ``restart``: a spherevm GSD file (a checkpoint, such as an earlier run's ``out``): its last
    frame gives the State and the timestep (so the Philox noise goes on where that run stopped),
    relaxation and equilibration are skipped (``n_cells`` and ``replicas`` are ignored), and the
    production phase runs ``steps`` more steps from there.

    ``initial_state``: a State to start from instead of random tilings (``n_cells``, ``replicas`` and
    ``surface`` are then ignored; relaxation and equilibration still run), for example tilings of
    several sizes joined with :meth:`State.concatenate`: one ensemble steps them all at once, which on
    a GPU costs about what the largest alone costs (small tissues leave the chip idle).
    """
    init.check_surface_spec(surface)
    if steps < 1 or int(steps) != steps:
        raise ValueError(f"steps must be a positive integer, got {steps!r}")
    equilibrate_steps = steps // 10 if equilibrate_steps is None else int(equilibrate_steps)
    sim = Simulation(device=device, seed=seed)
    if restart is not None and initial_state is not None:
        raise ValueError("give restart or initial_state, not both")
    if initial_state is not None:
        if not isinstance(initial_state, State):
            raise TypeError(f"initial_state must be a spherevm State, got {type(initial_state).__name__}")
        sim.state = initial_state
    elif restart is None:
        n_cells, replicas = integer("n_cells", n_cells, minimum=4), integer("replicas", replicas, minimum=1)
        check_run_memory(f"dynamics of {replicas} replica(s) of {n_cells} cells", n_cells * replicas, n_cells,
                         gpu=sim.device.is_gpu)
        sim.state = init.tilings_on(surface, n_cells, [(seed, r) for r in range(replicas)])
    else:
        sim.create_state_from_gsd(restart)
        relax_steps = equilibrate_steps = 0
    sim.operations.forces.append(VertexModel.dimensionless(kr=kr, p0=p0))
    sim.operations.forces.extend(extra_forces)
    if t1:
        sim.operations.updaters.append(T1())
    if relax_steps:
        sim.operations.integrator = FIRE(dt=0.02)
        sim.minimize(force_tol=1e-8, max_steps=relax_steps,
                     progress=None if progress is None else lambda k, d, n: progress("relax", k, relax_steps))
    sim.operations.integrator = Brownian(dt=dt, T=T)
    if equilibrate_steps:
        sim.run(equilibrate_steps, check_every=100, graphs=graphs,
                progress=None if progress is None else lambda i, n: progress("equilibrate", i, n))
    start = sim.timestep
    recorder = analysis.Recorder.log_spaced(steps, points_per_decade, start=start)
    sim.operations.writers.append(recorder)
    if out is not None:
        shots = (start + analysis.log_spaced_times(steps, max(1, frames // 4))).tolist()
        sim.operations.writers.append(GSD(shots, out))
    sim.run(steps, check_every=100, graphs=graphs,
            progress=None if progress is None else lambda i, n: progress("production", i, n))
    traj = analysis.Trajectory.from_recording(recorder, dt=dt)
    traj.times = traj.times - traj.times[0]
    m = analysis.msd(traj)
    q = analysis.self_overlap(traj, b=b)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", analysis.NoRelaxationWarning)
        tau = float(q.tau_alpha())
        tau_r = np.atleast_1d(np.asarray(q.tau_alpha(per_replica=True), dtype=float))
    return DynamicsResult(lag=m.lag, msd=m.value, self_overlap=q.value, msd_per_replica=m.per_replica,
                          self_overlap_per_replica=q.per_replica, tau_alpha=tau, tau_alpha_per_replica=tau_r,
                          simulation=sim, production_start=start)
