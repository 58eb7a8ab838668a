"""Triggers decide on which timesteps an operation runs (as in HOOMD-blue: a subclass implements
``compute(timestep)``, and the operation asks ``trigger(timestep)``)."""
from __future__ import annotations

import numpy as np

from .validation import integer


class Trigger:
    """Base class: a subclass implements ``compute(timestep) -> bool``, HOOMD-blue's name;
    ``trigger(timestep)`` calls it. (A subclass written for spherevm 0.1 that overrides
    ``__call__`` instead still works.) Combine with ``&``, ``|`` and ``~``."""

    def compute(self, timestep: int) -> bool:
        """Whether the operation runs on ``timestep``; a subclass implements it.

        Parameters
        ----------
        timestep : int

        Returns
        -------
        bool"""
        raise NotImplementedError(f"{type(self).__name__} must implement compute(timestep)")

    def __call__(self, timestep: int) -> bool:
        return bool(self.compute(timestep))

    def __and__(self, other):
        return And(self, other)

    def __or__(self, other):
        return Or(self, other)

    def __invert__(self):
        return Not(self)


class Periodic(Trigger):
    """Every ``period`` steps, on timesteps with ``(timestep - phase) % period == 0``.

    Parameters
    ----------
    period : int
        >= 1.
    phase : int
        >= 0."""

    def __init__(self, period: int, phase: int = 0):
        self.period = integer("period", period)
        if self.period < 1:
            raise ValueError(f"period must be >= 1, got {period!r}")
        self.phase = integer("phase", phase)

    def compute(self, timestep):
        return timestep >= self.phase and (timestep - self.phase) % self.period == 0

    def __repr__(self):
        return f"Periodic({self.period}, phase={self.phase})"


class On(Trigger):
    """Exactly on the given timestep.

    Parameters
    ----------
    timestep : int"""

    def __init__(self, timestep: int):
        self.timestep = integer("timestep", timestep)

    def compute(self, timestep):
        return timestep == self.timestep

    def __repr__(self):
        return f"On({self.timestep})"


class After(Trigger):
    """On every timestep strictly after the given one.

    Parameters
    ----------
    timestep : int"""

    def __init__(self, timestep: int):
        self.timestep = integer("timestep", timestep)

    def compute(self, timestep):
        return timestep > self.timestep

    def __repr__(self):
        return f"After({self.timestep})"


class Before(Trigger):
    """On every timestep strictly before the given one.

    Parameters
    ----------
    timestep : int"""

    def __init__(self, timestep: int):
        self.timestep = integer("timestep", timestep)

    def compute(self, timestep):
        return timestep < self.timestep

    def __repr__(self):
        return f"Before({self.timestep})"


def _trigger_list(name, triggers):
    """``And(a, b)`` or HOOMD's ``And([a, b])``: a tuple of one or more Triggers."""
    if len(triggers) == 1 and isinstance(triggers[0], (list, tuple)):
        triggers = tuple(triggers[0])
    if not triggers or not all(isinstance(t, Trigger) for t in triggers):
        raise ValueError(f"{name} needs one or more Trigger objects")
    return tuple(triggers)


class And(Trigger):
    """True when all the given triggers are."""

    def __init__(self, *triggers):
        self.triggers = _trigger_list("And", triggers)

    def compute(self, timestep):
        return all(t(timestep) for t in self.triggers)

    def __repr__(self):
        return f"And{self.triggers!r}"


class Or(Trigger):
    """True when any of the given triggers is."""

    def __init__(self, *triggers):
        self.triggers = _trigger_list("Or", triggers)

    def compute(self, timestep):
        return any(t(timestep) for t in self.triggers)

    def __repr__(self):
        return f"Or{self.triggers!r}"


class Not(Trigger):
    """True when the given trigger is not."""

    def __init__(self, trigger: Trigger):
        if not isinstance(trigger, Trigger):
            raise ValueError("Not needs a Trigger")
        self.trigger = trigger

    def compute(self, timestep):
        return not self.trigger(timestep)

    def __repr__(self):
        return f"Not({self.trigger!r})"


class OnTimesteps(Trigger):
    """True exactly on the given timesteps, e.g. log-spaced ones.

    Parameters
    ----------
    timesteps : iterable of int
        Non-negative."""

    def __init__(self, timesteps):
        arr = np.asarray(list(timesteps) if not isinstance(timesteps, np.ndarray) else timesteps)
        if arr.ndim != 1 or arr.size == 0:
            raise ValueError("timesteps must be a non-empty sequence of integers")
        if not np.all(np.isfinite(arr.astype(np.float64))) or np.any(arr != np.round(arr)) or np.any(arr < 0):
            raise ValueError(f"timesteps must be non-negative integers, got {timesteps!r}")
        self.timesteps = np.unique(arr.astype(np.int64))
        self._set = frozenset(int(t) for t in self.timesteps)

    def compute(self, timestep):
        return int(timestep) in self._set

    @property
    def last(self) -> int:
        return int(self.timesteps[-1])

    def __repr__(self):
        ts = self.timesteps
        shown = ", ".join(str(int(t)) for t in ts[:6]) + (", ..." if len(ts) > 6 else "")
        return f"OnTimesteps([{shown}] ({len(ts)} timesteps, last {self.last}))"


class Always(Trigger):
    """Every timestep."""

    def compute(self, timestep):
        return True

    def __repr__(self):
        return "Always()"


def as_trigger(value) -> Trigger:
    """A Trigger from a Trigger, an int period (``100`` means ``Periodic(100)``) or a sequence of
    timesteps (``OnTimesteps``)."""
    if isinstance(value, Trigger):
        return value
    if isinstance(value, (int, np.integer)) and not isinstance(value, bool):
        return Periodic(int(value))
    if isinstance(value, (list, tuple, np.ndarray, range)):
        return OnTimesteps(value)
    raise ValueError(f"trigger must be a spherevm.trigger.Trigger, a positive int period or a sequence of "
                     f"timesteps, got {value!r}")
