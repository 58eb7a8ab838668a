"""A parameter changed after attach takes effect at the next step, on both devices.

The rule tested: setting ``op.name = value`` between two runs gives, bit for bit, the run that a
fresh Simulation makes when it restarts from a checkpoint written at that step with ``op`` built
with ``name=value`` (the documented exceptions: FIRE's ``dt`` and ``dt_max`` also set the running
replicas' current step, as HOOMD's FIRE does). Each case also checks that the change mattered
(the run differs from one that kept the old value), unless the case says why it cannot show here.
"""
import inspect

import numpy as np
import pytest

import spherevm as svm
from spherevm.plugins.forces import Bending, VertexModel
from spherevm.plugins.integrators import FIRE, Active, Brownian
from spherevm.plugins.updaters import T1, Division, Extrusion, RadiusSchedule
from spherevm.plugins.writers import GSD

from conftest import to_numpy

# A scenario: how to build the operations (keyword overrides per class name) and what to run.
DYNAMICS = dict(forces=lambda kw: [VertexModel.dimensionless(**{"kr": 1.0, "p0": 3.8, **kw.get("VertexModel", {})})],
                updaters=lambda kw: [T1(**{"threshold": 0.1, "new_length": 0.3, **kw.get("T1", {})})],
                integrator=lambda kw: Brownian(**{"dt": 0.01, "T": 0.05, **kw.get("Brownian", {})}))
DIMENSIONAL = dict(DYNAMICS, forces=lambda kw: [VertexModel(**{"kA": 1.0, "kP": 1.0, "A0": 1.0, "P0": 3.8,
                                                             **kw.get("VertexModel", {})})])
BENDING = dict(DYNAMICS, forces=lambda kw: [VertexModel.dimensionless(kr=1.0, p0=3.8),
                                           Bending(**{"B": 0.5, **kw.get("Bending", {})})])
ACTIVE = dict(DYNAMICS, integrator=lambda kw: Active(**{"dt": 0.01, "v0": 0.5, "Dr": 1.0, "T": 0.01,
                                                        **kw.get("Active", {})}))
GROWTH = dict(DYNAMICS, updaters=lambda kw: [
    Division(**{"rule": "rate", "rate": 2.0, "area_threshold": 1.4, "max_cells": 60, **kw.get("Division", {})}),
    Extrusion(**{"area_threshold": 0.5, **kw.get("Extrusion", {})}),
    RadiusSchedule(**{"mode": "constant_area", **kw.get("RadiusSchedule", {})}),
    T1(threshold=0.1, new_length=0.3)])
MINIMIZE = dict(forces=DYNAMICS["forces"], updaters=lambda kw: [T1(**{"threshold": 0.1, "new_length": 0.3,
                                                                      **kw.get("T1", {})})],
                integrator=lambda kw: FIRE(**{"dt": 0.05, "check_every": 5, "force_tol": 1e-14,
                                              **kw.get("FIRE", {})}), minimize=True)
#: a slow start, whose replicas' steps grow (dt_max then caps them)
SLOW_START = dict(MINIMIZE, integrator=lambda kw: FIRE(**{"dt": 0.01, "check_every": 5, "force_tol": 1e-14,
                                                         **kw.get("FIRE", {})}))

