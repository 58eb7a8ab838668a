"""What a Simulation keeps about its runs outside the step loop: the wall clock behind
``Simulation.tps`` and ``walltime`` (HOOMD-blue's), and the one report of a restored checkpoint
whose saved operation states and the attached operations do not match (docs/file-format.md,
*Checkpoints*)."""
from __future__ import annotations

import functools
import time
import warnings


class CheckpointMismatchWarning(UserWarning):
    """A restored checkpoint's saved operation states and the Simulation's operations differ."""


class RunClock:
    """The wall clock of one ``run`` or ``minimize``: started when the call starts, stopped when it
    returns or raises."""

    def __init__(self, timestep: int):
        self.timestep, self.start, self.end = timestep, time.perf_counter(), None

    def walltime(self) -> float:
        """Seconds from the start to the end of the call (to now while it runs)."""
        return (time.perf_counter() if self.end is None else self.end) - self.start

    def tps(self, timestep: int) -> float:
        """Steps per second from the start of the call to ``timestep``."""
        seconds = self.walltime()
        return (timestep - self.timestep) / seconds if seconds > 0 else 0.0


class Restored:
    """What ``Simulation.create_state_from_gsd`` read: the file, the keys of the saved operation
    states, and the Simulation's dict of them not yet picked up (``pending``; a State set later
    replaces that dict, and then nothing of the file is left to report)."""

    def __init__(self, path, keys, pending: dict):
        self.path, self.keys, self.pending = str(path), frozenset(keys), pending

    def mismatch(self, pending: dict, keyed):
        """``(unclaimed, fresh)``: the keys of saved states no operation took (those left in
        ``pending``, the Simulation's dict now), and the keys of the operations (``keyed``: ``(key,
        operation)`` pairs) that keep state but found none saved, so started afresh."""
        if pending is not self.pending:
            return [], []
        fresh = [key for key, op in keyed if key not in self.keys and op.state_to_save()]
        return sorted(pending), fresh

    def report(self, pending: dict, keyed):
        """Warn (:class:`CheckpointMismatchWarning`) naming both lists of :meth:`mismatch`, if
        either is not empty."""
        unclaimed, fresh = self.mismatch(pending, keyed)
        parts = []
        if unclaimed:
            parts.append(f"saved state of {', '.join(unclaimed)} found no operation (kept for the next checkpoint)")
        if fresh:
            parts.append(f"{', '.join(fresh)} found no saved state and started fresh")
        if parts:
            warnings.warn(f"{self.path}: {'; '.join(parts)}. An operation takes its saved state by its key "
                          "(<list>.<position>.<ClassName>, or its name): attach the operations of the run that "
                          "wrote the file, in the same places, to continue it exactly", CheckpointMismatchWarning,
                          stacklevel=3)


class RunRecords:
    """A base of :class:`spherevm.Simulation`: ``tps`` and ``walltime`` of the current or last
    ``run`` or ``minimize`` (HOOMD-blue's ``Simulation.tps`` and ``walltime``), and the restore to
    report at the next one."""

    _clock = None      # the RunClock of the current or last call
    _restored = None   # the Restored of create_state_from_gsd, until the next call reports it

    @property
    def tps(self) -> float:
        """Steps per second of the current or last ``run`` or ``minimize`` (0 before the first)."""
        return 0.0 if self._clock is None else self._clock.tps(self.timestep)

    @property
    def walltime(self) -> float:
        """Seconds the current or last ``run`` or ``minimize`` took, so far while it runs (0 before
        the first)."""
        return 0.0 if self._clock is None else self._clock.walltime()


def stepping(method):
    """Decorate ``Simulation.run`` and ``minimize``: at the first call after a restore, report what
    the checkpoint and the operations did not match; time every call (``RunClock``)."""
    @functools.wraps(method)
    def wrapper(self, *args, **kwargs):     # self: the Simulation, whose run or minimize this is
        restored, self._restored = self._restored, None
        if restored is not None:
            restored.report(self._pending, self.operations.keyed())
        self._clock = clock = RunClock(self.timestep)
        try:
            return method(self, *args, **kwargs)
        finally:
            clock.end = time.perf_counter()
    return wrapper
