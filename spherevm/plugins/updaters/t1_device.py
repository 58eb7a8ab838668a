"""T1's pass on the GPU (t1.cu): detect, check, one small read-back, apply (which also gives the
claimed cells back); inside a CUDA graph (:mod:`spherevm.graphs`) the same kernels with no read-back."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from ...constraints.kernels import surface_kernels
from ...device import launch
from ...kernel_struct import KernelStruct
from ..fusion import FusedStage

_KERNELS = Path(__file__).with_name("t1.cu")
_CAND_INTS, _LOG_INTS = 13, 6
#: spare cell-table columns added beyond what a stretch of graph steps needs (fewer re-paddings)
SPARE_COLUMNS = 16


class DevicePass:
    """The GPU half of :class:`~spherevm.plugins.updaters.T1` (T1 holds the rules, the counters and
    the flip-back memory; this the device buffers and the kernel launches)."""

    def _gpu_buffers(self, state, capacity=0):
        """The device buffers for ``state``, with room for at least ``capacity`` candidates."""
        import cupy as cp
        buf = getattr(self, "_gpu", None)
        if buf is None or buf["n_cells"] != state.n_cells or buf["state"] is not state:
            cap, r = max(1024, state.n_vertices // 4, capacity), state.n_replicas
            # per-pass counters in one buffer, zeroed by one memset:
            # [candidates (short edges), widen, claimants (candidates not refused) | flips | refused]
            scratch = cp.zeros(3 + 2 * r, dtype=cp.int32)
            # the table width the graph and fused steps track, and the flip log's count: read together
            words = cp.zeros(2, dtype=cp.int32)
            buf = dict(state=state, n_cells=state.n_cells, capacity=cap,
                       claim=cp.full(state.n_cells, np.iinfo(np.int32).max, dtype=cp.int32), scratch=scratch,
                       counters=scratch[:3], flips=scratch[3:3 + r], refused=scratch[3 + r:],
                       words=words, width=words[:1], log_count=words[1:], log_bound=0,
                       log_pass=cp.zeros(1, dtype=cp.int32),
                       cand=cp.empty((cap, _CAND_INTS), dtype=cp.int32), cand_len=cp.empty(cap),
                       log=cp.empty((cap, _LOG_INTS), dtype=cp.int32), moved=cp.empty(2 * cap, dtype=cp.int32),
                       all_active=cp.ones(r, dtype=bool), width_host=-1,
                       width_bound=0, table=None, total_flips=cp.asarray(self._host_totals("total_flips", r)),
                       total_refused=cp.asarray(self._host_totals("total_refused", r)))
            self._gpu = buf
        elif capacity > buf["capacity"]:
            buf.update(capacity=capacity, cand=cp.empty((capacity, _CAND_INTS), cp.int32), cand_len=cp.empty(capacity))
        if len(buf["moved"]) < 2 * capacity:
            buf["moved"] = cp.empty(2 * capacity, dtype=cp.int32)
        return buf

    def _device_lengths(self, state):
        """Squared threshold chords and new edge lengths per replica, on the device: cached with
        the State, so a new radius (``State.clear_cache``) or a resize renews them."""
        def build():
            import cupy as cp
            unit = np.sqrt(state.mean_cell_area)
            new = self.new_length * unit if self.length_factor is None else np.full(state.n_replicas, -1.0)
            return cp.asarray(self.chord_threshold2(state)), cp.asarray(new)
        return state.cached((self, "lengths"), build)

    def _host_totals(self, name, n_replicas):
        """A running total to continue on the device (zeros if it belongs to another State)."""
        total = getattr(self, name)
        return total.astype(np.uint64) if len(total) == n_replicas else np.zeros(n_replicas, np.uint64)

    def _detect(self, simulation, buf, crossed_only=False):
        """Zero the pass counters, list the short edges (t1_detect; with ``untangle`` also the crossed
        ones) and apply the refusal rules to them (t1_check, over the whole room: the count is read on
        the device); returns what t1_apply takes besides. ``crossed_only``: list the crossed edges
        alone (:meth:`untangle_pass`), the per-replica flip and refusal counts kept (added to)."""
        import cupy as cp
        state = simulation.state
        chord2, new_length = self._device_lengths(state)
        if crossed_only:           # no chord is shorter than 0: no short edge
            chord2 = state.cached((self, "no_chord"), lambda: cp.zeros(state.n_replicas))
        module, size = surface_kernels(_KERNELS, state)
        integrator = simulation.operations.integrator
        active = integrator.active_on_device() if integrator is not None else buf["all_active"]
        zeroed = buf["counters"] if crossed_only else buf["scratch"]
        cp.cuda.runtime.memsetAsync(zeroed.data.ptr, 0, zeroed.nbytes, cp.cuda.get_current_stream().ptr)
        launch(module.get_function("t1_detect"), state.n_vertices,
               (state.positions, state.vertex_neighbors, state.vertex_cells, state.vertex_replica, size, chord2,
                active, np.int32(self.untangle or crossed_only), np.int32(state.n_vertices), buf["counters"],
                buf["cand"], buf["cand_len"], np.int32(buf["capacity"]), buf["log_pass"]))
        launch(module.get_function("t1_check"), buf["capacity"],
               (state.positions, state.vertex_neighbors, state.cell_sides, state.cell_vertices, size, new_length,
                np.float64(self.length_factor or 0.0), np.int32(state.max_sides), buf["claim"], buf["refused"],
                buf["total_refused"], buf["counters"], buf["cand"], buf["cand_len"], np.int32(buf["capacity"]),
                buf["width"], np.int32(self.untangle)))
        return module, size, new_length

    def _apply(self, simulation, buf, module, size, new_length, n_slots, logging, in_graph):
        """t1_apply over ``n_slots`` candidate slots (it also gives the claimed cells back), then the
        integrator forgets the moved vertices. ``logging``: each flip goes into the flip log, with its
        pass (numbered on the device by t1_detect since the log was last replayed)."""
        state = simulation.state
        moved = buf["moved"][:2 * n_slots]
        launch(module.get_function("t1_apply"), n_slots,
               (state.positions, state.vertex_neighbors, state.vertex_cells, state.cell_vertices, state.cell_sides,
                buf["claim"], buf["cand"], buf["cand_len"], buf["counters"], np.int32(n_slots),
                np.int32(state.max_sides), size, new_length, np.float64(self.length_factor or 0.0), buf["flips"],
                buf["total_flips"], moved, buf["log_count"], buf["log"], np.int32(logging), buf["log_pass"],
                buf["width"], np.int32(in_graph)))
        integrator = simulation.operations.integrator
        if self.reset_velocities and integrator is not None:
            integrator.reset_vertices(moved)
        simulation.state_changed()

    def _update_gpu(self, simulation, crossed_only=False):
        """Detect and check, one small read-back (candidates, full rows, claimants), apply:
        see t1.cu. Returns whether a candidate claimed its cells (then at least one flipped).
        ``crossed_only``: the crossed edges alone (:meth:`_detect`).
        Inside a CUDA graph: no read-back, see :meth:`capture_ready`."""
        import cupy as cp
        state = simulation.state
        buf = self._gpu_buffers(state)
        if simulation.capturing:
            module, size, new_length = self._detect(simulation, buf)
            self._apply(simulation, buf, module, size, new_length, buf["capacity"], self.counting(simulation), True)
            return True
        if buf["width_host"] != state.max_sides:
            buf["width"].fill(state.max_sides)
            buf["width_host"] = state.max_sides
        kept = buf["refused"].copy() if crossed_only else 0   # the refusals before this pass
        while True:
            module, size, new_length = self._detect(simulation, buf, crossed_only)
            n_cand, widen, n_claim = (int(x) for x in buf["counters"].get())   # the one read-back
            if n_cand <= buf["capacity"]:
                break
            cap = 2 * n_cand   # rare: more candidates than room; undo this pass's claims, grow, redo
            buf["claim"].fill(np.iinfo(np.int32).max)
            buf["total_refused"] -= (buf["refused"] - kept).astype(cp.uint64)
            buf["refused"][...] = kept
            self._gpu_buffers(state, cap)
        if n_claim == 0:        # no candidate, or every one refused: nothing claimed, nothing flips
            return False
        if widen:
            pad = cp.full((state.n_cells, 1), -1, dtype=cp.int32)
            state.cell_vertices = cp.ascontiguousarray(cp.concatenate([state.cell_vertices, pad], axis=1))
            buf["width"].fill(state.max_sides)
            buf["width_host"] = state.max_sides
        counting = self.counting(simulation)
        if counting and buf["log_bound"] + n_claim > len(buf["log"]):   # the log might overflow: replay it first
            self._flush_log(state)
            if n_claim > len(buf["log"]):
                buf["log"] = cp.empty((2 * n_claim, _LOG_INTS), cp.int32)
        buf["log_bound"] += n_claim if counting else 0
        self._apply(simulation, buf, module, size, new_length, n_cand, counting, False)
        state.topology_version += 1
        return True

    # ------------------------------------------------------------------ CUDA graphs
    def capture_ready(self, simulation, steps):
        """Passes inside a CUDA graph read nothing back, so nothing may need to grow there: room for a
        candidate per edge, the cell table padded for the steps (:meth:`_padded_table`) and, with the
        flip-back bookkeeping (``counting``), the flip log replayed now if the steps' flips might
        not fit (a pass flips at most one edge per four cells)."""
        state = simulation.state
        buf = self._gpu_buffers(state, 3 * state.n_vertices // 2)
        log = None
        if self.counting(simulation):
            room = steps * (state.n_cells // 4)
            if buf["log_bound"] + room > len(buf["log"]):
                self._flush_log(state)
                if room > len(buf["log"]):
                    import cupy as cp
                    buf["log"] = cp.empty((2 * room, _LOG_INTS), cp.int32)
            buf["log_bound"] += room
            log = buf["log"].data.ptr
        return self._padded_table(state, buf, steps).data.ptr, log

    def _padded_table(self, state, buf, steps):
        """The cell table padded with ``steps`` spare columns (a cell gains at most one side per
        pass); the width the step-by-step path would give it is kept on the device (t1_apply grows
        it) and :meth:`capture_done` trims the table to it. The width is read back only when the
        bound ``width_bound`` (last known width plus the passes since) nears the table's edge."""
        import cupy as cp
        table = buf["table"]
        if table is not None and state.cell_vertices is table:
            if buf["width_bound"] + steps > table.shape[1]:       # the width may be near the edge: look
                buf["width_bound"] = int(buf["width"].get()[0])
            if buf["width_bound"] + steps <= table.shape[1]:
                buf["width_bound"] += steps
                return table
            self.capture_done(self._simulation)
        width = state.max_sides
        if table is None or table.shape[1] - width < steps:
            table = buf["table"] = cp.full((state.n_cells, width + steps + SPARE_COLUMNS), -1, dtype=cp.int32)
        table[:, :width] = state.cell_vertices
        state.cell_vertices = table
        buf["width"].fill(width)
        buf["width_bound"] = width + steps   # at most one more column per pass
        buf["width_host"] = -1               # the step-by-step path sets it again
        return table

    #: the fused stage's arguments (t1_stage.cuh)
    FUSED_ARGS = KernelStruct("T1StageArgs", [
        ("chord2", "const double*"), ("new_length", "const double*"), ("length_factor", "double"), ("cand", "int*"),
        ("cand_len", "double*"), ("flips", "int*"), ("refused", "int*"), ("total_flips", "unsigned long long*"),
        ("total_refused", "unsigned long long*"), ("log_count", "int*"), ("log", "int*"), ("logging", "int"),
        ("log_pass", "const int*"), ("reset_vertices", "int"), ("untangle", "int")])

    def fused_stage(self, simulation, minimizing):
        """t1_stage.cuh: the pass (after :meth:`capture_ready`, which made the candidate room and
        padded the cell table): squared threshold chords, new lengths, whether it untangles, the
        candidate room, the per-pass counters and totals, the flip log (with whether this pass logs,
        :meth:`counting`) and its pass count, and whether the integrator forgets the flipped
        vertices' motion; after each launch, ``t1_steps_finish`` advances the table's width and the log's pass count as
        t1_detect and t1_apply would have."""
        state = simulation.state
        buf = self._gpu_buffers(state, 3 * state.n_vertices // 2)
        chord2, new_length = self._device_lengths(state)
        values = dict(chord2=chord2, new_length=new_length, length_factor=self.length_factor or 0.0,
                      cand=buf["cand"], cand_len=buf["cand_len"], flips=buf["flips"], refused=buf["refused"],
                      total_flips=buf["total_flips"], total_refused=buf["total_refused"], log_count=buf["log_count"],
                      log=buf["log"], logging=int(self.counting(simulation)), log_pass=buf["log_pass"],
                      reset_vertices=int(self.reset_velocities), untangle=int(self.untangle))

        def finish(module, step_need, steps):
            module.get_function("t1_steps_finish")((1,), (1,), (buf["width"], step_need, np.int32(steps),
                                                                buf["log_pass"]))
        return FusedStage("pass", "T1Stage", '#include "plugins/updaters/t1_stage.cuh"', self.FUSED_ARGS, values,
                          finish=finish)

    def capture_done(self, simulation):
        """The cell table back to the width the step-by-step path would have (one small read-back)."""
        buf = getattr(self, "_gpu", None)
        state = simulation.state
        if buf is not None and buf["table"] is not None and state.cell_vertices is buf["table"]:
            import cupy as cp
            state.cell_vertices = cp.ascontiguousarray(buf["table"][:, :int(buf["width"].get()[0])])

    def _flush_log(self, state):
        """Replay the device's flip log (its passes at once) into the flip-back bookkeeping."""
        buf = getattr(self, "_gpu", None)
        if buf is None:
            return
        n = int(buf["log_count"].get()[0])
        buf["log_bound"] = 0
        buf["log_pass"].fill(0)       # passes are numbered from here
        if n == 0:
            return
        log = buf["log"][:n].get()
        buf["log_count"].fill(0)
        self._count_flip_backs(state, log[:, 1:5].astype(np.int64), log[:, 5], buf["n_cells"], passes=log[:, 0])

    def _replay_could_reach(self, limit) -> bool:
        """Whether replaying the flip log now could bring a replica's ``flip_backs`` from below
        ``limit`` to it. A flip re-joins one pair once, so not while the largest count below
        ``limit`` plus the flips logged since the last replay stays below it: then the log waits
        (a convergence check reads its count, not the log, and replays nothing). The same read
        renews the bounds of the log's rows and of the table's width, exact between launches."""
        buf = getattr(self, "_gpu", None)
        if buf is None:
            return False             # nothing logged on the device
        width, n = (int(x) for x in buf["words"].get())
        buf["log_bound"] = n
        if buf["table"] is not None and buf["state"].cell_vertices is buf["table"]:
            buf["width_bound"] = width
        below = self.flip_backs[self.flip_backs < limit]
        return n > 0 and int(below.max(initial=0)) + n >= limit

    def _sync_flip_backs(self):
        """Bring the flip-back counts up to date (the flip log replayed; halting needs no more)."""
        buf = getattr(self, "_gpu", None)
        if buf is not None:
            self._flush_log(buf["state"])

    def _sync_counters(self):
        """Bring the GPU counters to the host attributes (for logging, checkpoints, narrowing)."""
        self._sync_flip_backs()
        buf = getattr(self, "_gpu", None)
        if buf is None:
            return
        self.last_flips = buf["flips"].get().astype(np.int64)
        self.last_refused = buf["refused"].get().astype(np.int64)
        self.total_flips = buf["total_flips"].get().astype(np.int64)
        self.total_refused = buf["total_refused"].get().astype(np.int64)