# (scenario, class, parameter, new value, why the change cannot show here or None)
CASES = [
    (DYNAMICS, VertexModel, "kr", 0.2, None), (DYNAMICS, VertexModel, "p0", 3.6, None),
    (DYNAMICS, VertexModel, "a0", 0.8, None), (DYNAMICS, VertexModel, "kP", 2.0, None),
    (DIMENSIONAL, VertexModel, "kA", 2.0, None), (DIMENSIONAL, VertexModel, "A0", 0.8, None),
    (DIMENSIONAL, VertexModel, "P0", 3.6, None),
    (BENDING, Bending, "B", 3.0, None),
    (DYNAMICS, T1, "threshold", 0.25, None), (DYNAMICS, T1, "new_length", 0.6, None),
    (DYNAMICS, T1, "length_factor", 3.0, None), (DYNAMICS, T1, "preset", "reference", None),
    (DYNAMICS, T1, "trigger", 2, None), (DYNAMICS, T1, "untangle", True, None),
    (DYNAMICS, T1, "count_flip_backs", True, "bookkeeping only: the flips are the same"),
    (MINIMIZE, T1, "max_flip_backs", 1, "halts only a replica whose cells re-join"),
    (MINIMIZE, T1, "reset_velocities", False, None),
    (DYNAMICS, Brownian, "dt", 0.02, None), (DYNAMICS, Brownian, "T", 0.1, None),
    (DYNAMICS, Brownian, "mu", 0.5, None),
    (DYNAMICS, Brownian, "max_step", 0.3, "a guard: moves are below both bounds"),
    (ACTIVE, Active, "v0", 1.5, None), (ACTIVE, Active, "Dr", 3.0, None),
    (GROWTH, Division, "area_threshold", 1.0, "read by rule='area' only"),
    (GROWTH, Division, "max_cells", 33, None), (GROWTH, Division, "rule", "area", None),
    (GROWTH, Division, "rate", 8.0, None), (GROWTH, Division, "axis", "random", None),
    (GROWTH, Division, "dt", 0.5, None),
    (GROWTH, Extrusion, "area_threshold", 0.95, None), (GROWTH, Extrusion, "rule", "area", "unchanged"),
    (GROWTH, RadiusSchedule, "area", 1.3, None), (GROWTH, RadiusSchedule, "mode", "fixed", None),
    (MINIMIZE, FIRE, "dt", 0.02, None), (SLOW_START, FIRE, "dt_max", 0.015, None),
    (MINIMIZE, FIRE, "n_min", 1, None), (MINIMIZE, FIRE, "f_inc", 1.5, None),
    (MINIMIZE, FIRE, "f_dec", 0.2, None), (MINIMIZE, FIRE, "alpha_start", 0.3, None),
    (MINIMIZE, FIRE, "f_alpha", 0.5, None),
    (MINIMIZE, FIRE, "max_step", 0.5, "a guard: moves are below both bounds"),
    (MINIMIZE, FIRE, "force_tol", 10.0, None), (MINIMIZE, FIRE, "energy_tol", 10.0, None),
    (MINIMIZE, FIRE, "check_every", 7, "no replica converges: checks only read"),
]
STEPS = 12


def _operation(sim, cls):
    ops = [*sim.operations.forces, *sim.operations.updaters, sim.operations.integrator]
    return next(op for op in ops if type(op) is cls)


def _simulation(scenario, device, overrides=None):
    overrides = overrides or {}
    sim = svm.Simulation(device=device, seed=5)
    sim.state = svm.init.random_tiling(32, replicas=2, seed=3)
    sim.operations.forces.extend(scenario["forces"](overrides))
    sim.operations.updaters.extend(scenario["updaters"](overrides))
    sim.operations.integrator = scenario["integrator"](overrides)
    return sim


def _advance(sim, scenario, resume):
    if scenario.get("minimize"):
        sim.minimize(max_steps=STEPS, resume=resume)
    else:
        sim.run(STEPS)


def _fingerprint(sim):
    state = sim.state
    out = [to_numpy(state.positions).tobytes(), to_numpy(state.cell_vertices).tobytes(), sim.timestep]
    for op in sim.operations:
        out.extend(np.asarray(v).tobytes() for v in op.state_to_save().values())
    return out


def _changed_run(scenario, device, cls, name, value, tmp_path):
    """Run, write a checkpoint, set the parameter, run on: the fingerprint, and the checkpoint's path."""
    path = tmp_path / "start.gsd"
    sim = _simulation(scenario, device)
    sim.operations.writers.append(GSD(10**6, path))
    _advance(sim, scenario, resume=False)
    sim.operations.writers.clear()
    setattr(_operation(sim, cls), name, value)
    _advance(sim, scenario, resume=True)
    return _fingerprint(sim), path


def _restarted_run(scenario, device, path, overrides, after_restore=None):
    sim = _simulation(scenario, device, overrides)
    sim.create_state_from_gsd(path)
    if after_restore is not None:
        after_restore(sim)
    _advance(sim, scenario, resume=True)
    return _fingerprint(sim)


def _fire_step_now(name, value):
    """FIRE's documented extra: a new dt is every running replica's current step, a new dt_max caps it."""
    def apply(sim):
        fire = sim.operations.integrator
        xp = sim.state.device.xp
        if name == "dt":
            fire.replica_dt = xp.where(fire.active_on_device(), value, fire.replica_dt)
        fire.replica_dt = xp.minimum(fire.replica_dt, fire.dt_max)
    return apply


