"""The paper's finite-temperature protocol: relax, equilibrate, then record the glassy dynamics."""
from __future__ import annotations

import csv
import time
import warnings
from dataclasses import dataclass

import numpy as np

from . import analysis, init, shapes
from .plugins.forces import VertexModel
from .plugins.integrators import FIRE, Brownian
from .plugins.updaters import T1
from .plugins.writers import GSD
from .simulation import Simulation
from .device import weighted_bincount
from .state import State
from .validation import check_run_memory, integer

#: ``stable_dt``'s safety factors c: Brownian ``dt = c / (mu lambda)``, FIRE ``dt_max = c / sqrt(lambda)``
STABILITY = {"brownian": 0.35, "fire": 0.8}
#: glassy_dynamics(dt="auto") refuses a smaller step (the forces are then close to singular)
MIN_AUTO_DT = 1e-4


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
    dt: float = None                #: the Brownian time step used
    production_steps: int = 0       #: production steps run (fewer than asked when stopped early)
    stopped: str = "steps"          #: why production ended: "steps", "relaxed" or "max_seconds"

    def write_csv(self, path):
        """Columns: time, msd, self_overlap (lengths in units of sqrt(<A>))."""
        with open(path, "w", newline="") as f:
            w = csv.writer(f)
            w.writerow(["time", "msd", "self_overlap"])
            for row in zip(self.lag, self.msd, self.self_overlap):
                w.writerow([f"{x:.10g}" for x in row])


def hessian_scale(sim, iterations: int = 30, seed: int = 0, eps: float = 1e-6):
    """Per replica, the largest eigenvalue (in absolute value) of the Hessian of the energy of
    ``sim``'s forces at its State, on the surface: the stiffest mode, which sets the largest stable
    time step.

    Power iteration on Hessian-vector products, each a central difference of the forces,
    ``H v = (F(x - e v) - F(x + e v)) / 2e`` (displacements tangent, points put back on the surface,
    ``e = eps sqrt(<A>)`` for a v of unit norm per replica); the replicas iterate together. It converges
    from below, so the estimate is slightly low (within a few per cent after 30 iterations on tilings
    of 32 to 1,024 cells); ``stable_dt``'s safety factors allow for it. Positions are written in place
    and restored; T1 does not run.

    For the dimensionless vertex model (kP = 1) it is about 17 on relaxed tilings; a ``Bending(B)``
    adds about 9-10 B / R^2 (a neighbour pair is a spring of stiffness ~ B / R^2 on the centres'
    distance, and each vertex moves the normals of three cells), more on irregular cells.

    Parameters
    ----------
    sim : Simulation
        With its State and forces.
    iterations : int
        Power iterations (two force evaluations each).
    seed : int
        Seed of the random start vector.
    eps : float
        The finite-difference step, in units of sqrt(<A>).

    Returns
    -------
    numpy.ndarray (n_replicas,)"""
    iterations = integer("iterations", iterations, minimum=1)
    sim.require_state()
    if not sim.operations.forces:
        raise ValueError("hessian_scale: the simulation has no forces")
    state = sim.state
    xp, con, rep, n = state.device.xp, state.constraint, state.vertex_replica, state.n_replicas
    x0 = state.positions.copy()
    size = con.size(state, rep)
    step = state.device.asarray(eps * np.sqrt(state.mean_cell_area))[rep][:, None]

    def normalised(v):
        norm = xp.sqrt(weighted_bincount(rep, weights=(v * v).sum(axis=1), minlength=n))
        return v / xp.where(norm > 0, norm, 1.0)[rep][:, None], norm

    v, _ = normalised(con.project_tangent(x0, state.device.asarray(np.random.default_rng(seed).normal(size=x0.shape))))
    try:
        for _ in range(iterations):
            forces = []
            for sign in (1.0, -1.0):
                state.positions[...] = con.project_normal(x0 + sign * step * v, size)   # in place: graphs keep it
                sim.state_changed()
                forces.append(sim.compute_forces()[0].copy())
            v, scale = normalised(con.project_tangent(x0, (forces[1] - forces[0]) / (2 * step)))
    finally:
        state.positions[...] = x0
        sim.state_changed()
    return state.device.to_numpy(scale)


