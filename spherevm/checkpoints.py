"""Checkpoints of a Simulation: what a frame holds besides the State, and restoring it exactly
(every operation's saved state handed over when it attaches; docs/file-format.md, *Checkpoints*)."""
from __future__ import annotations

import os

import numpy as np

from .runs import Restored


class Checkpoints:
    """The checkpoint half of :class:`spherevm.Simulation` (a base class of it: it reads and sets
    the Simulation's own fields)."""

    def restore_saved_state(self, op, where, keyed=False):
        """Hand ``op`` (just attached) its saved state from the checkpoint, if there is one.

        Parameters
        ----------
        op : spherevm.plugins.Operation
            The operation that just attached.
        where : str
            Its place (``"integrator"``, ``"forces.0"``, ...), or its checkpoint key if ``keyed``.
        """
        key = where if keyed else op.checkpoint_key(where)
        data = self._pending.pop(key, None)
        if data is not None:
            op.restore_state(data)

    def create_state_from_gsd(self, path, frame: int = -1, validate: bool = True):
        """Set the State, the timestep and every operation's saved state (now or when it attaches)
        from a GSD frame, exactly: running on is bitwise the uninterrupted run (docs/file-format.md).

        Parameters
        ----------
        path : str or path
        frame : int
            Frame index, negative from the end.
        validate : bool
            Check the stored network (:func:`spherevm.gsdio.read_state`)."""
        from . import gsdio
        with gsdio.Reader(path) as reader:
            state = reader.state(frame, device=self.device, validate=validate)
            step = reader.step(frame)
            saved = reader.checkpoint(frame)
        sim = saved.pop("simulation", {})
        if "seed" in sim and int(sim["seed"][0]) != self.seed:
            import warnings
            warnings.warn(f"{path}: the checkpoint was written by a Simulation with seed={int(sim['seed'][0])}, "
                          f"this one has seed={self.seed}; the random numbers will differ from the original run",
                          stacklevel=2)
        updated = int(sim["updated_at"][0]) if "updated_at" in sim else -1
        held = bool(sim["held_back"][0]) if "held_back" in sim else False
        self.timestep = step
        self.restored_from = (os.path.realpath(path), step)   # a GSD writer into this file appends
        self._set_state(state, pending=saved.get("op", {}), updated_at=None if updated < 0 else updated,
                        held_back=held)
        self._restored = Restored(path, saved.get("op", {}), self._pending)   # reported at the next run

    def checkpoint(self) -> dict:
        """What a checkpoint frame holds besides the State: ``op/<key>/<field>`` for every operation's
        :meth:`~spherevm.plugins.base.Operation.state_to_save`, ``simulation/<field>`` for the Simulation's.

        Returns
        -------
        dict"""
        out = {"simulation/seed": np.array([self.seed], dtype=np.int64),
               "simulation/updated_at": np.array([-1 if self._updated_at is None else self._updated_at],
                                                 dtype=np.int64),
               "simulation/held_back": np.array([int(self._held_back)], dtype=np.int64)}
        for key, op in self.operations.keyed():
            for field_name, value in op.state_to_save().items():
                out[f"op/{key}/{field_name}"] = value
        for key, data in self._pending.items():   # not picked up yet: keep it for a later restart
            for field_name, value in data.items():
                out.setdefault(f"op/{key}/{field_name}", value)
        return out
