"""Cell meshes for other programs (Blender, MeshLab, ParaView, web viewers) through trimesh.

Each cell becomes a fan of triangles from its centre to its edges; every fan triangle is cut into
``subdivisions^2`` small ones on a barycentric grid whose points are put back on the surface with
the constraint (``project_normal``), so edges are drawn as geodesics, curved on a sphere, and the
mesh's area tends to the surface's as ``subdivisions`` grows (error ~1/subdivisions^2). Every mesh
vertex belongs to one cell, so per-vertex colours are per-cell colours (``.obj`` and ``.glb`` store
vertex colours, ``.ply`` both)::

    from spherevm.export import export_gsd
    export_gsd("run.gsd", "cells.glb", frame=-1, quantity="shape_index", cmap="viridis")

or from the command line, ``spherevm export run.gsd --to cells.glb``. Colours come from a per-cell
quantity (``shape_index``, ``area``, ``perimeter``, ``energy`` where the GSD file has it, or any
array of ``n_cells`` values) through a matplotlib colour map; NaN values are grey.
"""
from __future__ import annotations

import os

import numpy as np

from .gsdio import Reader
from .shapes import cell_shapes, shape_index_of
from .validation import check_memory, integer

QUANTITIES = ("shape_index", "area", "perimeter", "energy")
FORMATS = (".ply", ".obj", ".glb")
NAN_COLOR = (128, 128, 128, 255)
#: host memory per mesh triangle while a mesh is built and written, rounded up from the measured
#: peak memory of :func:`export_gsd` (1.7e6 to 1.5e7 triangles): 110-130 B for .ply and .glb, 310 B
#: for .obj; :func:`cell_mesh` refuses a mesh that would not fit in the memory available
MESH_BYTES_PER_TRIANGLE = 320


def check_replica(state, replica) -> int:
    """``replica`` as an int in ``0..n_replicas - 1`` (ValueError naming the range otherwise)."""
    return integer("replica", replica, minimum=0, maximum=state.n_replicas - 1)


def cell_values(state, quantity: str = "shape_index", stored: dict | None = None) -> np.ndarray:
    """A per-cell quantity of ``state`` (``stored``: the GSD file's exact per-cell arrays, if any)."""
    if stored and quantity in stored:
        return np.asarray(stored[quantity], dtype=np.float64)
    if quantity == "energy":
        have = sorted(stored) if stored else []
        raise ValueError("quantity 'energy' is not stored in this frame (the GSD writer records per-cell "
                         f"energies only when every force gives them); choose one of {have or list(QUANTITIES[:3])}")
    if quantity not in QUANTITIES:
        raise ValueError(f"quantity must be one of {QUANTITIES}, got {quantity!r}")
    area, perimeter = cell_shapes(state)
    return {"area": area, "perimeter": perimeter, "shape_index": shape_index_of(area, perimeter)}[quantity]


def colors(values, cmap: str = "viridis", vmin=None, vmax=None) -> np.ndarray:
    """RGBA uint8 colours of ``values`` through a matplotlib colour map (NaN: grey)."""
    import matplotlib
    values = np.asarray(values, dtype=np.float64)
    ok = np.isfinite(values)
    lo = np.min(values[ok]) if vmin is None and ok.any() else (0.0 if vmin is None else vmin)
    hi = np.max(values[ok]) if vmax is None and ok.any() else (1.0 if vmax is None else vmax)
    t = (values - lo) / (hi - lo) if hi > lo else np.full_like(values, 0.5)
    try:
        cm = matplotlib.colormaps[cmap]
    except KeyError:
        raise ValueError(f"unknown colour map {cmap!r}; see matplotlib.colormaps") from None
    rgba = (cm(np.clip(np.nan_to_num(t), 0, 1)) * 255).round().astype(np.uint8)
    rgba[~ok] = NAN_COLOR
    return rgba


def _grid(n):
    """Barycentric grid of a triangle cut into n^2: weights (P, 3) and triangles (n^2, 3)."""
    index, weights = {}, []
    for i in range(n + 1):
        for j in range(n + 1 - i):
            index[i, j] = len(weights)
            weights.append((1 - (i + j) / n, i / n, j / n))     # (centre, a, b)
    tris = []
    for i in range(n):
        for j in range(n - i):
            tris.append((index[i, j], index[i + 1, j], index[i, j + 1]))
            if i + j < n - 1:
                tris.append((index[i + 1, j], index[i + 1, j + 1], index[i, j + 1]))
    return np.array(weights), np.array(tris)


def fan_triangles(state, cells=None):
    """Per fan triangle: the cell's centre, the two ends of one edge (counter-clockwise, unwrapped
    about the cell's first vertex on a periodic surface) and the cell; ``cells`` selects cells
    (default all)."""
    s = state.to("cpu") if state.device.is_gpu else state
    cells = np.arange(s.n_cells) if cells is None else np.asarray(cells)
    cv, sides = np.asarray(s.cell_vertices)[cells], np.asarray(s.cell_sides)[cells]
    pos = np.asarray(s.positions)
    k = np.arange(cv.shape[1])
    mask = k[None, :] < sides[:, None]
    nxt = cv[np.arange(len(cells))[:, None], (k[None, :] + 1) % np.maximum(sides[:, None], 1)]
    a, b = pos[cv[mask]], pos[nxt[mask]]
    cell_of = np.repeat(cells, sides)
    first = pos[cv[:, 0]][np.repeat(np.arange(len(cells)), sides)]
    size = s.constraint.size_np(s)[s.cell_replica_np()[cell_of]]
    a, b = s.constraint.unwrap(a, first, size), s.constraint.unwrap(b, first, size)
    centre = np.zeros((len(cells), 3))
    np.add.at(centre, np.repeat(np.arange(len(cells)), sides), a)
    centre = (centre / sides[:, None])[np.repeat(np.arange(len(cells)), sides)]
    return centre, a, b, cell_of


