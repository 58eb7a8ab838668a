"""The last resort of :meth:`T1.untangle_pass <spherevm.plugins.updaters.T1.untangle_pass>`: where its
flips leave cells that are not simple, their vertices go back to where the previous pass left them,
and if that is not enough, the whole replica does (docs/validation.md)."""
from __future__ import annotations

import numpy as np

from ... import simplicity
from ..rows import saved_field

#: the State arrays a replica sent back gets back: per vertex, then per cell
_VERTEX_ARRAYS = ("positions", "vertex_neighbors", "vertex_cells")
_CELL_ARRAYS = ("cell_sides", "cell_vertices")
#: rounds of sending vertices back (each adds the vertices of the cells still not simple) before
#: the whole replica goes back
LOCAL_ROUNDS = 3


def faults(state):
    """Per replica whether it is not simple (:func:`spherevm.simplicity.faults`), and the cells at
    fault (crossed, open or of area <= 0)."""
    found = simplicity.faults(state)
    cells = np.unique(np.concatenate([found["crossed"], found["open"], found["inverted"]]))
    bad = found["uncovered"].copy()
    bad[state.cell_replica_np()[cells]] = True
    return bad, cells


class StepRefusal:
    """What the last untangling pass left, and the steps it refused since. Where the flips leave a
    replica that was simple at the last pass not simple, the vertices of its cells at fault take
    back their positions from the last pass, then those of the cells still at fault (up to
    :data:`LOCAL_ROUNDS` rounds); a replica still not simple takes back all its positions and tables.
    Every replica's rows are kept for the next pass."""

    def __init__(self, n_replicas=0):
        self.reset(n_replicas)

    def reset(self, n_replicas):
        """Forget the saved rows; zero the per-replica count of refused steps."""
        self.saved = None        # the arrays the last pass left (device arrays), or None
        self.simple = None       # per replica: its saved rows are simple
        self.refused = np.zeros(n_replicas, dtype=np.int64)

    def _usable(self, state):
        s = self.saved
        return s is not None and s["state"] is state and len(s["positions"]) == state.n_vertices and \
            len(s["cell_sides"]) == state.n_cells

    def apply(self, simulation):
        """Send back what is not simple and was at the last pass (the vertices sent back forget
        their integrator memory, as after a flip), then keep every replica's rows. Returns the mask
        of replicas with a step refused (some or all of their vertices sent back)."""
        state = simulation.state
        if len(self.refused) != state.n_replicas:
            self.reset(state.n_replicas)
        bad, cells = faults(state)
        fix = bad & self.simple if self._usable(state) else np.zeros_like(bad)
        refused = fix.copy()
        for _ in range(LOCAL_ROUNDS):
            if not fix.any():
                break
            mine = cells[fix[state.cell_replica_np()[cells]]]
            table = state.device.to_numpy(state.cell_vertices)[mine]
            self._restore(simulation, np.unique(table[table >= 0]), None)
            bad, cells = faults(state)
            fix &= bad
        if fix.any():
            self._restore(simulation, np.flatnonzero(fix[state.vertex_replica_np()]),
                          np.flatnonzero(fix[state.cell_replica_np()]))
            bad &= ~fix
        self.refused += refused
        xp = state.device.xp
        self.saved = dict(state=state, **{k: xp.copy(getattr(state, k)) for k in _VERTEX_ARRAYS + _CELL_ARRAYS})
        self.simple = ~bad
        return refused

    def to_save(self) -> dict:
        """Checkpoint fields: the refused steps per replica, and the rows the last pass kept (with
        whether each replica's are simple), so that a restarted run's first pass can send back what
        the uninterrupted run's would."""
        out = {"untangle_refused": self.refused.astype(np.int64)}
        if self.saved is not None:
            host = lambda a: a.get() if hasattr(a, "get") else np.asarray(a)   # noqa: E731
            out.update({f"untangle_{k}": host(self.saved[k]).copy() for k in _VERTEX_ARRAYS + _CELL_ARRAYS})
            out["untangle_simple"] = self.simple.astype(np.uint8)
        return out

    def restore(self, op, data, state):
        """The fields of :meth:`to_save` from ``data`` (``op``'s saved state), checked, the rows put
        on ``state``'s device and tied to it; a checkpoint without them (untangling off when it was
        written) starts afresh."""
        n, n_v = state.n_replicas, state.n_vertices
        self.reset(n)
        if "untangle_refused" not in data:
            return
        self.refused = saved_field(op, data, "untangle_refused", np.int64, (n,), low=0).copy()
        if "untangle_positions" not in data:
            return
        rows = {"positions": saved_field(op, data, "untangle_positions", np.float64, (n_v, 3))}
        for name in ("vertex_neighbors", "vertex_cells"):
            high = n_v - 1 if name == "vertex_neighbors" else state.n_cells - 1
            rows[name] = saved_field(op, data, f"untangle_{name}", np.int32, (n_v, 3), low=0, high=high)
        rows["cell_sides"] = saved_field(op, data, "untangle_cell_sides", np.int32, (state.n_cells,), low=3)
        rows["cell_vertices"] = saved_field(op, data, "untangle_cell_vertices", np.int32, (state.n_cells, None),
                                            low=-1, high=n_v - 1)
        simple = saved_field(op, data, "untangle_simple", np.uint8, (n,), low=0, high=1)
        xp = state.device.xp
        self.saved = dict(state=state, **{k: xp.asarray(v.copy()) for k, v in rows.items()})
        self.simple = simple.astype(bool)

    def _restore(self, simulation, vertices, cells):
        """The saved positions of ``vertices`` into the State, and with ``cells`` (a whole replica's
        vertices and cells) their saved tables too; in new arrays (the old ones may be held
        elsewhere), the narrower of the saved and the current cell table padded."""
        state = simulation.state
        xp = state.device.xp
        vertices = xp.asarray(vertices)
        rows = [("positions", vertices)]
        if cells is not None:
            cells = xp.asarray(cells)
            rows = [(k, vertices) for k in _VERTEX_ARRAYS] + [(k, cells) for k in _CELL_ARRAYS]
            state.topology_version += 1
        width = max(state.max_sides, self.saved["cell_vertices"].shape[1])
        for name, index in rows:
            now, saved = getattr(state, name), self.saved[name]
            if name == "cell_vertices":
                now, saved = (xp.concatenate([a, xp.full((len(a), width - a.shape[1]), -1, dtype=a.dtype)], axis=1)
                              for a in (now, saved))
            now = xp.ascontiguousarray(now.copy())
            now[index] = saved[index]
            setattr(state, name, now)
        integrator = simulation.operations.integrator
        if integrator is not None:
            integrator.reset_vertices(vertices)
        simulation.state_changed()
