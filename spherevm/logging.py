"""Choosing what a writer logs: :class:`Logger`, after HOOMD-blue's ``hoomd.logging.Logger``.

HOOMD keys quantities by namespace tuples and categories; here a loggable is a flat name that the
Simulation knows (``Simulation.loggables``: its own and every attached operation's), and a Logger
is the ordered set of names a writer records, plus any custom quantities given as functions.
"""
from __future__ import annotations


class Logger:
    """An ordered set of loggable quantities, for ``GSD(..., logger=)`` and ``Table(..., logger=)``.

    >>> logger = Logger(["energy_per_cell", "mean_shape_index"])
    >>> logger.add(t1)                                   # every loggable of an operation (or a Simulation)
    >>> logger["mean_area"] = lambda sim: sim.state.mean_cell_area    # a custom quantity

    A custom quantity is a callable ``f(simulation)`` returning a scalar or one value per replica.
    Names are checked against the Simulation when a writer first uses the logger (:meth:`check`),
    since operations attached later add loggables.

    Parameters
    ----------
    quantities : sequence of str
        Loggable names (see ``Simulation.loggables``)."""

    def __init__(self, quantities=(), categories=None):
        """``quantities``: loggable names (a name or names). ``categories``: accepted for HOOMD-blue's
        ``Logger(categories=[...])`` when it includes ``"scalar"`` (every spherevm quantity is a
        scalar or one scalar per replica, so nothing is filtered); other categories are refused."""
        if categories is not None:
            given = [categories] if isinstance(categories, str) else list(categories)
            if "scalar" not in given:
                raise ValueError(f"Logger(categories={given!r}): spherevm logs scalars only (one per replica), so "
                                 "categories must include 'scalar', as HOOMD's Logger(categories=['scalar', "
                                 "'string']); per-cell values go in GSD(cell_quantities=...)")
        self._custom = {}
        self._names = []
        self.add(quantities=quantities)

    def add(self, obj=None, quantities=None):
        """Add quantities by name, or every loggable of an object.

        Parameters
        ----------
        obj : Operation or Simulation, optional
            Anything with a ``loggables`` mapping: all of them, or those named in ``quantities``.
        quantities : str or sequence of str, optional
            Names; with ``obj``, they must be ``obj``'s.

        Returns
        -------
        Logger
            ``self``."""
        names = [quantities] if isinstance(quantities, str) else list(quantities or ())
        if not all(isinstance(n, str) and n for n in names):
            raise ValueError(f"quantities must be loggable names (str), got {quantities!r}")
        if obj is not None:
            if not hasattr(obj, "loggables"):
                raise TypeError(f"Logger.add: {type(obj).__name__} has no loggables; pass an operation or a "
                                "Simulation, or names with quantities=")
            available = list(obj.loggables)
            missing = [n for n in names if n not in available]
            if missing:
                raise ValueError(f"Logger.add: {type(obj).__name__} has no loggable(s) {missing}; it has "
                                 f"{sorted(available)}")
            names = names or available
        for name in names:
            if name not in self._names:
                self._names.append(name)
        return self

    def __setitem__(self, name, function):
        if not isinstance(name, str) or not name:
            raise ValueError(f"a custom quantity's name must be a non-empty str, got {name!r}")
        if not callable(function):
            raise TypeError(f"custom quantity {name!r}: expected a callable f(simulation), got "
                            f"{type(function).__name__}")
        self._custom[name] = function
        if name not in self._names:
            self._names.append(name)

    def remove(self, name):
        """Stop logging ``name``."""
        if name not in self._names:
            raise KeyError(f"{name!r} is not logged; logged: {self._names}")
        self._names.remove(name)
        self._custom.pop(name, None)

    __delitem__ = remove

    @property
    def names(self) -> tuple:
        """The logged names, in the order they were added."""
        return tuple(self._names)

    def __iter__(self):
        return iter(self._names)

    def __len__(self):
        return len(self._names)

    def __contains__(self, name):
        return name in self._names

    def check(self, simulation, who="Logger"):
        """Raise ValueError naming every logged name that is neither custom nor one of
        ``simulation.loggables`` (``who`` names the writer in the message)."""
        known = simulation.loggables
        clash = [n for n in self._custom if n in known]
        if clash:
            raise ValueError(f"{who}: custom quantity {clash} has the name of a loggable of the Simulation; "
                             "give it another name")
        unknown = [n for n in self._names if n not in known and n not in self._custom]
        if unknown:
            raise ValueError(f"{who}: unknown loggable(s) {unknown}; available: {sorted(known)}")

    def log(self, simulation) -> dict:
        """``{name: value}`` now, in order: each value as ``simulation.log`` or the custom function
        returns it (a scalar or one value per replica)."""
        return {n: self._custom[n](simulation) if n in self._custom else simulation.log(n) for n in self._names}

    def __repr__(self):
        return f"Logger({list(self._names)!r})"