def stable_dt(sim, method: str = "brownian", mu: float = 1.0, safety: float = None, iterations: int = 30):
    """Per replica, a time step that keeps ``method`` stable on ``sim``'s forces at its State, from the
    stiffest mode ``lambda`` (:func:`hessian_scale`).

    * ``"brownian"`` (overdamped Euler, ``dx = mu dt F + noise``): a mode of stiffness ``lambda`` is
      stable for ``mu dt lambda < 2``; ``dt = c / (mu lambda)`` with ``c = 0.35``
      (:data:`STABILITY`), which gives the bending study's dt = 0.02 on relaxed B = 0 tilings (lambda
      about 17); dt = 0.05 there (``mu dt lambda`` = 0.85) had exploding steps at T = 0.04, as thermal
      states are stiffer than relaxed ones.
    * ``"fire"`` (unit mass, semi-implicit Euler): stable for ``dt^2 lambda < 4``; the result is FIRE's
      ``dt_max = c / sqrt(lambda)`` with ``c = 0.8``, about 0.19 at lambda = 17 (FIRE's usual 0.2).

    Both fall as 1/B (Brownian) and 1/sqrt(B) (FIRE) once a ``Bending(B)`` term dominates.

    Parameters
    ----------
    sim : Simulation
    method : {"brownian", "fire"}
    mu : float
        The mobility (Brownian).
    safety : float, optional
        The factor c (default :data:`STABILITY` of the method).
    iterations : int
        Power iterations of :func:`hessian_scale`.

    Returns
    -------
    numpy.ndarray (n_replicas,)"""
    if method not in STABILITY:
        raise ValueError(f"stable_dt: method must be 'brownian' or 'fire', got {method!r}")
    c = STABILITY[method] if safety is None else float(safety)
    if not c > 0 or not mu > 0:
        raise ValueError(f"stable_dt: safety and mu must be > 0, got safety={safety!r}, mu={mu!r}")
    lam = np.maximum(hessian_scale(sim, iterations), 1e-300)
    return c / (mu * lam) if method == "brownian" else c / np.sqrt(lam)


def inherent_states(n_cells, replicas, p0, kr, steps=5000, seed=0, device="auto", dt=0.02) -> State:
    """Random tilings relaxed by FIRE + T1 under the vertex model alone (at most ``steps`` iterations):
    the start of a run with extra forces that the raw tilings cannot take (a ``Bending`` term makes
    FIRE's first steps from a random Voronoi tiling's smallest cells explode).

    Parameters
    ----------
    n_cells, replicas, seed : int
        As :func:`spherevm.init.random_tiling`.
    p0, kr : float
        The dimensionless vertex model.
    steps : int
        FIRE iterations at most (force tolerance 1e-8).
    device : str
    dt : float
        FIRE's initial step (dt_max ten times it).

    Returns
    -------
    State"""
    sim = Simulation(device=device, seed=seed)
    sim.state = init.random_tiling(n_cells, replicas=replicas, seed=seed)
    sim.operations.forces.append(VertexModel.dimensionless(kr=kr, p0=p0))
    sim.operations.updaters.append(T1())
    sim.operations.integrator = FIRE(dt=dt)
    sim.minimize(force_tol=1e-8, max_steps=steps)
    return sim.state


