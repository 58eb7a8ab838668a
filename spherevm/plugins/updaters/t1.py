"""T1 neighbour exchanges: short edges are rotated so that four cells swap neighbours."""
from __future__ import annotations

import numpy as np

from ... import folding, topology
from ...constraints.kernels import KERNEL_SURFACES
from ...init_plane import MIN_T1_PLANAR_CELLS
from ..base import Updater
from ..minimizer import Minimizer
from ..parameters import Parameter
from ..rows import saved_field, saved_where
from ...validation import integer, positive
from .t1_device import DevicePass
from .untangle import StepRefusal

PRESETS = {
    # The rules of the paper's own code: threshold 0.1, new edge twice the old length.
    "reference": dict(threshold=0.1, new_length=None, length_factor=2.0),
}


def _preset(name, value):
    if value is not None and value not in PRESETS:
        raise ValueError(f"preset must be one of {sorted(PRESETS)} or None, got {value!r}")
    return value


def _flag(name, value):
    if not isinstance(value, (bool, np.bool_)):
        raise ValueError(f"{name} must be True or False, got {value!r}")
    return bool(value)


def _count_flip_backs(name, value):
    if value not in (None, True, False):
        raise ValueError(f"count_flip_backs must be None (auto), True or False, got {value!r}")
    return value