def replica_offsets(state) -> np.ndarray:
    """The shifts ``(n_replicas, 3)`` that lay the replicas side by side along x, replica 0 in
    place, :meth:`~spherevm.constraints.Constraint.replica_spacing` apart: 2.5 of the largest
    radius on a sphere; on the plane 1.1 of the widest box plus twice the widest cell."""
    _, a, _, cell_of = fan_triangles(state)
    hi, lo = np.full(state.n_cells, -np.inf), np.full(state.n_cells, np.inf)
    np.maximum.at(hi, cell_of, a[:, 0])
    np.minimum.at(lo, cell_of, a[:, 0])
    step = state.constraint.replica_spacing(state.constraint.size_np(state), (hi - lo).max())
    out = np.zeros((state.n_replicas, 3))
    out[:, 0] = step * np.arange(state.n_replicas)
    return out


def cell_mesh(state, values=None, quantity: str = "shape_index", cmap: str = "viridis", subdivisions: int = 3,
              replica=None, side_by_side: bool = True, vmin=None, vmax=None):
    """A ``trimesh.Trimesh`` of the cells of ``state``, coloured per cell: mesh vertices carry
    ``vertex_colors``, ``mesh.metadata['cell']`` gives each face's cell.

    Parameters
    ----------
    state : State
    values : array (n_cells,), optional
        Overrides ``quantity``.
    quantity : str
    cmap : str
        A matplotlib colour map.
    subdivisions : int
        Each fan triangle cut into ``subdivisions^2`` on the surface.
    replica : int, optional
        One replica, or all (None).
    side_by_side : bool
        All replicas placed side by side along x; False: where they are, overlapping.
    vmin, vmax : float, optional
        The colour scale's range.

    Returns
    -------
    trimesh.Trimesh
        Its vertices carry ``vertex_colors``; ``mesh.metadata['cell']`` gives each face's cell. A
        mesh needs about ``MESH_BYTES_PER_TRIANGLE`` (320) bytes per triangle: one that would not
        fit in the host memory available now is refused at once
        (:class:`~spherevm.validation.InsufficientMemory`, a ValueError)."""
    import trimesh
    n = integer("subdivisions", subdivisions, minimum=1)
    values = cell_values(state, quantity) if values is None else np.asarray(values, dtype=np.float64)
    if values.shape != (state.n_cells,):
        raise ValueError(f"values must have one entry per cell ({state.n_cells}), got shape {values.shape}")
    crep = state.cell_replica_np()
    cells = np.arange(state.n_cells) if replica is None else np.flatnonzero(crep == check_replica(state, replica))
    fans = int(np.asarray(state.device.to_numpy(state.cell_sides))[cells].sum())
    check_memory(f"a mesh of {fans} fan triangles x subdivisions^2 = {n}^2 ({float(fans) * n * n:.3g} triangles)",
                 host_bytes=float(fans) * n * n * MESH_BYTES_PER_TRIANGLE,
                 advice="lower subdivisions (area error ~1/subdivisions^2; the default 3 draws edges smoothly)")
    centre, a, b, cell_of = fan_triangles(state, cells)
    w, tris = _grid(n)
    points = w[None, :, 0, None] * centre[:, None] + w[None, :, 1, None] * a[:, None] + w[None, :, 2, None] * b[:, None]
    rep = crep[cell_of]
    pr = np.repeat(state.constraint.size_np(state)[rep], len(w), axis=0)
    points = np.asarray(state.constraint.draw_points(points.reshape(-1, 3), pr)).reshape(points.shape)
    if replica is None and side_by_side:
        points = points + replica_offsets(state)[rep][:, None, :]
    nf, npt = len(centre), len(w)
    faces = (tris[None, :, :] + (np.arange(nf) * npt)[:, None, None]).reshape(-1, 3)
    vcol = np.repeat(colors(values, cmap, vmin, vmax)[cell_of], npt, axis=0)
    mesh = trimesh.Trimesh(vertices=points.reshape(-1, 3), faces=faces, vertex_colors=vcol, process=False)
    mesh.metadata["cell"] = np.repeat(cell_of, len(tris))
    return mesh


def export_state(state, out, values=None, quantity: str = "shape_index", **options):
    """Write :func:`cell_mesh` of ``state`` to ``out`` (``.ply``, ``.obj`` or ``.glb``); return the mesh."""
    ext = os.path.splitext(os.fspath(out))[1].lower()
    if ext not in FORMATS:
        raise ValueError(f"output must end in one of {FORMATS}, got {os.fspath(out)!r}")
    mesh = cell_mesh(state, values=values, quantity=quantity, **options)
    mesh.export(os.fspath(out))
    return mesh


def export_gsd(path, out, frame: int = -1, quantity: str = "shape_index", **options):
    """Write a frame of a spherevm GSD file as a mesh; the quantity's exact per-cell values come
    from the file (``energy`` only where it was recorded).

    Parameters
    ----------
    path : str or path
    out : str or path
        ``.ply``, ``.obj`` or ``.glb``.
    frame : int
        Negative from the end.
    quantity : str
    **options
        As in :func:`cell_mesh`.

    Returns
    -------
    trimesh.Trimesh"""
    with Reader(path) as reader:
        state = reader.state(frame)
        stored = reader.cell_values(frame)
    return export_state(state, out, values=cell_values(state, quantity, stored), **options)
