"""Tests that kill mutants of spherevm/plugins/updaters/t1.py that survived the existing tests.

Found with ``python3 benchmarks/mutate.py spherevm/plugins/updaters/t1.py ...`` (docs/testing.md,
"Mutation testing"): documented defaults, the closed ends of the parameter ranges, the flip-back
bookkeeping and the halting threshold, re-keying of cell pairs for narrowing.
"""
import inspect
from types import SimpleNamespace

import numpy as np
import pytest
from conftest import t1_simulations

import spherevm as svm
from spherevm.plugins.updaters import T1
from spherevm.plugins.updaters import t1 as t1_module


def test_documented_defaults_and_preset():
    sig = inspect.signature(T1)
    defaults = {k: p.default for k, p in sig.parameters.items()}
    assert defaults == dict(threshold=0.04, new_length=0.12, length_factor=None, preset=None, trigger=1,
                            reset_velocities=True, max_flip_backs=100, count_flip_backs=None, untangle=False)
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


def test_flip_backs_of_many_passes_at_once_are_those_pass_by_pass():
    """The device's flip log is replayed in one call (``passes``): the memory, the re-join counts
    and flip_backs must be those of replaying its passes one after another. Random logs over a few
    cells, so that pairs are separated and re-joined many times, within and across calls."""
    rng = np.random.default_rng(7)
    state = SimpleNamespace(n_cells=12, n_replicas=2)
    most = 0
    for trial in range(200):
        batched, stepped = T1(), T1()
        for t in (batched, stepped):
            t._reset_counters(2)
        for call in range(3):
            rows = []
            for p in range(int(rng.integers(1, 6))):
                for r in range(2):          # a pass's flips share no cell: at most one flip per replica here
                    if rng.random() < 0.8:
                        cells = rng.choice(6, size=4, replace=False) + 6 * r
                        rows.append([p, *cells, r])
            if not rows:
                continue
            log = np.array(rows)[rng.permutation(len(rows))]      # the device writes a pass's flips in any order
            batched._count_flip_backs(state, log[:, 1:5], log[:, 5], passes=log[:, 0])
            for p in np.unique(log[:, 0]):
                rows_p = log[log[:, 0] == p]
                stepped._count_flip_backs(state, rows_p[:, 1:5], rows_p[:, 5])
            assert batched._separated.tolist() == stepped._separated.tolist(), trial
            assert batched._rejoins.tolist() == stepped._rejoins.tolist(), trial
            assert batched.flip_backs.tolist() == stepped.flip_backs.tolist(), trial
        most = max(most, int(stepped.flip_backs.max()))
    assert most > 2, "pairs were re-joined several times"


def test_pairs_between_rekeys_and_drops():
    n_from, n_to = 6, 3
    keys = np.array([0 * 6 + 5, 1 * 6 + 4, 2 * 6 + 3])
    cell_map = np.array([-1, 2, 0, 1, 0, -1])          # cells 1 -> 2, 2 -> 0, 3 -> 1, 4 -> 0
    new, keep = T1._pairs_between(keys, n_from, cell_map, n_to)
    # (0, 5) dropped; (1, 4) -> (2, 0) -> key 0 * 3 + 2 = 2; (2, 3) -> (0, 1) -> key 1
    assert new.tolist() == [1, 2] and keep.tolist() == [2, 1]


def test_loggables_and_counters_after_a_pass():
    sim, t = _attached(threshold=1.0, new_length=1.1)     # every edge short, no flip folds
    assert set(t.loggables) == {"t1_flips", "t1_refused", "t1_total_flips", "t1_total_refused", "t1_flip_backs",
                                "t1_untangle_refused"}
    sim.run(1)
    assert np.array_equal(t.loggables["t1_untangle_refused"](sim), np.zeros(2))   # no untangle_pass: none refused
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


def test_counters_are_empty_before_attaching():
    t = T1()
    for name in ("last_flips", "last_refused", "total_flips", "total_refused", "flip_backs"):
        assert getattr(t, name).shape == (0,)