class T1(DevicePass, Updater):
    """Flip every edge shorter than ``threshold`` (units of sqrt(<A>) of its replica).

    The flip rotates the edge by 90 degrees about the surface normal at its midpoint: the two cells
    that shared it stop touching, the two cells at its ends now share it, and its vertices sit
    symmetrically about the midpoint. Rules, applied per pass (every time the trigger fires):

    * a flip that would leave a cell with fewer than 3 sides, or fold the network (leave one of its
      four cells with signed area <= 0, or invert a corner; see
      :func:`spherevm.folding.t1_placement`), is refused and counted, never an error; one whose
      usual placement would fold is rotated the other way round if that does not;
    * conflicting flips (short edges touching a common cell) are resolved deterministically: an
      edge flips only if it has the lowest index among the candidate edges touching each of its
      four cells, so at most one flip per cell per pass. The edge index is ``3 u + k`` for the edge
      ``u -> vertex_neighbors[u, k]`` with ``u < v``; the GPU kernel follows the same rule.

    Oscillation: a flip that makes two cells neighbours again after an earlier flip separated them
    is a flip back. When one pair of cells has been re-joined ``max_flip_backs`` times, its replica
    is reported as halted (``Simulation.minimize`` stops it with reason ``"t1_oscillation"``).
    ``flip_backs`` holds, per replica, the largest re-join count of any pair. See docs/t1.md.

    Parameters
    ----------
    threshold : float
        Edges shorter than this flip (default 0.04).
    new_length : float
        Length of a fresh edge (default 0.12, 3 x threshold, so it is not immediately short again).
    length_factor : float, optional
        Instead of ``new_length``: a fresh edge is this many times the old one.
    preset : {"reference"}, optional
        The paper's code: threshold 0.1, new edge twice the old length.
    trigger : Trigger or int
        The timesteps a pass runs on (default every step).
    reset_velocities : bool
        Ask the integrator to forget the flipped vertices' memory (``Integrator.reset_vertices``:
        FIRE zeroes their velocities).
    max_flip_backs : int
        Re-joins of one cell pair that halt its replica.
    count_flip_backs : bool, optional
        Keep the flip-back bookkeeping (a record of every separated cell pair). None: unless the
        integrator is a dynamics integrator that is not a Minimizer (Brownian, Active): there flips
        back and forth are physics, and the record grows with every flip.
    untangle : bool
        Also flip the edges that a step turned past zero length (a bow tie: the edges before and
        after one cross, :func:`spherevm.folding.inverted_edges`), by the same rules, so that cells
        stay simple polygons; where no edge is crossed the pass is the same to the bit. Both devices
        make the same flips. :meth:`untangle_pass` flips them alone after a step, and refuses the
        step of a replica left not simple. Default False; see docs/validation.md."""

    preset = Parameter(_preset)
    threshold = Parameter(positive)
    new_length = Parameter(lambda name, value: None if value is None else positive(name, value))
    length_factor = Parameter(lambda name, value: None if value is None else positive(name, value))
    max_flip_backs = Parameter(lambda name, value: integer(name, value, minimum=1))
    reset_velocities = Parameter(lambda name, value: bool(value))
    count_flip_backs = Parameter(_count_flip_backs)
    untangle = Parameter(_flag)

    def __init__(self, threshold=0.04, new_length=0.12, length_factor=None, preset=None, trigger=1,
                 reset_velocities=True, max_flip_backs=100, count_flip_backs=None, untangle=False):
        super().__init__(trigger)
        if preset is not None:
            threshold, new_length, length_factor = (PRESETS[_preset("preset", preset)][k] for k in
                                                    ("threshold", "new_length", "length_factor"))
        if new_length is None and length_factor is None:
            raise ValueError("give new_length (in units of sqrt(<A>)) or length_factor")
        self.threshold = threshold
        self.length_factor = length_factor
        self.new_length = None if length_factor is not None else new_length
        self.max_flip_backs = max_flip_backs
        self.reset_velocities = reset_velocities
        self.count_flip_backs = count_flip_backs
        self.untangle = untangle
        self.preset = preset
        self._reset_counters(0)

    def check_parameters(self):
        """Exactly one of new_length (> threshold) and length_factor (> 1)."""
        if self.length_factor is not None:
            if self.length_factor <= 1:
                raise ValueError(f"length_factor must be > 1 (a shorter new edge is short again and flips "
                                 f"straight back), got {self.length_factor!r}")
        elif self.new_length is None:
            raise ValueError("give new_length (in units of sqrt(<A>)) or length_factor")
        elif self.new_length <= self.threshold:
            raise ValueError(f"new_length must be finite and > threshold={self.threshold} "
                             f"(else the new edge flips straight back), got {self.new_length!r}")

    def parameters_changed(self, name):
        """A preset sets threshold, new_length and length_factor; setting one of those leaves the
        preset (``preset`` becomes None); new_length and length_factor replace each other."""
        if name == "preset":
            if self.preset is not None:
                self.__dict__.update({k: v for k, v in PRESETS[self.preset].items()
                                      if k in ("threshold", "new_length", "length_factor")})
            return
        if name in ("threshold", "new_length", "length_factor"):
            self.__dict__["preset"] = None
        if name == "new_length" and self.new_length is not None:
            self.__dict__["length_factor"] = None
        elif name == "length_factor" and self.length_factor is not None:
            self.__dict__["new_length"] = None

    def _reset_counters(self, n_replicas):
        self.last_flips = np.zeros(n_replicas, dtype=np.int64)
        self.last_refused = np.zeros(n_replicas, dtype=np.int64)
        self.total_flips = np.zeros(n_replicas, dtype=np.int64)
        self.total_refused = np.zeros(n_replicas, dtype=np.int64)
        self.flip_backs = np.zeros(n_replicas, dtype=np.int64)
        self._refusal = StepRefusal(n_replicas)     # untangle_pass's kept rows and refused steps
        self._forget_pairs()

    def _forget_pairs(self):
        self._separated = np.zeros(0, dtype=np.int64)  # cell pairs separated by a flip (sorted keys)
        self._rejoins = np.zeros(0, dtype=np.int64)    # how often each was joined again

    gpu_surfaces = KERNEL_SURFACES
    surface_needs = ("normal", "project_normal", "edge_lengths", "chord_length", "total_area_np", "triangle_area")

    def attach(self, simulation):
        state = simulation.state
        if getattr(state.constraint, "euler_characteristic", 2) == 0 and state.n_cells:
            smallest = int(np.argmin(state.cells_per_replica))
            if state.cells_per_replica[smallest] < MIN_T1_PLANAR_CELLS:
                raise ValueError(f"T1 needs at least {MIN_T1_PLANAR_CELLS} cells per replica on a periodic plane, but "
                                 f"replica {smallest} has {int(state.cells_per_replica[smallest])}: in a smaller box "
                                 "edges reach half the box under T1 and cells stop closing (docs/plane.md)")
        super().attach(simulation)
        self._update = self.implementation("update", simulation.state)
        self._gpu = None
        self._reset_counters(simulation.state.n_replicas)

    # ------------------------------------------------------------------ detection
    def chord_threshold2(self, state):
        """Squared chord of the threshold per replica: an edge is short iff its chord is shorter.

        The constraint gives the chord of a geodesic of length ``L`` (on the sphere ``2 R sin(L / 2R)``),
        monotonic in ``L``, so the test needs no trigonometry for the many long edges; the GPU kernel
        uses the same test.
        """
        L = self.threshold * np.sqrt(state.mean_cell_area)
        return state.constraint.chord_length(L, state.constraint.size_np(state)) ** 2

    def _edge_list(self, state):
        """Each undirected edge once, as the corner ``3 u + slot`` with ``u < neighbour``, in edge
        index order, with its two vertices and its replica. Cached per State and topology version."""
        def build():
            xp = state.device.xp
            vn = state.vertex_neighbors
            corner = xp.flatnonzero((xp.arange(state.n_vertices)[:, None] < vn).reshape(-1))
            u = corner // 3
            return dict(corner=corner, u=u, v=vn.reshape(-1)[corner], replica=state.vertex_replica[u])

        return state.cached((self, "edges"), build, topology=True)

    def short_edges(self, state):
        """Candidate edges ``(u, slot, geodesic length)`` shorter than the threshold, by edge index."""
        dev = state.device
        xp = dev.xp
        e = self._edge_list(state)
        periodic = getattr(state.constraint, "displacement", None)     # minimum images on a periodic box
        if periodic is not None:
            d = periodic(state, e["u"], e["v"])
            chord2 = (d * d).sum(axis=1)
        else:
            comp = xp.ascontiguousarray(state.positions.T)
            d = xp.take(comp, e["u"], axis=1) - xp.take(comp, e["v"], axis=1)
            chord2 = xp.einsum("ij,ij->j", d, d)
        limit = xp.asarray(self.chord_threshold2(state))
        flat = dev.to_numpy(e["corner"][chord2 < limit[e["replica"]]])
        if len(flat) == 0:
            return flat, flat, np.zeros(0)
        uu, slot = flat // 3, flat % 3
        vn = state.vertex_neighbors
        lengths = state.constraint.edge_lengths(state, xp.asarray(uu), vn[xp.asarray(uu), xp.asarray(slot)])
        return uu, slot, dev.to_numpy(lengths)

    def new_lengths(self, state, u, lengths):
        """The length each candidate edge gets when it flips (``lengths``: its current length)."""
        if self.length_factor is not None:
            return self.length_factor * lengths
        return self.new_length * np.sqrt(state.mean_cell_area)[state.vertex_replica_np()[u]]

    def select(self, state, u, slot, lengths):
        """Apply the rules: returns (flip mask, refused mask) over the candidates, their cells, and
        which flips turn the other way (:func:`spherevm.folding.t1_placement`)."""
        dev = state.device
        vn, vc = dev.to_numpy(state.vertex_neighbors), dev.to_numpy(state.vertex_cells)
        sides = dev.to_numpy(state.cell_sides)
        _, _, _, _, _, C1, C2, C3, C4 = topology.t1_cells(vn, vc, u, slot)
        cells = np.stack([C1, C2, C3, C4], axis=1)
        ordered = np.sort(cells, axis=1)
        distinct = (ordered[:, 1:] != ordered[:, :-1]).all(axis=1)
        refused = (sides[C1] <= 3) | (sides[C2] <= 3) | ~distinct
        rest = np.flatnonzero(~refused)
        turn = np.zeros(len(u), dtype=bool)
        refused[rest], turn[rest] = folding.t1_placement(state, u[rest], slot[rest],
                                                         self.new_lengths(state, u[rest], lengths[rest]),
                                                         self.untangle)
        index = 3 * u + slot
        claim = np.full(state.n_cells, np.iinfo(np.int64).max, dtype=np.int64)
        ok = ~refused
        np.minimum.at(claim, cells[ok].reshape(-1), np.repeat(index[ok], 4))
        flip = ok & (claim[cells] == index[:, None]).all(axis=1)
        return flip, refused, cells, turn

    # ------------------------------------------------------------------ the pass
    def update(self, simulation, timestep):
        self._update(simulation)

    def counting(self, simulation) -> bool:
        """Whether this pass records flip-backs (see ``count_flip_backs``)."""
        if self.count_flip_backs is not None:
            return self.count_flip_backs
        integrator = simulation.operations.integrator
        return integrator is None or isinstance(integrator, Minimizer)

    def _update_cpu(self, simulation):
        state = simulation.state
        self.last_flips = np.zeros(state.n_replicas, dtype=np.int64)
        self.last_refused = np.zeros(state.n_replicas, dtype=np.int64)
        u, slot, lengths = self.short_edges(state)
        if self.untangle:
            u, slot, lengths = self._with_inverted(state, u, slot, lengths)
        self._flip_pass(simulation, u, slot, lengths)

    def untangle_pass(self, simulation, rounds: int = 4, revert: bool = True):
        """Flip the edges that are turned past zero length (:func:`spherevm.folding.inverted_edges`)
        by this updater's rules, adding to this step's counts, again while a round flips some (at
        most ``rounds``: edges of one cell wait for the next round). On the GPU each round is the
        device pass on the crossed edges (one small read-back), the same flips. Then (``revert``) in
        a replica still not simple (:func:`spherevm.simplicity.faults`) that the last such call left
        simple, the vertices at fault take back their places from that call, or failing that the
        whole replica its rows (:class:`~spherevm.plugins.updaters.untangle.StepRefusal`; counted in
        ``untangle_refused``). Called right after every step, what writers and checks see is
        simple. Returns the flips made."""
        gpu = simulation.state.device.is_gpu
        before = self._flips_so_far(simulation.state)
        for _ in range(rounds):
            if not (self._update_gpu(simulation, crossed_only=True) if gpu else self._untangle_round(simulation)):
                break
        if revert:
            self._refusal.apply(simulation)
        return self._flips_so_far(simulation.state) - before

    @property
    def untangle_refused(self):
        """Per replica: the steps :meth:`untangle_pass` refused (replicas it sent back)."""
        return self._refusal.refused.copy()

    def _flips_so_far(self, state):
        """All flips made, on the host or (one small read-back) the device."""
        if state.device.is_gpu:
            return int(self._gpu_buffers(state)["total_flips"].sum())
        return int(self.total_flips.sum())

    def _untangle_round(self, simulation):
        """One pass on the crossed edges alone (NumPy); whether it flipped any."""
        made = int(self.total_flips.sum())
        empty = np.zeros(0, dtype=np.int64)
        self._flip_pass(simulation, *self._with_inverted(simulation.state, empty, empty, np.zeros(0)))
        return int(self.total_flips.sum()) != made

    def _with_inverted(self, state, u, slot, lengths):
        """The candidates ``(u, slot, lengths)`` joined by the inverted edges, in edge index order."""
        iu, islot = folding.inverted_edges(state)
        index = 3 * np.asarray(u, dtype=np.int64) + slot
        new = ~np.isin(3 * iu + islot, index)
        if not new.any():
            return u, slot, lengths
        iu, islot = iu[new], islot[new]
        xp = state.device.xp
        ilen = state.device.to_numpy(state.constraint.edge_lengths(
            state, xp.asarray(iu), state.vertex_neighbors[xp.asarray(iu), xp.asarray(islot)]))
        order = np.argsort(np.concatenate([index, 3 * iu + islot]))
        return (np.concatenate([u, iu])[order], np.concatenate([slot, islot])[order],
                np.concatenate([lengths, ilen])[order])

    def _flip_pass(self, simulation, u, slot, lengths):
        """Flip the candidates ``(u, slot, lengths)`` of active replicas by the rules, counting."""
        state = simulation.state
        n_rep = state.n_replicas
        integrator = simulation.operations.integrator
        if len(u) and integrator is not None:
            keep = integrator.active[state.vertex_replica_np()[u]]
            u, slot, lengths = u[keep], slot[keep], lengths[keep]
        if len(u) == 0:
            return
        flip, refused, cells, turn = self.select(state, u, slot, lengths)
        rep = state.vertex_replica_np()[u]
        refusals = np.bincount(rep[refused], minlength=n_rep)
        self.last_refused = self.last_refused + refusals
        self.total_refused += refusals
        if not flip.any():
            return
        u, slot, lengths, cells, rep = u[flip], slot[flip], lengths[flip], cells[flip], rep[flip]
        new = self.new_lengths(state, u, lengths)
        if self.counting(simulation):
            self._count_flip_backs(state, cells, rep)
        moved = topology.t1_flip(state, u, slot, new, turn=turn[flip])
        flips = np.bincount(rep, minlength=n_rep)
        self.last_flips = self.last_flips + flips
        self.total_flips += flips
        if self.reset_velocities and integrator is not None:
            integrator.reset_vertices(state.device.asarray(moved))
        simulation.state_changed()

    def _count_flip_backs(self, state, cells, rep, n_cells=None, passes=None):
        """Count re-joins: a flip making two cells neighbours again that an earlier flip separated.
        ``n_cells``: the cell count the flips saw (the device log's, if the State was resized since).
        ``passes``: each flip's pass (None: all of one pass). The passes are counted at once, as if
        one after another: a flip is a flip back if its pair was separated before its pass (in the
        memory, or by a flip of an earlier pass here); a pair gains a re-join per pass that makes it
        back (two flips of one pass never share a cell), and each replica's ``flip_backs`` is its
        largest count after a flip back, the count after the pair's last one."""
        n = state.n_cells if n_cells is None else n_cells

        def pair_key(x, y):
            return np.minimum(x, y).astype(np.int64) * n + np.maximum(x, y)

        def find(sorted_keys, keys):
            """Positions of keys in sorted_keys, and whether each is there."""
            at = np.searchsorted(sorted_keys, keys)
            found = np.zeros(len(keys), dtype=bool)
            inside = at < len(sorted_keys)
            found[inside] = sorted_keys[at[inside]] == keys[inside]
            return at, found

        removed, made = pair_key(cells[:, 0], cells[:, 1]), pair_key(cells[:, 2], cells[:, 3])
        passes = np.zeros(len(made), dtype=np.int64) if passes is None else np.asarray(passes, dtype=np.int64)
        order = np.lexsort((passes, removed))               # each pair separated here, at its earliest pass
        new, first = np.unique(removed[order], return_index=True)
        first_pass = passes[order][first]
        at, earlier = find(new, made)
        earlier[earlier] = first_pass[at[earlier]] < passes[earlier]
        back = find(self._separated, made)[1] | earlier
        at, known = find(self._separated, new)              # merged into the sorted memory (no sort
        self._separated = np.insert(self._separated, at[~known], new[~known])   # of all of it: a sweep
        self._rejoins = np.insert(self._rejoins, at[~known], 0)                  # replays many passes)
        pos = np.searchsorted(self._separated, made[back])
        np.add.at(self._rejoins, pos, 1)
        worst = np.zeros(state.n_replicas, dtype=np.int64)
        np.maximum.at(worst, np.asarray(rep)[back], self._rejoins[pos])
        self.flip_backs = np.maximum(self.flip_backs, worst)

    # ------------------------------------------------------------------ narrowing (minimize)
    narrowable = True
    _COUNTERS = ("last_flips", "last_refused", "total_flips", "total_refused", "flip_backs")

    @staticmethod
    def _pairs_between(keys, n_from, cell_map, n_to):
        """Re-key cell pairs ``min * n + max`` through ``cell_map`` (-1: dropped); sorted, with the
        positions kept."""
        a, b = cell_map[keys // n_from], cell_map[keys % n_from]
        keep = np.flatnonzero((a >= 0) & (b >= 0))
        new = np.minimum(a[keep], b[keep]) * n_to + np.maximum(a[keep], b[keep])
        order = np.argsort(new)
        return new[order], keep[order]

    def narrow(self, selection):
        """Counters follow the selected replicas; the flip-back memory their cells."""
        self._sync_counters()
        saved = {name: getattr(self, name) for name in self._COUNTERS}
        saved.update(separated=self._separated, rejoins=self._rejoins)
        for name in self._COUNTERS:
            setattr(self, name, saved[name][selection.replicas].copy())
        n_from = self._simulation.state.n_cells           # still the wider State
        cell_map = np.full(n_from, -1, dtype=np.int64)
        cell_map[selection.cells] = np.arange(len(selection.cells))
        self._separated, keep = self._pairs_between(self._separated, n_from, cell_map, len(selection.cells))
        self._rejoins = saved["rejoins"][keep]
        self._gpu = None
        return saved

    def widen(self, selection, saved):
        self._sync_counters()
        for name in self._COUNTERS:
            saved[name][selection.replicas] = getattr(self, name)
            setattr(self, name, saved[name])
        n_to = self._simulation.state.n_cells              # the wider State again
        mine, keep = self._pairs_between(self._separated, len(selection.cells), selection.cells, n_to)
        others = ~np.isin(saved["separated"] // n_to, selection.cells)
        keys = np.concatenate([saved["separated"][others], mine])
        order = np.argsort(keys)
        self._separated = keys[order]
        self._rejoins = np.concatenate([saved["rejoins"][others], self._rejoins[keep]])[order]
        self._gpu = None

    # ------------------------------------------------------------------ checkpoints
    def state_to_save(self) -> dict:
        """Counters per replica and the flip-back memory (separated cell pairs, re-join counts)."""
        self._sync_counters()
        out = {name: np.array(getattr(self, name), dtype=np.int64) for name in self._COUNTERS}
        out.update(separated=self._separated.astype(np.int64), rejoins=self._rejoins.astype(np.int64))
        return dict(out, **(self._refusal.to_save() if self.untangle else {}))

    def restore_state(self, data: dict):
        """Counters per replica (>= 0, the last pass's at most the totals) and the flip-back memory:
        sorted distinct cell-pair keys ``a * n_C + b`` with ``a < b`` cells of this State, and as many
        re-join counts (>= 0)."""
        state = self._simulation.state
        n, n_c = state.n_replicas, state.n_cells
        saved = {name: saved_field(self, data, name, np.int64, (n,), low=0) for name in self._COUNTERS}
        for last, total in (("last_flips", "total_flips"), ("last_refused", "total_refused")):
            over = np.flatnonzero(saved[last] > saved[total])
            if len(over):
                raise ValueError(f"{saved_where(self, data, last)}: expected at most {total} per replica, got "
                                 f"{saved[last][over[0]]} > {saved[total][over[0]]} for replica {over[0]}")
        keys = saved_field(self, data, "separated", np.int64, (None,), low=0, high=n_c * n_c - 1)
        if np.any(np.diff(keys) <= 0) or np.any(keys // n_c >= keys % n_c):
            raise ValueError(f"{saved_where(self, data, 'separated')}: expected sorted distinct keys a * {n_c} + b "
                             f"of cell pairs a < b, got {keys.tolist()[:8]}")
        rejoins = saved_field(self, data, "rejoins", np.int64, (len(keys),), low=0)
        for name in self._COUNTERS:
            setattr(self, name, saved[name].copy())
        self._separated, self._rejoins = keys.copy(), rejoins.copy()
        self._refusal.restore(self, data, state)     # untangle_pass's kept rows, where saved
        self._gpu = None          # device counters are rebuilt from these totals

    def resized(self, change):
        """Cells divided or removed: the flip-back memory follows its cells (pairs with a removed
        cell are forgotten); the per-replica counters stay. On the GPU the device counters and flip
        log (in the old numbering) are read first, and the buffers are rebuilt for the new counts."""
        self._sync_counters()
        self._separated, keep = self._pairs_between(self._separated, change.n_cells_before, change.cell_map,
                                                    len(change.cell_source))
        self._rejoins = self._rejoins[keep]
        self._gpu = None

    # ------------------------------------------------------------------ reporting
    def halted(self):
        """Per-replica mask of replicas caught flipping back and forth, for Simulation.minimize (at
        every convergence check). On the GPU the flip log is read back and replayed only when it
        could halt a replica (:meth:`_replay_could_reach`); the counts stay exact for what they
        decide, and ``_sync_counters`` brings them up to date for anything else."""
        if self._replay_could_reach(self.max_flip_backs):
            self._sync_flip_backs()
        return self.flip_backs >= self.max_flip_backs

    halt_reason = "t1_oscillation"

    def reset_halted(self):
        self._sync_counters()
        self.flip_backs[:] = 0
        self._forget_pairs()

    @property
    def loggables(self):
        def read(name):
            def value(sim):
                self._sync_counters()
                return getattr(self, name).copy()
            return value
        return {"t1_flips": read("last_flips"), "t1_refused": read("last_refused"),
                "t1_total_flips": read("total_flips"), "t1_total_refused": read("total_refused"),
                "t1_flip_backs": read("flip_backs"), "t1_untangle_refused": lambda sim: self.untangle_refused}

    def __repr__(self):
        length = f"length_factor={self.length_factor}" if self.length_factor else f"new_length={self.new_length}"
        return f"T1(threshold={self.threshold}, {length}, trigger={self.trigger!r})"
