"""T1's flip log is replayed at a convergence check only when it could halt a replica.

A flip re-joins one cell pair once, so ``max_flip_backs`` cannot be reached while the largest
count below it plus the flips logged since the last replay stays below it; then the check reads
the log's count and nothing else. The halts, and the flip-back memory once brought up to date,
must be exactly those of replaying at every check.
"""
import numpy as np
import pytest

from spherevm.plugins.updaters import T1

from conftest import sweep_like
from test_tissue_steps import MINIMIZE_WAYS, ensemble


class _Words:
    """A stand-in for the device's (width, log count) pair: what ``get`` reads back."""

    def __init__(self, width, n):
        self.host = np.array([width, n], dtype=np.int32)

    def get(self):
        return self.host


@pytest.mark.parametrize("logged, expected", [(0, False), (2, False), (3, True), (40, True)])
def test_a_replay_is_needed_only_when_the_limit_is_within_reach(logged, expected):
    t1 = T1(max_flip_backs=5)
    t1.flip_backs = np.array([2, 7, 0])          # replica 1 is past the limit: halted already
    t1._gpu = dict(words=_Words(9, logged), table=None, state=None, log_bound=10 ** 6, width_bound=50)
    assert t1._replay_could_reach(5) is expected
    assert t1._gpu["log_bound"] == logged         # the bound on the log's rows is the exact count now
    assert t1._gpu["width_bound"] == 50           # no padded table: its width bound is left alone


def test_without_device_buffers_nothing_is_replayed():
    t1 = T1()
    t1.flip_backs = np.zeros(2, dtype=np.int64)
    assert t1._replay_could_reach(t1.max_flip_backs) is False
    assert not t1.halted().any()


@pytest.mark.gpu
@pytest.mark.parametrize("max_flip_backs", [3, 100])
@pytest.mark.parametrize("way", MINIMIZE_WAYS[::2], ids=["fused", "step_by_step"])
def test_replaying_only_when_needed_halts_as_replaying_always(monkeypatch, max_flip_backs, way):
    """The same minimisation with the log replayed at every check (the bound switched off) and
    only when needed: the same results, FIRE state and flip-back memory; fewer replays."""
    state = ensemble("sphere", (80, 60, 120))
    t1 = dict(threshold=0.3, new_length=0.45, max_flip_backs=max_flip_backs)
    records = []
    for always in (True, False):
        replays = []
        flush = T1._flush_log
        monkeypatch.setattr(T1, "_flush_log", lambda self, s: (replays.append(1), flush(self, s))[1])
        if always:
            monkeypatch.setattr(T1, "_replay_could_reach", lambda self, limit: True)
        sim = sweep_like(state, np.full(3, 3.9), **t1)
        result = sim.minimize(max_steps=1500, check_every=20, **way)
        op = sim.operations.updaters[0]
        op._sync_counters()
        records.append(dict(reason=result.reason.tolist(), steps=result.steps.tolist(),
                            energy=result.energy.tobytes(), positions=sim.state.positions.get().tobytes(),
                            flip_backs=op.flip_backs.copy(), separated=op._separated.copy(),
                            rejoins=op._rejoins.copy(), replays=len(replays)))
        monkeypatch.undo()
    always, needed = records
    for key in always:
        if key != "replays":
            assert np.array_equal(always[key], needed[key]), key
    assert needed["separated"].size > 0, "T1 flipped and kept its memory"
    if max_flip_backs == 3:      # the limit is always within reach: every check replays
        assert "t1_oscillation" in needed["reason"], "some replica was halted"
    else:
        assert needed["replays"] < always["replays"], "some checks read the count alone"
