"""Checks for plugin authors: is a Force's output minus the surface gradient of its energy?

``check_force(force, state)`` runs four checks and returns a :class:`ForceCheck` report;
``check_force(...).assert_ok()`` (or :func:`assert_force_ok`) raises AssertionError with the report,
for use in pytest::

    from spherevm.testing import assert_force_ok
    assert_force_ok(LineTension(0.7), svm.init.random_tiling(40, replicas=3, seed=1))

1. **directional derivatives**: at sampled vertices of every replica, the derivative of the energy
   along a random unit tangent direction ``t`` (the vertex moved along the surface, through
   ``constraint.geodesic_offset``) equals ``-F . t``. Central differences with one Richardson step,
   ``D = (4 D(h/2) - D(h)) / 3``, error O(h^4): with ``h = 1e-3 sqrt(<A>)`` the
   truncation error is ~1e-12 relative and rounding ``~eps |E| / h`` stays small, so the default
   relative tolerance ``rtol = 1e-6`` leaves a wide margin while a force off by 1% fails by 10^4;
2. **tangency**: the normal part of every force is at most ``tangent_tol`` of the force scale;
3. **per-cell energies** (when ``cell_energy`` is given): they sum to each replica's energy;
4. **replica independence**: moving a vertex of one replica leaves the other replicas' energies
   unchanged (so one vertex per replica is moved at once in check 1).

A State on the GPU is checked where it lives (the force computed there, differences of energies
computed there); with ``compare_cpu=True`` (default) the forces are also compared with those of the
CPU copy. The State's positions are restored afterwards.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .state import State
from .validation import integer

EPS = np.finfo(np.float64).eps
#: the most samples :func:`check_force` takes: each costs four force evaluations of the whole State
#: (about 1.2 ms on a small tissue on one core, 19 ms at 10,000 cells), so 10,000 take 10 s to minutes
MAX_SAMPLES = 10_000


@dataclass
class ForceCheck:
    """The outcome of :func:`check_force`. ``ok`` is True when every check passed; ``failures``
    lists one line per failed check; the ``worst_*`` fields name where each check came closest to
    (or went furthest past) its tolerance."""

    force: str
    n_replicas: int
    n_samples: int
    rtol: float
    worst_derivative: dict = field(default_factory=dict)
    worst_tangency: dict = field(default_factory=dict)
    cell_energy_error: float | None = None
    replica_leak: float | None = None
    cpu_difference: float | None = None
    failures: list = field(default_factory=list)

    @property
    def ok(self) -> bool:
        return not self.failures

    def __bool__(self):
        return self.ok

    def __str__(self):
        d, t = self.worst_derivative, self.worst_tangency
        lines = [f"check_force({self.force}): {'ok' if self.ok else 'FAILED'} "
                 f"({self.n_samples} directional derivatives over {self.n_replicas} replica(s), rtol {self.rtol:g})"]
        if d:
            lines.append(f"  worst derivative: vertex {d['vertex']} (replica {d['replica']}, local vertex "
                         f"{d['local_vertex']}): finite difference {d['finite_difference']:.12g}, -F.t "
                         f"{d['analytic']:.12g}, error {d['error']:.3g} = {d['relative']:.3g} of the scale "
                         f"{d['scale']:.3g}")
        if t:
            lines.append(f"  worst tangency: vertex {t['vertex']} (replica {t['replica']}): normal part "
                         f"{t['normal']:.3g}, {t['relative']:.3g} of the force scale")
        if self.cell_energy_error is not None:
            lines.append(f"  per-cell energies vs replica energies: relative error {self.cell_energy_error:.3g}")
        if self.replica_leak is not None:
            lines.append(f"  other replicas' energies after moving one replica: change {self.replica_leak:.3g}")
        if self.cpu_difference is not None:
            lines.append(f"  GPU vs CPU forces: relative difference {self.cpu_difference:.3g}")
        lines += [f"  FAILED: {f}" for f in self.failures]
        return "\n".join(lines)

    def assert_ok(self):
        """Raise AssertionError with the whole report unless every check passed; return self."""
        if not self.ok:
            raise AssertionError(str(self))
        return self


def _np(state, a):
    return np.asarray(state.device.to_numpy(a), dtype=np.float64)


def _result(force, state):
    r = force.compute(state)
    cell = None if r.cell_energy is None else _np(state, r.cell_energy)
    return _np(state, r.forces), _np(state, r.energy).reshape(-1), cell


def check_force(force, state, *, samples: int = 8, rtol: float = 1e-6, h: float = 1e-3,
                tangent_tol: float = 1e-10, cell_rtol: float = 1e-10, seed: int = 0,
                compare_cpu: bool = True) -> ForceCheck:
    """Check ``force`` on ``state``: directional derivatives, tangency, per-cell energies, replica
    independence (the module docstring says how).

    Check at unrelaxed states (random tilings are): near a minimum both sides are nearly 0 and a
    wrong force is hard to see, and a relaxed fluid tissue has vanishing edges where the energy is
    not differentiable, which the check reports.

    Parameters
    ----------
    force : Force
    state : State
        Any device, any number of replicas.
    samples : int
        Vertices per replica, each with its own random unit tangent direction, in
        ``[1, MAX_SAMPLES]`` (10,000: each sample costs four force evaluations).
    rtol : float
        The error of a derivative is compared with ``rtol`` times ``|F_v| + rms |F| + |E''| h``
        (the second difference keeps the test meaningful where forces vanish), plus the rounding
        floor ``100 eps |E_r| / h``.
    h : float
        The step, in units of each replica's cell size ``sqrt(<A>)``.
    tangent_tol : float
        Bound on the normal part of each force relative to ``|F_v| + rms |F|``.
    cell_rtol : float
        Bound on the sum of per-cell energies against each replica's energy, relative to the sum of
        their magnitudes.
    seed : int
    compare_cpu : bool
        On the GPU, also compare the forces with those of the CPU copy.

    Returns
    -------
    ForceCheck
        ``ok``, ``failures`` (one line per failed check) and where each check came closest."""
    if not callable(getattr(force, "compute", None)):
        raise TypeError(f"force must be a spherevm Force (an object with compute(state)), got {force!r}")
    if not isinstance(state, State):
        raise TypeError(f"state must be a spherevm.State, got {type(state).__name__}")
    samples = integer("samples", samples, minimum=1, maximum=MAX_SAMPLES)
    if not rtol > 0 or not h > 0:
        raise ValueError(f"rtol and h must be positive, got rtol={rtol}, h={h}")
    xp = state.device.xp
    constraint = state.constraint
    nr = state.n_replicas
    vrep = state.vertex_replica_np()
    vstart = np.concatenate([[0], np.cumsum(np.bincount(vrep, minlength=nr))])
    x0 = state.positions.copy()
    forces, energy, cell_energy = _result(force, state)
    report = ForceCheck(force=repr(force), n_replicas=nr, n_samples=samples * nr, rtol=rtol)

    # force scale per replica: rms |F| (a minimised state still has a finite scale through the floor)
    fnorm = np.linalg.norm(forces, axis=1)
    rms = np.sqrt(np.bincount(vrep, weights=fnorm ** 2, minlength=nr) / np.maximum(np.diff(vstart), 1))
    size_np = constraint.size_np(state)
    n_cells = np.bincount(state.cell_replica_np(), minlength=nr)
    scale = np.sqrt(np.asarray(constraint.total_area_np(size_np), dtype=np.float64).reshape(nr) / n_cells)

    try:
        # 2. tangency
        normal = _np(state, constraint.normal(x0, constraint.size(state, state.vertex_replica)))
        radial = np.abs((forces * normal).sum(axis=1))
        rel = radial / np.maximum(fnorm + rms[vrep], np.finfo(float).tiny)
        i = int(np.argmax(rel))
        report.worst_tangency = dict(vertex=i, replica=int(vrep[i]), normal=float(radial[i]), relative=float(rel[i]))
        if rel[i] > tangent_tol:
            report.failures.append(f"force on vertex {i} (replica {vrep[i]}) has a normal part {radial[i]:.3g}, "
                                   f"{rel[i]:.3g} of the force scale (tangent_tol {tangent_tol:g})")

        # 3. per-cell energies
        if cell_energy is not None:
            if cell_energy.shape != (state.n_cells,):
                report.failures.append(f"cell_energy has shape {cell_energy.shape}, expected ({state.n_cells},)")
            else:
                crep = state.cell_replica_np()
                total = np.bincount(crep, weights=cell_energy, minlength=nr)
                mag = np.bincount(crep, weights=np.abs(cell_energy), minlength=nr) + np.abs(energy)
                err = np.abs(total - energy) / np.maximum(mag, np.finfo(float).tiny)
                report.cell_energy_error = float(err.max())
                if err.max() > cell_rtol:
                    r = int(np.argmax(err))
                    report.failures.append(f"per-cell energies of replica {r} sum to {total[r]:.12g}, its energy is "
                                           f"{energy[r]:.12g} (relative error {err[r]:.3g} > {cell_rtol:g})")

        # 1. directional derivatives, one vertex per replica at a time
        rng = np.random.default_rng(seed)
        worst = None
        size_v = constraint.size(state, state.vertex_replica)
        for _ in range(samples):
            local = np.array([rng.integers(vstart[r + 1] - vstart[r]) for r in range(nr)])
            verts = vstart[:-1] + local
            vd = xp.asarray(verts)
            t = _np(state, constraint.project_tangent(x0[vd], xp.asarray(rng.standard_normal((nr, 3))), size_v[vd]))
            t /= np.linalg.norm(t, axis=1)[:, None]
            td = xp.asarray(t)

            def energy_at(s):
                x = x0.copy()
                x[vd] = constraint.geodesic_offset(x0[vd], td, xp.asarray(s * scale), size_v[vd])
                state.positions = x
                return _np(state, force.compute(state).energy).reshape(-1)

            e_plus, e_minus = energy_at(h), energy_at(-h)
            d1 = (e_plus - e_minus) / (2 * h * scale)
            d2 = (energy_at(h / 2) - energy_at(-h / 2)) / (h * scale)
            fd = (4 * d2 - d1) / 3
            analytic = -(forces[verts] * t).sum(axis=1)
            floor = 100 * EPS * np.abs(energy) / (h * scale)
            curvature = np.abs(e_plus + e_minus - 2 * energy) / (h * scale)     # ~ |E''| h sqrt(<A>)
            tol_scale = fnorm[verts] + rms + curvature
            err = np.abs(fd - analytic)
            relative = err / np.maximum(tol_scale, np.finfo(float).tiny)
            bad = err > rtol * tol_scale + floor
            for r in range(nr):
                entry = dict(vertex=int(verts[r]), replica=r, local_vertex=int(local[r]), finite_difference=float(fd[r]),
                             analytic=float(analytic[r]), error=float(err[r]), relative=float(relative[r]),
                             scale=float(tol_scale[r]), bad=bool(bad[r]))
                if worst is None or (entry["bad"], entry["relative"]) > (worst["bad"], worst["relative"]):
                    worst = entry
        report.worst_derivative = worst
        if worst["bad"]:
            report.failures.append(f"energy derivative along a tangent direction at vertex {worst['vertex']} "
                                   f"(replica {worst['replica']}) is {worst['finite_difference']:.12g}, but -F.t is "
                                   f"{worst['analytic']:.12g} (relative error {worst['relative']:.3g} > rtol {rtol:g})")

        # 4. replica independence
        if nr > 1:
            x = x0.copy()
            v = xp.asarray([0])
            t = constraint.project_tangent(x0[v], xp.asarray(rng.standard_normal((1, 3))), size_v[v])
            t = t / xp.sqrt((t * t).sum(axis=1))[:, None]
            x[v] = constraint.geodesic_offset(x0[v], t, xp.asarray([0.1 * scale[0]]), size_v[v])
            state.positions = x
            moved = _np(state, force.compute(state).energy).reshape(-1)
            leak = np.abs(moved[1:] - energy[1:]) / np.maximum(np.abs(energy[1:]), 1.0)
            report.replica_leak = float(leak.max())
            if leak.max() > 1e-12:
                r = int(np.argmax(leak)) + 1
                report.failures.append(f"moving vertex 0 (replica 0) changed the energy of replica {r} by "
                                       f"{moved[r] - energy[r]:.3g}: replicas must be independent")
    finally:
        state.positions = x0

    if compare_cpu and state.device.is_gpu:
        cpu_forces, _, _ = _result(force, state.to("cpu"))
        diff = np.abs(cpu_forces - forces).max() / max(np.abs(cpu_forces).max(), np.finfo(float).tiny)
        report.cpu_difference = float(diff)
        if diff > 1e-9:
            report.failures.append(f"GPU and CPU forces differ by {diff:.3g} (relative to the largest force)")
    return report


def assert_force_ok(force, state, **options) -> ForceCheck:
    """:func:`check_force` that raises AssertionError with the report when a check fails.

    Parameters
    ----------
    force, state, **options
        As in :func:`check_force`.

    Returns
    -------
    ForceCheck"""
    return check_force(force, state, **options).assert_ok()
