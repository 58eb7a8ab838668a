"""Tests that kill mutants of spherevm/plugins/updaters/t1.py that survived the existing tests.

Found with ``python3 benchmarks/mutate.py spherevm/plugins/updaters/t1.py ...`` (docs/testing.md,
"Mutation testing"): documented defaults, the closed ends of the parameter ranges, the flip-back
bookkeeping and the halting threshold, re-keying of cell pairs for narrowing.
"""
import inspect
from types import SimpleNamespace

import numpy as np
import pytest

import spherevm as svm
from spherevm.plugins.updaters import T1
from spherevm.plugins.updaters import t1 as t1_module


def test_documented_defaults_and_preset():
    sig = inspect.signature(T1)
    defaults = {k: p.default for k, p in sig.parameters.items()}
    assert defaults == dict(threshold=0.04, new_length=0.12, length_factor=None, preset=None, trigger=1,
                            reset_velocities=True, max_flip_backs=100, count_flip_backs=None)
    t = T1()
    assert (t.threshold, t.new_length, t.length_factor, t.max_flip_backs, t.reset_velocities) == \
        (0.04, 0.12, None, 100, True)
    assert t1_module.PRESETS["reference"] == dict(threshold=0.1, new_length=None, length_factor=2.0)
    r = T1(preset="reference")
    assert (r.threshold, r.new_length, r.length_factor) == (0.1, None, 2.0)
    assert repr(r).startswith("T1(threshold=0.1, length_factor=2.0, trigger=")
    assert repr(t).startswith("T1(threshold=0.04, new_length=0.12, trigger=")
    assert T1.halt_reason == "t1_oscillation"


def test_closed_ends_of_the_parameter_ranges():
    with pytest.raises(ValueError, match="length_factor must be > 1"):
        T1(length_factor=1.0)
    assert T1(length_factor=1.0000001).length_factor == 1.0000001
    with pytest.raises(ValueError, match="new_length must be finite and > threshold"):
        T1(threshold=0.05, new_length=0.05)
    assert T1(threshold=0.05, new_length=0.0500001).new_length == 0.0500001
    assert T1(max_flip_backs=1).max_flip_backs == 1
    with pytest.raises(ValueError, match="give new_length"):
        T1(new_length=None)
    assert T1(reset_velocities=0).reset_velocities is False


def _attached(n_cells=16, replicas=2, **kw):
    sim = svm.Simulation(device="cpu")
    sim.state = svm.init.random_tiling(n_cells, replicas=replicas, seed=1)
    t = T1(**kw)
    sim.operations.updaters.append(t)
    sim.operations.forces.append(svm.plugins.forces.VertexModel.dimensionless(kr=1.0, p0=3.8))
    sim.operations.integrator = svm.plugins.integrators.FIRE(dt=0.01)
    sim.run(0)
    return sim, t


def test_halted_exactly_at_max_flip_backs():
    sim, t = _attached(max_flip_backs=5)
    assert t.flip_backs.tolist() == [0, 0]
    t.flip_backs = np.array([4, 5])
    assert t.halted().tolist() == [False, True]
    t.reset_halted()
    assert t.flip_backs.tolist() == [0, 0] and len(t._separated) == 0 and len(t._rejoins) == 0


def test_flip_back_bookkeeping():
    t = T1()
    t._reset_counters(2)
    state = SimpleNamespace(n_cells=10, n_replicas=2)
    # a flip in replica 1 separates cells (3, 1) and joins (2, 4)
    t._count_flip_backs(state, np.array([[3, 1, 2, 4]]), np.array([1]))
    assert t._separated.tolist() == [1 * 10 + 3] and t._rejoins.tolist() == [0]
    assert t.flip_backs.tolist() == [0, 0]
    # the flip back joins (1, 3) again and separates (2, 4): one re-join
    t._count_flip_backs(state, np.array([[4, 2, 1, 3]]), np.array([1]))
    assert t.flip_backs.tolist() == [0, 1]
    assert t._separated.tolist() == [13, 24] and t._rejoins.tolist() == [1, 0]
    # and again: (2, 4) re-joined once, (1, 3) separated again keeps its count
    t._count_flip_backs(state, np.array([[1, 3, 4, 2]]), np.array([1]))
    assert t._separated.tolist() == [13, 24] and t._rejoins.tolist() == [1, 1]
    t._count_flip_backs(state, np.array([[2, 4, 3, 1]]), np.array([1]))
    assert t._rejoins.tolist() == [2, 1] and t.flip_backs.tolist() == [0, 2]
    # an unrelated pair in replica 0: no re-join; a new pair larger than all known ones
    t._count_flip_backs(state, np.array([[8, 9, 7, 6]]), np.array([0]))
    assert t.flip_backs.tolist() == [0, 2] and t._separated.tolist() == [13, 24, 89]
    # joining a pair never separated, sorting after every key, is not a re-join
    t._count_flip_backs(state, np.array([[5, 6, 9, 7]]), np.array([0]))
    assert t.flip_backs.tolist() == [0, 2]


def test_pairs_between_rekeys_and_drops():
    n_from, n_to = 6, 3
    keys = np.array([0 * 6 + 5, 1 * 6 + 4, 2 * 6 + 3])
    cell_map = np.array([-1, 2, 0, 1, 0, -1])          # cells 1 -> 2, 2 -> 0, 3 -> 1, 4 -> 0
    new, keep = T1._pairs_between(keys, n_from, cell_map, n_to)
    # (0, 5) dropped; (1, 4) -> (2, 0) -> key 0 * 3 + 2 = 2; (2, 3) -> (0, 1) -> key 1
    assert new.tolist() == [1, 2] and keep.tolist() == [2, 1]


def test_loggables_and_counters_after_a_pass():
    sim, t = _attached(threshold=1.0, new_length=1.1)     # every edge short, no flip folds
    assert set(t.loggables) == {"t1_flips", "t1_refused", "t1_total_flips", "t1_total_refused", "t1_flip_backs"}
    sim.run(1)
    flips = t.loggables["t1_flips"](sim)
    assert flips.shape == (2,) and np.all(flips > 0)
    assert np.array_equal(t.loggables["t1_total_flips"](sim), t.total_flips)
    assert np.array_equal(t.total_flips, t.last_flips)
    sim.run(1)
    assert np.array_equal(t.total_flips, flips + t.last_flips)
    assert np.array_equal(t.total_refused, t.loggables["t1_total_refused"](sim))


def test_chord_threshold_on_the_sphere():
    sim, t = _attached(threshold=0.1)
    s = sim.state
    L = 0.1 * np.sqrt(s.mean_cell_area)
    R = s.radius_np()
    assert np.allclose(t.chord_threshold2(s), (2 * R * np.sin(L / (2 * R))) ** 2, rtol=1e-14)
