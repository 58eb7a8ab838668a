"""Parameters of an operation: checked on every assignment, and live after attach.

HOOMD-blue keeps an operation's parameters in a dictionary that validates what is set and passes a
change to the C++ object at once. Here an operation declares each public parameter as a class
attribute ``name = Parameter(check)``; then ``op.name = value``, in the constructor or at any time
later, goes through the same check, and a change after the operation attached takes effect at the
next step:

* the operation's ``parameter_version`` advances, which renews everything derived from its
  parameters: what it keeps with the State (:meth:`spherevm.state.State.cached` entries keyed by the
  operation), the CUDA graphs that hold its kernels' arguments, and the fused steps' arguments;
* its :meth:`~spherevm.plugins.base.Operation.parameters_changed` hook runs (FIRE, for example,
  puts the running replicas' step back to a new ``dt``);
* a parameter that cannot change once attached (``fixed``: a writer's file name) is refused with a
  message saying what to do instead.

A user's plugin declares its parameters the same way and gets the same guarantees.
"""
from __future__ import annotations

import functools

_MISSING = object()


class Parameter:
    """A public parameter of an :class:`~spherevm.plugins.base.Operation` (a data descriptor).

    Parameters
    ----------
    check : callable, optional
        ``check(name, value) -> value``: validates a new value (raising ValueError that names the
        parameter and its allowed range) and returns what is stored; None stores the value as given.
    fixed : str, optional
        Refuse assignments once the operation is attached; the string says what to do instead.
    """

    def __init__(self, check=None, fixed=None):
        self.check = check
        self.fixed = fixed
        self.name = None

    def __set_name__(self, owner, name):
        self.name = name

    def __get__(self, obj, owner=None):
        if obj is None:
            return self
        try:
            return obj.__dict__[self.name]
        except KeyError:
            raise AttributeError(f"{type(obj).__name__}.{self.name} is not set yet") from None

    def __set__(self, obj, value):
        attached = obj.__dict__.get("_simulation") is not None
        if self.fixed is not None and attached:
            raise AttributeError(f"{type(obj).__name__}.{self.name} cannot change once the operation is attached; "
                                 f"{self.fixed}")
        if self.check is not None:
            value = self.check(self.name, value)
        old = obj.__dict__.get(self.name, _MISSING)
        obj.__dict__[self.name] = value
        if not all(name in obj.__dict__ for name in parameter_names(type(obj))):
            return                           # still in the constructor: the rest is not set yet
        try:
            obj.check_parameters()
        except ValueError as exc:
            if old is _MISSING:
                del obj.__dict__[self.name]
            else:
                obj.__dict__[self.name] = old
            raise ValueError(f"{type(obj).__name__}.{self.name} = {value!r} refused: {exc}") from None
        obj.__dict__["parameter_version"] = obj.parameter_version + 1
        obj.parameters_changed(self.name)


@functools.lru_cache(maxsize=None)
def parameter_names(cls) -> tuple:
    """The names of the :class:`Parameter` attributes of an operation class, in declaration order
    (base classes first)."""
    names = []
    for klass in reversed(cls.__mro__):
        for name, value in vars(klass).items():
            if isinstance(value, Parameter) and name not in names:
                names.append(name)
    return tuple(names)