@pytest.mark.parametrize("scenario, cls, name, value, unseen", CASES,
                         ids=[f"{c.__name__}.{n}" + ("-dimensional" if s is DIMENSIONAL else "")
                              for s, c, n, _, _ in CASES])
def test_a_parameter_change_takes_effect_at_the_next_step(device, tmp_path, scenario, cls, name, value, unseen):
    changed, path = _changed_run(scenario, device, cls, name, value, tmp_path)
    kwarg = {"mode": "directors"}.get(name, name) if cls is Active else name
    extra = _fire_step_now(name, value) if cls is FIRE and name in ("dt", "dt_max") else None
    fresh = _restarted_run(scenario, device, path, {cls.__name__: {kwarg: value}}, extra)
    assert changed == fresh, f"{cls.__name__}.{name} = {value!r} is not the run restarted with it"
    kept = _restarted_run(scenario, device, path, {})
    if unseen is None:
        assert changed != kept, f"{cls.__name__}.{name} = {value!r} changed nothing"


def test_every_parameter_of_every_built_in_is_covered():
    """A new parameter needs a case above; every constructor keyword is a parameter (or named here)."""
    aliases = {(Active, "directors"): "mode", (VertexModel, "kA"): "kA"}
    covered = {(c, n) for _, c, n, _, _ in CASES} | {(Active, "mode")}   # fixed: its own test
    built_ins = (VertexModel, Bending, T1, Brownian, Active, FIRE, Division, Extrusion, RadiusSchedule)
    for cls in built_ins:
        for kw in inspect.signature(cls.__init__).parameters:
            if kw != "self":
                assert aliases.get((cls, kw), kw) in cls.parameter_names(), f"{cls.__name__}({kw}=) is no Parameter"
        own = [n for n in cls.parameter_names() if n != "trigger"]
        inherited = {n for base in cls.__mro__[1:] if base in built_ins for n in base.parameter_names()}
        missing = [n for n in own if (cls, n) not in covered and n not in inherited]
        assert not missing, f"no case changes {cls.__name__}.{missing}"


def test_a_parameter_is_checked_when_set_later_too():
    bd = Brownian(dt=0.01)
    with pytest.raises(ValueError, match="dt must be"):
        bd.dt = -1
    assert bd.dt == 0.01
    fire = FIRE(dt=0.02)
    with pytest.raises(ValueError, match="dt_max must be >= dt"):
        fire.dt_max = 0.01
    assert fire.dt_max == pytest.approx(0.2)
    fire.dt = 0.05
    assert fire.dt_max == pytest.approx(0.5), "a dt_max left to its default follows dt"
    t1 = T1(preset="reference")
    t1.new_length = 0.2
    assert (t1.length_factor, t1.preset) == (None, None)
    with pytest.raises(ValueError, match="new_length must be"):
        t1.new_length = 0.01


def test_a_parameter_of_the_other_form_is_refused():
    with pytest.raises(ValueError, match="dimensionless: set its kr, p0, a0"):
        VertexModel.dimensionless(p0=3.8).P0 = 4.0
    with pytest.raises(ValueError, match="dimensional: set its kA, kP, A0 and P0"):
        VertexModel(P0=3.8).p0 = 4.0


def test_a_fixed_parameter_is_refused_once_attached():
    sim = _simulation(ACTIVE, "cpu")
    with pytest.raises(AttributeError, match="Active.mode cannot change once the operation is attached"):
        sim.operations.integrator.mode = "vertex"


def test_a_per_replica_value_of_the_wrong_length_is_refused_when_set(device):
    sim = _simulation(BENDING, device)
    with pytest.raises(ValueError, match="per-replica B has length 3"):
        sim.operations.forces[1].B = [1.0, 2.0, 3.0]
    with pytest.raises(ValueError, match="T has 3 values"):
        sim.operations.integrator.T = [0.1, 0.2, 0.3]
    sim.run(2)


@pytest.mark.parametrize("name, value", [("T", 0.2), ("dt", 0.02)])
def test_a_change_reaches_graphs_and_fused_steps(device, tmp_path, name, value):
    """Long enough runs for CUDA graphs and the fused steps on the GPU (step by step on the CPU)."""
    global STEPS
    saved, STEPS = STEPS, 96
    try:
        changed, path = _changed_run(DYNAMICS, device, Brownian, name, value, tmp_path)
        fresh = _restarted_run(DYNAMICS, device, path, {"Brownian": {name: value}})
    finally:
        STEPS = saved
    assert changed == fresh