def test_pairs_with_one_dropped_cell_are_dropped():
    keys = np.array([1 * 6 + 5, 0 * 6 + 2, 2 * 6 + 3])
    cell_map = np.array([-1, 2, 0, 1, 0, -1])          # (1, 5) and (0, 2) lose one cell, (2, 3) -> (0, 1)
    new, keep = T1._pairs_between(keys, 6, cell_map, 3)
    assert new.tolist() == [1] and keep.tolist() == [2]


def test_short_edges_of_a_tissue_without_any():
    sim, t = _attached(threshold=1e-6, new_length=0.12)
    u, slot, lengths = t.short_edges(sim.state)
    assert u.shape == slot.shape == lengths.shape == (0,)


def test_an_edge_exactly_at_the_threshold_is_not_short():
    """A honeycomb and a threshold, within a few ulps of its edge length, whose chord limit equals
    some edges' squared chord exactly: those edges are not candidates, the shorter ones are."""
    s = svm.init.hexagonal_tiling(4, 4)
    probe = T1()
    e = probe._edge_list(s)
    d = s.constraint.displacement(s, e["u"], e["v"])
    c2 = (d * d).sum(axis=1)
    threshold = np.sqrt(c2.max() / s.mean_cell_area[0]) * (1 - 8 * np.finfo(float).eps)
    for _ in range(32):
        t = T1(threshold=threshold, new_length=1.0)
        limit = t.chord_threshold2(s)[0]
        if np.any(c2 == limit) and np.any(c2 < limit):
            break
        threshold = np.nextafter(threshold, 1.0)
    assert np.any(c2 == limit) and np.any(c2 < limit)
    u, slot, _ = t.short_edges(s)
    assert sorted((3 * u + slot).tolist()) == sorted(e["corner"][c2 < limit].tolist())
    assert not np.isin(e["corner"][c2 == limit], 3 * u + slot).any()



def test_checkpoint_round_trip_and_wrong_replica_count():
    sim, t = _attached(threshold=1.0, new_length=1.1)      # every edge short, no flip folds
    sim.run(2)
    saved = t.state_to_save()
    assert len(saved["separated"]) > 1 and np.all(saved["total_flips"] > 0)
    _, fresh = _attached(threshold=1.0, new_length=1.1)
    fresh.restore_state({k: v.copy() for k, v in saved.items()})
    for name in ("last_flips", "last_refused", "total_flips", "total_refused", "flip_backs"):
        assert np.array_equal(getattr(fresh, name), saved[name]), name
    assert np.array_equal(fresh._separated, saved["separated"]) and np.array_equal(fresh._rejoins, saved["rejoins"])
    with pytest.raises(ValueError, match=r"T1: saved field 'total_flips': expected shape \(2,\), got \(3,\)"):
        fresh.restore_state(dict(saved, total_flips=np.zeros(3, dtype=np.int64)))


@pytest.mark.gpu
def test_gpu_pass_with_more_candidates_than_room_matches_numpy():
    """Nearly every edge short: more candidates than the GPU's first candidate room and flip log
    (1024 rows), so a pass regrows both and replays the log; it still flips as NumPy does."""
    state = svm.init.random_tiling(1000, replicas=2, seed=5)
    sims = t1_simulations(state, threshold=1.0, new_length=1.5, max_flip_backs=10 ** 6)
    c, g = sims["cpu"], sims["gpu"]
    for _ in range(3):
        c.run_updaters()
        g.run_updaters()
        for name in ("t1_flips", "t1_refused", "t1_total_flips", "t1_total_refused", "t1_flip_backs"):
            assert np.array_equal(g.log(name), c.log(name)), name
        assert np.array_equal(g.state.vertex_neighbors.get(), c.state.vertex_neighbors)
        assert np.array_equal(g.state.vertex_cells.get(), c.state.vertex_cells)
        assert np.abs(g.state.positions.get() - c.state.positions).max() <= 1e-12
    assert int(c.log("t1_flips").sum()) > 0
    assert g.operations.updaters[0]._gpu["capacity"] > 1024
