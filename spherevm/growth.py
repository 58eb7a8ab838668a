"""Cell division and T2 extrusion: table surgery that changes the numbers of cells and vertices.

Pure network editing on the host (NumPy), one cell at a time in the order given, then one relayout
of the whole State (:func:`apply`): new vertices and cells go at the end of their own replica,
removed ones are dropped, replicas stay back to back, every index is renumbered, the vertex tables
are rebuilt from the cell table (:func:`spherevm.topology.build_vertex_tables`) and the State's
arrays are replaced (:meth:`spherevm.state.State.resize`: a plain reallocation, no spare capacity;
``topology_version`` bumps and every cached entry is dropped).

**Division** of a cell: its centre is the centroid of its vertices (unwrapped about its first
vertex) projected on the surface; the cut is the curve through the centre whose tangent-plane
normal is ``m`` (on the sphere the great circle of plane normal ``m``, on the plane the straight
line), so a vertex lies on the ``+`` or ``-`` side by the sign of ``m . (x - centre)``. The cut
crosses two edges; a new vertex is put on each, exactly where the cut meets it (the edge's
geodesic, so no cell changes area), and one new edge joins them. The mother keeps the ``+`` half,
the daughter (a new cell at the end of the replica) the ``-`` half. Refused (the cell left as it
is, the reason counted): a cut within ``1e-9`` cell sizes of a vertex (``"through_vertex"``: the
vertex would become four-fold, or a triangle would give a two-sided daughter) and a cut crossing
the boundary other than twice (``"crossings"``: a folded or strongly non-convex cell).

**Extrusion (T2)** of a triangle: its three vertices merge into one at their centroid, joining the
three neighbours, which lose a side each; the triangle disappears. Refused: a cell with more than
three sides (``"not_triangle"``: it must first lose sides by T1s), a neighbour with three sides
or neighbours that are not three distinct cells (``"neighbours"``: a two-sided cell would
result), and a neighbour that would fold (``"fold"``: non-positive signed area afterwards).

Both keep trivalence, counter-clockwise order, V - E + F (2 on the sphere, 0 on the periodic
plane) and the total area (a division changes no area; after a T2 the neighbours share the
triangle's area).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import topology

DIVISION_REASONS = ("through_vertex", "crossings", "neighbours")
EXTRUSION_REASONS = ("not_triangle", "neighbours", "fold")
DEGENERATE = 1e-9


@dataclass
class Change:
    """How the rows of a State changed: what :meth:`spherevm.plugins.base.Operation.resized` gets.

    ``vertex_source[i]``: the old index of new vertex ``i``, -1 for a created vertex;
    ``cell_source[j]``: the old index of new cell ``j``; for a daughter, its mother's old index
    (``new_cells[j]`` is True); ``vertex_map`` / ``cell_map``: old index -> new index, -1 if removed;
    ``moved``: new indices of vertices created or moved (their dynamical memory is stale).
    """
    vertex_source: np.ndarray
    cell_source: np.ndarray
    new_cells: np.ndarray
    vertex_map: np.ndarray
    cell_map: np.ndarray
    moved: np.ndarray

    @property
    def n_vertices_before(self):
        return len(self.vertex_map)

    @property
    def n_cells_before(self):
        return len(self.cell_map)


class Editor:
    """A host copy of a State's network that cells are divided in and extruded from, one at a time.

    Rows edited are kept as lists; :meth:`finish` builds the new arrays. Indices stay the old ones
    while editing; created vertices and cells take indices past the old ends.
    """

    def __init__(self, state):
        dev = state.device
        self.constraint = state.constraint
        self.size = self.constraint.size_np(state)
        self.table = dev.to_numpy(state.cell_vertices)
        self.sides = dev.to_numpy(state.cell_sides)
        self.vcells = dev.to_numpy(state.vertex_cells)
        self.pos = np.array(dev.to_numpy(state.positions), dtype=np.float64)
        self.vrep = list(state.vertex_replica_np())
        self.crep = list(state.cell_replica_np())
        self.n_v0, self.n_c0 = len(self.pos), len(self.sides)
        self.n_replicas = state.n_replicas
        self.rows, self.cells_of = {}, {}      # edited cell rows, edited vertex -> cells
        self.new_pos, self.parent = [], []
        self.dead_v, self.dead_c, self.moved = set(), set(), set()

    # ------------------------------------------------------------------ access
    def row(self, c):
        if c in self.rows:
            return list(self.rows[c])
        return self.table[c, :self.sides[c]].tolist()

    def cells(self, v):
        return list(self.cells_of[v]) if v in self.cells_of else self.vcells[v].tolist()

    def point(self, v):
        return self.pos[v] if v < self.n_v0 else self.new_pos[v - self.n_v0]

    def _size(self, c):
        return self.size[self.crep[c]]

    def _unwrapped(self, c, verts):
        points = np.array([self.point(v) for v in verts])
        return self.constraint.unwrap(points, points[:1], self._size(c)[None])

    def _across(self, c, a, b):
        """The cell other than ``c`` holding both ``a`` and ``b`` (None unless exactly one)."""
        common = (set(self.cells(a)) & set(self.cells(b))) - {c}
        return common.pop() if len(common) == 1 else None

    def _add_vertex(self, x, rep):
        self.new_pos.append(x)
        self.vrep.append(rep)
        v = self.n_v0 + len(self.new_pos) - 1
        self.moved.add(v)
        return v

    def centre(self, c):
        """Centre of cell ``c`` (vertex centroid on the surface, near its first vertex), its normal,
        and the unwrapped vertices."""
        q = self._unwrapped(c, self.row(c))
        size = self._size(c)
        cen = self.constraint.project_normal(q.mean(axis=0)[None], size[None])
        cen = self.constraint.unwrap(cen, q[:1], size[None])[0]
        return cen, self.constraint.normal(cen[None], size[None])[0], q

    # ------------------------------------------------------------------ division
    def divide(self, c, m):
        """Divide cell ``c`` by the cut of tangent normal ``m`` (3-vector, tangent at the centre).
        Returns the daughter's index or a refusal reason (a string)."""
        verts = self.row(c)
        cen, _, q = self.centre(c)
        s = (q - cen) @ m
        scale = np.sqrt(((q - cen) ** 2).sum(axis=1)).max()
        if np.any(np.abs(s) <= DEGENERATE * scale):
            return "through_vertex"
        k = len(verts)
        pos_side = s > 0
        change = np.flatnonzero(pos_side != np.roll(pos_side, -1))
        if len(change) != 2:
            return "crossings"
        i, j = (change[0], change[1]) if pos_side[change[0]] else (change[1], change[0])
        i1, j1 = (i + 1) % k, (j + 1) % k          # + to - across edge (i, i1); - to + across (j, j1)
        n1, n2 = self._across(c, verts[i], verts[i1]), self._across(c, verts[j], verts[j1])
        if n1 is None or n2 is None:
            return "neighbours"
        rep, size = self.crep[c], self._size(c)

        def cut_point(a, b):
            t = s[a] / (s[a] - s[b])
            x = q[a] + t * (q[b] - q[a])
            return self.constraint.project_normal(x[None], size[None])[0]

        x1 = self._add_vertex(cut_point(i, i1), rep)
        x2 = self._add_vertex(cut_point(j, j1), rep)
        d = self.n_c0 + len(self.parent)
        self.parent.append(c)
        self.crep.append(rep)
        walk = lambda a, b: [verts[(a + t) % k] for t in range((b - a) % k + 1)]   # noqa: E731
        plus, minus = walk(j1, i), walk(i1, j)
        self.rows[c] = plus + [x1, x2]
        self.rows[d] = minus + [x2, x1]
        for nb, a, b, x in ((n1, verts[i1], verts[i], x1), (n2, verts[j1], verts[j], x2)):
            row = self.row(nb)
            p = next(t for t in range(len(row)) if row[t] == a and row[(t + 1) % len(row)] == b)
            self.rows[nb] = row[:p + 1] + [x] + row[p + 1:]
        for v in minus:
            self.cells_of[v] = [d if w == c else w for w in self.cells(v)]
        self.cells_of[x1], self.cells_of[x2] = [c, d, n1], [c, d, n2]
        return d

    def long_axis(self, c):
        """Unit tangent vector of the long axis of cell ``c``: the eigenvector of the largest
        eigenvalue of its vertex gyration tensor in the tangent plane at its centre."""
        cen, n, q = self.centre(c)
        e1, e2 = tangent_basis(n)
        r = q - cen
        a, b = r @ e1, r @ e2
        g = np.array([[a @ a, a @ b], [a @ b, b @ b]]) / len(r)
        w, vec = np.linalg.eigh(g)
        return vec[0, 1] * e1 + vec[1, 1] * e2

    def tangent(self, c, direction):
        """``direction`` projected on the tangent plane at the centre of ``c`` and normalised."""
        cen, n, _ = self.centre(c)
        t = np.asarray(direction, dtype=np.float64) - (np.asarray(direction) @ n) * n
        norm = np.linalg.norm(t)
        if not norm > 0:
            raise ValueError(f"axis of cell {c} is normal to the surface (or zero): give a tangent direction")
        return t / norm

    def angle_axis(self, c, angle):
        _, n, _ = self.centre(c)
        e1, e2 = tangent_basis(n)
        return np.cos(angle) * e1 + np.sin(angle) * e2

    # ------------------------------------------------------------------ extrusion
    def extrude(self, c):
        """Merge triangle ``c`` into one vertex. Returns the merged vertex or a refusal reason."""
        verts = self.row(c)
        if len(verts) != 3:
            return "not_triangle"
        across = [self._across(c, verts[t], verts[(t + 1) % 3]) for t in range(3)]
        if any(x is None for x in across) or len(set(across)) != 3 or any(len(self.row(x)) <= 3 for x in across):
            return "neighbours"
        q = self._unwrapped(c, verts)
        size = self._size(c)
        m = self.constraint.project_normal(q.mean(axis=0)[None], size[None])[0]
        keep, gone = verts[0], set(verts)
        new_rows = {}
        for x in across:
            row = [keep if v in gone else v for v in self.row(x)]
            row = [v for t, v in enumerate(row) if v != row[t - 1]]     # collapse the repeated keep
            new_rows[x] = row
        old = self.point(keep).copy()
        self._set_point(keep, m)
        if any(self.signed_area(x, r) <= 0 for x, r in new_rows.items()):
            self._set_point(keep, old)
            return "fold"
        self.rows.update(new_rows)
        self.cells_of[keep] = across
        self.dead_c.add(c)
        self.dead_v.update(gone - {keep})
        self.moved.add(keep)
        return keep

    def _set_point(self, v, x):
        if v < self.n_v0:
            self.pos[v] = x
        else:
            self.new_pos[v - self.n_v0] = x

    def signed_area(self, c, verts):
        """Signed area of the polygon ``verts`` (a row of cell ``c``'s replica)."""
        return float(self.constraint.polygon_area(self._unwrapped(c, verts), self._size(c)))

    # ------------------------------------------------------------------ the new arrays
    def finish(self):
        """``(arrays for State.resize, Change)``; replicas back to back, old rows first in each."""
        n_v, n_c = self.n_v0 + len(self.new_pos), self.n_c0 + len(self.parent)
        vrep, crep = np.asarray(self.vrep, dtype=np.int64), np.asarray(self.crep, dtype=np.int64)
        alive_v, alive_c = np.ones(n_v, bool), np.ones(n_c, bool)
        alive_v[list(self.dead_v)] = False
        alive_c[list(self.dead_c)] = False
        order_v = np.flatnonzero(alive_v)[np.argsort(vrep[alive_v], kind="stable")]
        order_c = np.flatnonzero(alive_c)[np.argsort(crep[alive_c], kind="stable")]
        inv_v, inv_c = np.full(n_v, -1, np.int64), np.full(n_c, -1, np.int64)
        inv_v[order_v], inv_c[order_c] = np.arange(len(order_v)), np.arange(len(order_c))
        rows = {c: r for c, r in self.rows.items() if alive_c[c]}
        width = max([self.table.shape[1]] + [len(r) for r in rows.values()])
        table = np.full((n_c, width), -1, dtype=np.int64)
        table[:self.n_c0, :self.table.shape[1]] = self.table
        sides = np.zeros(n_c, dtype=np.int64)
        sides[:self.n_c0] = self.sides
        for c, r in rows.items():
            table[c, :] = -1
            table[c, :len(r)] = r
            sides[c] = len(r)
        table = table[order_c]
        table = np.where(table >= 0, inv_v[np.maximum(table, 0)], -1).astype(np.int32)
        sides = sides[order_c].astype(np.int32)
        pos = np.concatenate([self.pos, np.reshape(self.new_pos, (-1, 3))])[order_v]
        vn, vc = topology.build_vertex_tables(table, sides, len(order_v))
        start = lambda rep: np.concatenate(([0], np.cumsum(np.bincount(rep, minlength=self.n_replicas))))  # noqa
        arrays = dict(positions=pos, cell_vertices=table, cell_sides=sides, vertex_neighbors=vn, vertex_cells=vc,
                      vertex_start=start(vrep[order_v]), cell_start=start(crep[order_c]))
        parent = np.asarray(self.parent, dtype=np.int64)
        source_c = np.concatenate([np.arange(self.n_c0), parent])[order_c]
        source_v = np.concatenate([np.arange(self.n_v0), np.full(len(self.new_pos), -1)])[order_v]
        moved = inv_v[sorted(v for v in self.moved if alive_v[v])]
        change = Change(vertex_source=source_v, cell_source=source_c, new_cells=order_c >= self.n_c0,
                        vertex_map=inv_v[:self.n_v0], cell_map=inv_c[:self.n_c0], moved=moved)
        return arrays, change


