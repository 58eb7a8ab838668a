"""The operations of a Simulation: forces, one integrator, updaters and writers, kept in lists that
type-check and attach what joins them."""
from __future__ import annotations

from collections.abc import MutableSequence

from .plugins.base import Force, Integrator, Updater, Writer


class Operations:
    """The operations of a Simulation: forces, one integrator, updaters and writers.

    Order inside a step: updaters, force computation, integrator, writers. ``sim.operations += op``
    (or :meth:`add`) puts an operation where its kind goes, as in HOOMD-blue; ``-=`` (:meth:`remove`)
    takes it out.
    """

    def __init__(self, simulation):
        self._sim = simulation
        self.forces = _OperationList(simulation, Force)
        self.updaters = _OperationList(simulation, Updater)
        self.writers = _OperationList(simulation, Writer)
        self._integrator = None

    @property
    def integrator(self):
        return self._integrator

    @integrator.setter
    def integrator(self, value):
        if value is not None and not isinstance(value, Integrator):
            raise TypeError(f"integrator must be a spherevm.plugins.Integrator, got {type(value).__name__}")
        if value is not None and self._sim.state is not None:
            value.attach(self._sim)             # a refused integrator leaves the old one in place
            self._sim.restore_saved_state(value, "integrator")
        if self._integrator is not None:
            self._integrator.detach()
        self._integrator = value

    def add(self, op):
        """Add ``op`` where its kind goes (HOOMD-blue's ``Operations.add``): a Force to ``forces``, an
        Updater to ``updaters``, a Writer to ``writers``; an Integrator becomes ``integrator``
        (replacing the one there)."""
        if isinstance(op, Integrator):
            self.integrator = op
        else:
            self._list_of(op, "add").append(op)

    def remove(self, op):
        """Take ``op`` out of the Simulation (HOOMD-blue's ``Operations.remove``); ValueError if it is
        not there."""
        ops = [self._integrator] if isinstance(op, Integrator) else self._list_of(op, "remove")
        where = next((i for i, other in enumerate(ops) if other is op), None)
        if where is None:
            raise ValueError(f"this {type(op).__name__} is not in sim.operations")
        if isinstance(op, Integrator):
            self.integrator = None
        else:
            del ops[where]

    def __iadd__(self, op):
        """``sim.operations += op``: :meth:`add`."""
        self.add(op)
        return self

    def __isub__(self, op):
        """``sim.operations -= op``: :meth:`remove`."""
        self.remove(op)
        return self

    def __contains__(self, op):
        return any(other is op for other in self)

    def _list_of(self, op, verb):
        for kind, ops in ((Force, self.forces), (Updater, self.updaters), (Writer, self.writers)):
            if isinstance(op, kind):
                return ops
        raise TypeError(f"sim.operations.{verb}: expected a spherevm.plugins Force, Integrator, Updater or Writer, "
                        f"got {type(op).__name__}")

    def __iter__(self):
        yield from self.updaters
        yield from self.forces
        if self._integrator is not None:
            yield self._integrator
        yield from self.writers

    def keyed(self):
        """``(checkpoint key, operation)`` for every operation (see ``Operation.checkpoint_key``)."""
        for kind in ("updaters", "forces"):
            for i, op in enumerate(getattr(self, kind)):
                yield op.checkpoint_key(f"{kind}.{i}"), op
        if self._integrator is not None:
            yield self._integrator.checkpoint_key("integrator"), self._integrator
        for i, op in enumerate(self.writers):
            yield op.checkpoint_key(f"writers.{i}"), op


class _OperationList(MutableSequence):
    """A list of operations of one kind: every mutation (append, insert, ``+=``, slice and item
    assignment) type-checks the operations and attaches them; removal detaches."""

    def __init__(self, simulation, kind):
        self._sim, self._kind, self._items = simulation, kind, []

    def _check(self, op):
        if not isinstance(op, self._kind):
            raise TypeError(f"expected a spherevm.plugins.{self._kind.__name__}, got {type(op).__name__}")
        return op

    def _attach(self, ops, start=0):
        if self._sim.state is not None:
            kind = next(k for k in ("forces", "updaters", "writers")
                        if getattr(self._sim.operations, k, None) is self)
            for i, op in enumerate(ops):
                op.attach(self._sim)
                self._sim.restore_saved_state(op, f"{kind}.{start + i}")

    def __getitem__(self, i):
        return self._items[i]

    def __len__(self):
        return len(self._items)

    def __setitem__(self, i, value):
        new = [self._check(op) for op in value] if isinstance(i, slice) else [self._check(value)]
        start = range(len(self._items))[i][0] if isinstance(i, slice) and range(len(self._items))[i] \
            else (i % max(len(self._items), 1) if not isinstance(i, slice) else len(self._items))
        self._attach(new, start)                # a refused operation never joins the list
        old = self._items[i] if isinstance(i, slice) else [self._items[i]]
        self._items[i] = new if isinstance(i, slice) else value
        for op in old:
            if not any(op is n for n in new):
                op.detach()

    def __delitem__(self, i):
        old = self._items[i] if isinstance(i, slice) else [self._items[i]]
        del self._items[i]
        for op in old:
            op.detach()

    def insert(self, i, op):
        n = len(self._items)
        self._attach([self._check(op)], min(max(i if i >= 0 else n + i, 0), n))
        self._items.insert(i, op)

    def __eq__(self, other):
        return list(self) == list(other)

    def __repr__(self):
        return repr(self._items)
