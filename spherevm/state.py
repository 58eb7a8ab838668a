"""State: every array of one or many tissues (replicas), struct of arrays, on one device."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import topology
from .device import CPU, resolve


@dataclass(frozen=True)
class ReplicaSelection:
    """Some replicas of a State, in order, with the global indices of their vertices and cells
    (NumPy int64): what :meth:`State.select` keeps and :meth:`State.write_back` restores."""
    replicas: np.ndarray
    vertices: np.ndarray
    cells: np.ndarray


class State:
    """Vertex positions and the trivalent cell network of one or more replicas.

    Replicas are independent tissues stored back to back: replica ``r`` owns vertices
    ``vertex_start[r]:vertex_start[r+1]`` and cells ``cell_start[r]:cell_start[r+1]``; all indices are
    global. Each replica lives on its own surface. See :mod:`spherevm.topology` for the orientation
    rules. States usually come from :mod:`spherevm.init`.

    Parameters
    ----------
    positions : array (V, 3) of float64
        On the surface.
    cell_vertices, cell_sides : array (C, max_sides), (C,) of int32
        Each cell's vertices, counter-clockwise seen from outside, padded with -1; its side count.
    vertex_neighbors, vertex_cells : array (V, 3) of int32
        Each vertex's three neighbours and three cells, counter-clockwise.
    vertex_start, cell_start : array (R + 1,)
        Where each replica's vertices and cells start.
    size : array, ``(R,) + constraint.size_shape``, optional
        Each replica's surface size (:attr:`~spherevm.constraints.Constraint.size_names`), or one
        size for all replicas.
    constraint : Constraint, optional
        The surface (default :class:`~spherevm.constraints.Sphere`).
    device : Device or str
        Where the arrays live.
    validate : bool
        Check the network (:func:`spherevm.topology.check`); call :meth:`validate` again after
        editing arrays by hand.
    radius, box : optional
        The size under the name of its :attr:`~spherevm.constraints.Constraint.size_key`, instead
        of ``size``: a sphere's radius per replica (or one), a periodic plane's (Lx, Ly)."""

    def __init__(self, positions, cell_vertices, cell_sides, vertex_neighbors, vertex_cells,
                 vertex_start, cell_start, radius=None, constraint=None, device=CPU, validate=True, box=None,
                 size=None):
        from .constraints import Sphere
        self.device = resolve(device)
        self.constraint = constraint if constraint is not None else Sphere()
        xp = self.device.xp
        self.vertex_start = np.asarray(vertex_start, dtype=np.int64)
        n_rep = max(len(self.vertex_start) - 1, 1)      # the layout itself is checked by _derive_layout
        self.positions = xp.asarray(positions, dtype=xp.float64)
        self.cell_vertices = xp.asarray(cell_vertices, dtype=xp.int32)
        self.cell_sides = xp.asarray(cell_sides, dtype=xp.int32)
        self.vertex_neighbors = xp.asarray(vertex_neighbors, dtype=xp.int32)
        self.vertex_cells = xp.asarray(vertex_cells, dtype=xp.int32)
        self.cell_start = np.asarray(cell_start, dtype=np.int64)
        self.size = xp.asarray(self._per_replica(n_rep, size=size, radius=radius, box=box))
        self.topology_version = 0   # bumped by every topology edit (T1 flips): caches key on it
        self._cached = {}
        self._buffers = {}          # capacity of the arrays resize() refills (Device.fit)
        self._derive_layout()
        if validate:
            self.validate()

    def _per_replica(self, n_rep, **given):
        """The one size given (as ``size`` or under the constraint's ``size_key``) as a
        ``(n_rep, *size_shape)`` float64 NumPy array, or a ValueError naming the argument."""
        con = self.constraint
        key, shape, names = con.size_key, tuple(con.size_shape), ", ".join(con.size_names)
        passed = [k for k, v in given.items() if v is not None]
        wrong = [k for k in passed if k not in ("size", key)]
        if wrong:
            raise ValueError(f"{wrong[0]} is given, but a State on {con!r} needs {key} ({names} per replica), "
                             "the size its constraint declares")
        if len(passed) != 1:
            raise ValueError(f"a State on {con!r} needs {key} ({names} per replica) or size, given once; got "
                             f"{', '.join(f'{k}=given' for k in passed) or 'none'}")
        name = passed[0]
        value = np.asarray(self.device.to_numpy(given[name]), dtype=np.float64)
        if value.shape == shape or (value.shape[1:] == shape and value.ndim == len(shape) + 1
                                    and len(value) in (1, n_rep)):
            return np.broadcast_to(value, (n_rep,) + shape).copy()
        one = "a scalar" if shape == () else f"({names})"
        each = "one value" if shape == () else f"one ({names})"
        raise ValueError(f"{name} must be {one} or {each} per replica ({n_rep} replicas), got shape {value.shape}")

    # ------------------------------------------------------------------ layout
    def _derive_layout(self):
        vs, cs = self.vertex_start, self.cell_start
        if vs.ndim != 1 or cs.shape != vs.shape or len(vs) < 2:
            raise ValueError("vertex_start and cell_start must both have length n_replicas + 1 >= 2")
        if vs[0] != 0 or cs[0] != 0 or np.any(np.diff(vs) <= 0) or np.any(np.diff(cs) <= 0):
            raise ValueError("vertex_start and cell_start must start at 0 and increase strictly")
        if vs[-1] != len(self.positions) or cs[-1] != len(self.cell_sides):
            raise ValueError(f"replica layout covers {vs[-1]} vertices and {cs[-1]} cells, "
                             f"but the arrays hold {len(self.positions)} and {len(self.cell_sides)}")
        self.constraint.check_size(self.size_np())
        self._vertex_replica = np.repeat(np.arange(self.n_replicas, dtype=np.int32), np.diff(vs))
        self._cell_replica = np.repeat(np.arange(self.n_replicas, dtype=np.int32), np.diff(cs))
        self._refill("vertex_replica", self._vertex_replica, np.int32)
        self._refill("cell_replica", self._cell_replica, np.int32)

    def _refill(self, name, data, dtype):
        """Set array ``name`` to ``data`` through its capacity buffer (see :meth:`resize`)."""
        self._buffers[name], view = self.device.fit(self._buffers.get(name), data, dtype)
        setattr(self, name, view)

    def vertex_replica_np(self):
        return self._vertex_replica

    def cell_replica_np(self):
        return self._cell_replica

    @property
    def size(self):
        """Each replica's surface size on the device, ``(n_replicas, *constraint.size_shape)``
        (a sphere's radius, a periodic plane's (Lx, Ly)). Assign a new array to change it
        (RadiusSchedule does): the host copy :meth:`size_np` follows assignments, not edits in place."""
        return self._size

    @size.setter
    def size(self, value):
        self._size, self._size_host = value, None

    def size_np(self):
        """The size as a NumPy array: a host copy kept from the last assignment, so reading it every
        step costs no device-to-host transfer."""
        if self._size_host is None:
            self._size_host = np.asarray(self.device.to_numpy(self._size))
        return self._size_host.copy()

    def _views(key, what):        # called in the class body: builds two members
        """``state.<key>`` and ``state.<key>_np()``: :attr:`size` (and :meth:`size_np`) where the
        constraint's ``size_key`` is ``key``, else None."""
        def get(self):
            return self._size if self.constraint.size_key == key else None

        def put(self, value):
            if self.constraint.size_key != key:
                raise ValueError(f"{self.constraint!r} has no {key}: its size is {self.constraint.size_key} "
                                 f"({', '.join(self.constraint.size_names)}); assign state.size")
            self.size = value

        def host(self):
            return self.size_np() if self.constraint.size_key == key else None

        host.__doc__ = f":meth:`size_np` where the size is {what}, else None."
        return property(get, put, doc=f":attr:`size` where it is {what}, else None (assigning sets :attr:`size`)."), host

    radius, radius_np = _views("radius", "a radius per replica (a sphere)")
    box, box_np = _views("box", "a box (Lx, Ly) per replica (a periodic plane)")
    del _views

    @property
    def n_vertices(self) -> int:
        return int(self.positions.shape[0])

    @property
    def n_cells(self) -> int:
        return int(self.cell_sides.shape[0])

    @property
    def n_replicas(self) -> int:
        return len(self.vertex_start) - 1

    @property
    def max_sides(self) -> int:
        return int(self.cell_vertices.shape[1])

    @property
    def cells_per_replica(self):
        return np.diff(self.cell_start)

    @property
    def vertices_per_replica(self):
        return np.diff(self.vertex_start)

    @property
    def mean_cell_area(self):
        """<A> per replica: total surface area over the number of cells."""
        return self.constraint.total_area_np(self.size_np()) / self.cells_per_replica

    def cached(self, key, build, topology: bool = False):
        """``build()``, computed once and kept with this State under ``key`` (recomputed after a
        topology edit if ``topology``): the one place constraints and operations keep derived data
        (device copies of parameters, corner maps, edge lists). Keys start with the owner object,
        e.g. ``(self, "edges")``; the data dies with the State. An owner with a
        ``parameter_version`` (an operation, :mod:`spherevm.plugins.parameters`) has its entries
        rebuilt after each change of its parameters."""
        version = (self.topology_version if topology else None, getattr(key[0], "parameter_version", None))
        entry = self._cached.get(key)
        if entry is None or entry[0] != version:
            entry = self._cached[key] = (version, build())
        return entry[1]

    def topology_changed(self):
        """Call after editing the index arrays by hand: cached corner maps are rebuilt."""
        self.topology_version += 1

    def clear_cache(self):
        """Drop every :meth:`cached` entry (after a change that is not a topology edit, such as a
        new radius, that derived data may depend on)."""
        self._cached.clear()

    def resize(self, positions, cell_vertices, cell_sides, vertex_neighbors, vertex_cells, vertex_start, cell_start):
        """Replace the arrays by ones with other numbers of vertices and cells per replica (cells
        divided or removed, :mod:`spherevm.growth`; NumPy or device arrays), replicas back to back.

        Capacity: each array is refilled in place when its buffer has the rows, else moved to one
        of at least twice the old capacity (:meth:`spherevm.device.Device.fit`), so a growing
        tissue reallocates O(log N) times, not at every division. The arrays are then views of
        those buffers: copy one to keep it across a resize. ``topology_version`` bumps and every
        cached entry is dropped."""
        for name, data, dtype in (("positions", positions, np.float64), ("cell_vertices", cell_vertices, np.int32),
                                  ("cell_sides", cell_sides, np.int32), ("vertex_cells", vertex_cells, np.int32),
                                  ("vertex_neighbors", vertex_neighbors, np.int32)):
            self._refill(name, data, dtype)
        self.vertex_start = np.asarray(vertex_start, dtype=np.int64)
        self.cell_start = np.asarray(cell_start, dtype=np.int64)
        self._derive_layout()
        self.clear_cache()
        self.topology_changed()

    # ------------------------------------------------------------------ checks and copies
    def validate(self, tol: float = 1e-9, orientation: bool = True, cover: bool = True, simple: bool = True):
        """Raise ValueError naming the first offending cell or vertex if the network is invalid.

        ``tol`` is the allowed distance from the surface in units of R; ``orientation=False`` skips
        the positive-area test (cells may fold over at kA = 0); ``cover=False`` skips it and the
        total-area test (cells cover the surface once, none over a hemisphere); ``simple=False``
        skips the test for cells crossing themselves (docs/validation.md): see
        :func:`spherevm.topology.check`.
        """
        topology.check(self, tol=tol, orientation=orientation, cover=cover, simple=simple)
        return self

    def to(self, device) -> "State":
        """A copy of this State on another device.

        Parameters
        ----------
        device : {"cpu", "gpu", "auto"} or Device

        Returns
        -------
        State"""
        return State(**self.arrays_np(), constraint=self.constraint, device=device, validate=False)

    def copy(self) -> "State":
        """A copy of this State on the same device.

        Returns
        -------
        State"""
        return State(**self._arrays(), constraint=self.constraint, device=self.device, validate=False)

    def _arrays(self):
        return dict(positions=self.positions.copy(), cell_vertices=self.cell_vertices.copy(),
                    cell_sides=self.cell_sides.copy(), vertex_neighbors=self.vertex_neighbors.copy(),
                    vertex_cells=self.vertex_cells.copy(), vertex_start=self.vertex_start.copy(),
                    cell_start=self.cell_start.copy(), **{self.constraint.size_key: self.size.copy()})

    def arrays_np(self):
        """Every array of the State by its constructor's name, as NumPy copies (the size under its
        constraint's ``size_key``: ``radius``, ``box`` or ``size``)."""
        return {k: self.device.to_numpy(v) for k, v in self._arrays().items()}

    def replica(self, r: int) -> "State":
        """Replica ``r`` alone, as a new single-replica State with local indices."""
        if not 0 <= r < self.n_replicas:
            raise IndexError(f"replica must be in 0..{self.n_replicas - 1}, got {r}")
        part = self.select(self.selection([r]))
        width = max(int(part.device.to_numpy(part.cell_sides).max()), 3)
        part.cell_vertices = part.device.xp.ascontiguousarray(part.cell_vertices[:, :width])
        return part

    def selection(self, replicas) -> ReplicaSelection:
        """The :class:`ReplicaSelection` of the given replica indices (in that order)."""
        r = np.asarray(replicas, dtype=np.int64).reshape(-1)
        if len(r) == 0 or r.min() < 0 or r.max() >= self.n_replicas:
            raise IndexError(f"replicas must be a non-empty list of indices in 0..{self.n_replicas - 1}")

        def ranges(start):
            n = start[r + 1] - start[r]
            return np.repeat(start[r] - np.concatenate(([0], np.cumsum(n)[:-1])), n) + np.arange(n.sum())

        return ReplicaSelection(replicas=r, vertices=ranges(self.vertex_start), cells=ranges(self.cell_start))

    def select(self, selection: ReplicaSelection) -> "State":
        """A new State holding only the selected replicas, renumbered (same device, no validation).

        Parameters
        ----------
        selection : ReplicaSelection
            From :meth:`selection`.

        Returns
        -------
        State"""
        xp = self.device.xp
        v, c = xp.asarray(selection.vertices), xp.asarray(selection.cells)
        vmap = xp.full(self.n_vertices + 1, -1, dtype=xp.int64)   # old -> new; index -1 (padding) -> -1
        vmap[v] = xp.arange(len(selection.vertices))
        cmap = xp.full(self.n_cells, -1, dtype=xp.int64)
        cmap[c] = xp.arange(len(selection.cells))
        r = selection.replicas
        return State(self.positions[v], vmap[self.cell_vertices[c]], self.cell_sides[c], vmap[self.vertex_neighbors[v]],
                     cmap[self.vertex_cells[v]],
                     np.concatenate(([0], np.cumsum(self.vertex_start[r + 1] - self.vertex_start[r]))),
                     np.concatenate(([0], np.cumsum(self.cell_start[r + 1] - self.cell_start[r]))),
                     constraint=self.constraint, device=self.device, validate=False,
                     size=self.size_np()[r])

    def write_back(self, selection: ReplicaSelection, part: "State"):
        """Copy ``part`` back into this State's rows of its replicas.

        Parameters
        ----------
        selection : ReplicaSelection
            The selection ``part`` was made with (:meth:`select`).
        part : State
            The selected replicas, evolved since (T1 flips included)."""
        xp = self.device.xp
        v, c = xp.asarray(selection.vertices), xp.asarray(selection.cells)
        self.positions[v] = part.positions
        self.vertex_neighbors[v] = v[part.vertex_neighbors]
        self.vertex_cells[v] = c[part.vertex_cells]
        if part.max_sides > self.max_sides:    # T1 flips grew a cell beyond this table's width
            pad = xp.full((self.n_cells, part.max_sides - self.max_sides), -1, dtype=xp.int32)
            self.cell_vertices = xp.ascontiguousarray(xp.concatenate([self.cell_vertices, pad], axis=1))
        rows = xp.full((len(selection.cells), self.max_sides), -1, dtype=xp.int32)
        cv = part.cell_vertices
        rows[:, :part.max_sides] = xp.where(cv >= 0, v[xp.maximum(cv, 0)], -1)
        self.cell_vertices[c] = rows
        self.cell_sides[c] = part.cell_sides
        self.topology_changed()

    @classmethod
    def concatenate(cls, states, device=None) -> "State":
        """Stack single- or multi-replica States (same constraint type) into one ensemble.

        Parameters
        ----------
        states : sequence of State
        device : Device or str, optional
            Where the result lives (default: the first State's device).

        Returns
        -------
        State"""
        states = list(states)
        if not states:
            raise ValueError("states must hold at least one State")
        width = max(s.max_sides for s in states)
        kinds = {type(s.constraint).__name__ for s in states}
        if len(kinds) > 1:
            raise ValueError(f"states must share one constraint type to be concatenated, got {sorted(kinds)}")
        key = states[0].constraint.size_key
        parts = {k: [] for k in ("positions", "cell_vertices", "cell_sides", "vertex_neighbors",
                                 "vertex_cells", key)}
        vstart, cstart = [0], [0]
        for s in states:
            a = s.arrays_np()
            v0, c0 = vstart[-1], cstart[-1]
            cv = np.full((s.n_cells, width), -1, dtype=np.int32)
            cv[:, :s.max_sides] = np.where(a["cell_vertices"] >= 0, a["cell_vertices"] + v0, -1)
            parts["positions"].append(a["positions"])
            parts["cell_vertices"].append(cv)
            parts["cell_sides"].append(a["cell_sides"])
            parts["vertex_neighbors"].append(a["vertex_neighbors"] + v0)
            parts["vertex_cells"].append(a["vertex_cells"] + c0)
            parts[key].append(a[key])
            vstart.extend((s.vertex_start[1:] + v0).tolist())
            cstart.extend((s.cell_start[1:] + c0).tolist())
        return cls(**{k: np.concatenate(v) for k, v in parts.items()}, vertex_start=vstart,
                   cell_start=cstart, constraint=states[0].constraint,
                   device=device if device is not None else states[0].device, validate=False)

    def __repr__(self):
        return (f"State(n_replicas={self.n_replicas}, n_cells={self.n_cells}, n_vertices={self.n_vertices}, "
                f"max_sides={self.max_sides}, constraint={self.constraint!r}, device={self.device.name!r})")