def tangent_basis(n):
    """Two orthonormal tangent vectors ``e1, e2`` at unit normal ``n`` (``e1`` along x where it can)."""
    ref = np.array([1.0, 0.0, 0.0]) if abs(n[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    e1 = ref - (ref @ n) * n
    e1 /= np.linalg.norm(e1)
    return e1, np.cross(n, e1)


def apply(state, editor):
    """Resize ``state`` to the edited network; returns the :class:`Change` (None if nothing changed)."""
    if not editor.parent and not editor.dead_c:
        return None
    arrays, change = editor.finish()
    state.resize(**arrays)
    return change


def divide(state, cells, axes):
    """Divide ``cells`` of ``state`` (in place) across the cuts of tangent normals ``axes`` ((n, 3));
    returns ``(Change or None, daughters or refusal reasons per cell)``. A convenience for scripts
    and tests; the :class:`spherevm.plugins.updaters.Division` updater chooses cells and axes."""
    ed = Editor(state)
    out = [ed.divide(int(c), ed.tangent(int(c), m)) for c, m in zip(cells, axes)]
    return apply(state, ed), out


def extrude(state, cells):
    """T2 on ``cells`` of ``state`` (in place); returns ``(Change or None, outcome per cell)``."""
    ed = Editor(state)
    out = [ed.extrude(int(c)) for c in cells]
    return apply(state, ed), out
