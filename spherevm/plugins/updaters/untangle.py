"""The last resort of :meth:`T1.untangle_pass <spherevm.plugins.updaters.T1.untangle_pass>`: a replica
that its flips left not simple goes back to what the previous pass left (docs/validation.md)."""
from __future__ import annotations

import numpy as np

from ... import simplicity

#: the State arrays a refused replica gets back: per vertex, then per cell
_VERTEX_ARRAYS = ("positions", "vertex_neighbors", "vertex_cells")
_CELL_ARRAYS = ("cell_sides", "cell_vertices")


def not_simple(state):
    """Per replica: whether a cell crosses itself, does not close (periodic surfaces), has signed
    area <= 0, or the areas do not add up to the surface's (:func:`spherevm.simplicity.counts`)."""
    return np.any([c > 0 for c in simplicity.counts(state).values()], axis=0)


class StepRefusal:
    """What the last untangling pass left, and the replicas it refused since: a replica that is not
    simple after the pass's flips takes back its positions and tables from the previous pass, where
    it was simple; every replica's rows are kept for the next pass."""

    def __init__(self):
        self.saved = None        # the arrays the last pass left (device arrays), or None
        self.simple = None       # per replica: its saved rows are simple
        self.refused = np.zeros(0, dtype=np.int64)

    def reset(self, n_replicas):
        """Forget the saved rows; zero the per-replica count of refused steps."""
        self.saved, self.simple = None, None
        self.refused = np.zeros(n_replicas, dtype=np.int64)

    def _usable(self, state):
        s = self.saved
        return s is not None and s["state"] is state and len(s["positions"]) == state.n_vertices and \
            len(s["cell_sides"]) == state.n_cells

    def apply(self, simulation):
        """Refuse the replicas that are not simple and were simple at the last pass (their vertices'
        integrator memory forgotten, as after a flip), then keep every replica's rows. Returns the
        mask of replicas refused."""
        state = simulation.state
        if len(self.refused) != state.n_replicas:
            self.reset(state.n_replicas)
        bad = not_simple(state)
        back = bad & self.simple if self._usable(state) else np.zeros_like(bad)
        if back.any():
            self._restore(simulation, back)
            self.refused += back
            bad &= ~back
        xp = state.device.xp
        self.saved = dict(state=state, **{k: xp.copy(getattr(state, k)) for k in _VERTEX_ARRAYS + _CELL_ARRAYS})
        self.simple = ~bad
        return back

    def _restore(self, simulation, back):
        """The saved rows of the replicas ``back`` into new State arrays (the old ones may be held
        elsewhere); the narrower of the saved and the current cell table is padded."""
        state = simulation.state
        xp = state.device.xp
        vertices = xp.asarray(np.flatnonzero(back[state.vertex_replica_np()]))
        cells = xp.asarray(np.flatnonzero(back[state.cell_replica_np()]))
        width = max(state.max_sides, self.saved["cell_vertices"].shape[1])
        for name, rows in [(k, vertices) for k in _VERTEX_ARRAYS] + [(k, cells) for k in _CELL_ARRAYS]:
            now, saved = getattr(state, name), self.saved[name]
            if name == "cell_vertices":
                now, saved = (xp.concatenate([a, xp.full((len(a), width - a.shape[1]), -1, dtype=a.dtype)], axis=1)
                              for a in (now, saved))
            now = xp.ascontiguousarray(now.copy())
            now[rows] = saved[rows]
            setattr(state, name, now)
        state.topology_version += 1
        integrator = simulation.operations.integrator
        if integrator is not None:
            integrator.reset_vertices(vertices)
        simulation.state_changed()