def glassy_dynamics(n_cells, p0, kr, T, dt=0.01, steps=10_000, replicas=1, seed=0, device="auto",
                    relax_steps=10_000, equilibrate_steps=None, b=0.5, points_per_decade=10, out=None,
                    frames=50, t1=True, progress=None, surface: str = "sphere",
                    extra_forces=(), restart=None, initial_state=None, graphs=None, until_relaxed: bool = False,
                    max_seconds: float = None, max_time: float = None) -> DynamicsResult:
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
    (docs/plane.md). An implicit surface's spec (``"torus:R=3,r=1"``): its random tilings
    (:func:`spherevm.init.tilings_on`, CPU), displacements measured as chords (docs/surfaces.md).

    ``restart``: a spherevm GSD file (a checkpoint, such as an earlier run's ``out``): its last
    frame gives the State and the timestep (so the Philox noise goes on where that run stopped),
    relaxation and equilibration are skipped (``n_cells`` and ``replicas`` are ignored), and the
    production phase runs ``steps`` more steps from there.

    ``initial_state``: a State to start from instead of random tilings (``n_cells``, ``replicas`` and
    ``surface`` are then ignored; relaxation and equilibration still run), for example tilings of
    several sizes joined with :meth:`State.concatenate`: one ensemble steps them all at once, which on
    a GPU costs about what the largest alone costs (small tissues leave the chip idle).

    ``dt="auto"``: steps from the stiffest mode of the forces (:func:`stable_dt`, the smallest over the
    replicas): FIRE's ``dt_max`` (at most its usual 0.2, ``dt`` a tenth of it) from the starting
    state, the Brownian step from the relaxed one (about 0.02 without bending; stiff ``Bending``
    terms get proportionally smaller steps). The result's ``dt`` is the step used. A step below
    :data:`MIN_AUTO_DT` raises FloatingPointError naming the smallest cell (such stiffness comes from
    a cell flattening to zero area, not from a stiff but healthy tissue).

    ``until_relaxed``: production runs in stretches (about ``steps / 40`` each, at least 1,000) and
    stops as soon as every replica's Q_s has fallen to 1/e; ``max_seconds``: it stops after the
    stretch in which that many wall seconds (counted from the call) have passed. ``steps`` is then
    the cap; the result's ``production_steps`` and ``stopped`` ("steps", "relaxed", "max_seconds")
    say what ran. The lags end where production ended. ``max_time``: the cap in time units instead
    (``steps = ceil(max_time / dt)``, with the step ``dt`` resolves to; equilibration a tenth of it
    unless given).
    """
    if restart is None and initial_state is None:        # else the surface is the file's or the State's
        init.check_surface_spec(surface)
    started = time.perf_counter()
    if steps < 1 or int(steps) != steps:
        raise ValueError(f"steps must be a positive integer, got {steps!r}")
    if isinstance(dt, str) and dt != "auto":
        raise ValueError(f"dt must be a positive number or 'auto', got {dt!r}")
    if max_seconds is not None and not max_seconds > 0:
        raise ValueError(f"max_seconds must be > 0 or None, got {max_seconds!r}")
    if max_time is not None and not max_time > 0:
        raise ValueError(f"max_time must be > 0 or None, got {max_time!r}")
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
        relax_steps, equilibrate_steps = 0, 0
    sim.operations.forces.append(VertexModel.dimensionless(kr=kr, p0=p0))
    sim.operations.forces.extend(extra_forces)
    if t1:
        sim.operations.updaters.append(T1())
    if relax_steps:
        dt_max = min(0.2, float(stable_dt(sim, "fire").min())) if dt == "auto" else 0.2
        sim.operations.integrator = FIRE(dt=dt_max / 10, dt_max=dt_max)
        sim.minimize(force_tol=1e-8, max_steps=relax_steps,
                     progress=None if progress is None else lambda k, d, n: progress("relax", k, relax_steps))
    if dt == "auto":
        dt = float(stable_dt(sim, "brownian").min())
        if dt < MIN_AUTO_DT:
            area = shapes.cell_shapes(sim.state)[0] / sim.state.mean_cell_area[sim.state.cell_replica_np()]
            raise FloatingPointError(f"dt='auto': the stable Brownian step is {dt:.3g}, below {MIN_AUTO_DT:g}: the "
                                     f"forces are close to singular (smallest cell area {area.min():.3g} <A>; a cell "
                                     "flattening under a stiff Bending term?)")
    if max_time is not None:
        steps = int(np.ceil(max_time / dt))
    equilibrate_steps = steps // 10 if equilibrate_steps is None else int(equilibrate_steps)
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
    stretch = steps if not (until_relaxed or max_seconds) else max(1000, -(-steps // 4000) * 100)
    done, stopped = 0, "steps"
    while done < steps:
        n = min(stretch, steps - done)
        sim.run(n, check_every=100, graphs=graphs,
                progress=None if progress is None else lambda i, _, d=done: progress("production", d + i, steps))
        done += n
        if done < steps and until_relaxed and np.all(np.isfinite(_overlap(recorder, dt, b)[2])):
            stopped = "relaxed"
        elif done < steps and max_seconds is not None and time.perf_counter() - started > max_seconds:
            stopped = "max_seconds"
        if stopped != "steps":
            break
    traj, q, tau_r = _overlap(recorder, dt, b)
    m = analysis.msd(traj)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", analysis.NoRelaxationWarning)
        tau = float(q.tau_alpha())
    return DynamicsResult(lag=m.lag, msd=m.value, self_overlap=q.value, msd_per_replica=m.per_replica,
                          self_overlap_per_replica=q.per_replica, tau_alpha=tau, tau_alpha_per_replica=tau_r,
                          simulation=sim, production_start=start, dt=dt, production_steps=done, stopped=stopped)


def _overlap(recorder, dt, b):
    """The Trajectory of what ``recorder`` holds (lags from its first frame), its Q_s and tau_alpha per
    replica (NaN: not relaxed)."""
    traj = analysis.Trajectory.from_recording(recorder, dt=dt)
    traj.times = traj.times - traj.times[0]
    q = analysis.self_overlap(traj, b=b)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", analysis.NoRelaxationWarning)
        tau_r = np.atleast_1d(np.asarray(q.tau_alpha(per_replica=True), dtype=float))
    return traj, q, tau_r
