"""OVITO helper: each frame's cells as an OVITO SurfaceMesh with per-cell properties.

OVITO's GSD reader sees vertices (particles) and edges (bonds) only; this modifier reads the cell
topology that spherevm stores beside them (``spherevm/`` chunks) and adds a surface mesh ``cells``
with one polygonal face, and one region, per cell (edges cut into ``segments`` pieces on the
surface, so geodesics are drawn curved), carrying the face properties ``Region`` (the cell),
``cell``, ``replica``, ``shape_index``, ``area``, ``perimeter`` and ``energy`` (when the file has
it), coloured by ``shape_index``. Bonds get a width proportional to the cell size.

An ensemble's replicas share the origin in the file (they would be drawn on top of each other), so
by default the modifier lays them side by side along x, as ``spherevm export`` does: it moves each
replica's particles and cells by :func:`spherevm.export.replica_offsets` (replica 0 stays in
place; ``side_by_side=False`` leaves them where the file has them).

In a script, one call::

    import spherevm.ovito
    pipeline = spherevm.ovito.pipeline("run.gsd")      # an ovito.pipeline.Pipeline
    data = pipeline.compute(0)
    data.surfaces["cells"].faces["shape_index"]

In OVITO's GUI: add a *Python script* modifier whose script is
``from spherevm.ovito import modify``. This module needs the ``ovito`` package (``pip install
ovito``, or OVITO's own Python); it is imported only when used.
"""
from __future__ import annotations

import numpy as np

SEGMENTS = 4
BOND_WIDTH = 0.06          # in units of sqrt(<A>)


def _import_ovito():
    try:
        import ovito  # noqa: F401
        from ovito.data import DataCollection  # noqa: F401
    except ImportError as exc:
        raise ImportError("spherevm.ovito needs the 'ovito' Python package: pip install ovito "
                          "(or run the script with OVITO's ovitos)") from exc


def add_cell_mesh(data, state, values: dict, segments: int = SEGMENTS, identifier: str = "cells", shift=None):
    """Add ``state``'s cells to the OVITO DataCollection ``data`` as a SurfaceMesh (see module doc).

    Parameters
    ----------
    values : per-cell arrays by name, made face and region properties
    shift : ``(n_replicas, 3)`` added to each replica's cells (default none), in the file's
        particle coordinates (see :func:`spherevm.gsdio.particle_origin`)

    Returns
    -------
    The ``SurfaceMesh``.
    """
    from ovito.vis import SurfaceMeshVis

    from .gsdio import particle_origin
    from .render import cell_polygons
    cells = np.arange(state.n_cells)
    polys = cell_polygons(state, cells, segments)
    sizes = np.array([len(p) for p in polys])
    moved = -particle_origin(state) + (0.0 if shift is None else np.asarray(shift)[state.cell_replica_np()])
    mesh = data.surfaces.create(identifier, title="Cells")
    mesh.create_vertices(np.concatenate(polys) + np.repeat(np.broadcast_to(moved, (state.n_cells, 3)), sizes, axis=0))
    starts = np.concatenate([[0], np.cumsum(sizes)[:-1]])
    flat = np.concatenate([np.concatenate([[k], s + np.arange(k)]) for k, s in zip(sizes, starts)])
    mesh.create_faces(flat.astype(np.int64))
    mesh.regions.count = state.n_cells
    mesh.faces.create_property("Region", data=cells.astype(np.int32))
    mesh.faces.create_property("cell", data=cells.astype(np.int32))
    mesh.faces.create_property("replica", data=state.cell_replica_np().astype(np.int32))
    for name, v in values.items():
        mesh.faces.create_property(name, data=np.asarray(v, dtype=np.float64))
        mesh.regions.create_property(name, data=np.asarray(v, dtype=np.float64))
    vis = mesh.vis if mesh.vis is not None else SurfaceMeshVis()
    vis.highlight_edges = True
    vis.smooth_shading = False
    vis.show_cap = False
    vis.clip_at_domain_boundaries = False
    if "shape_index" in values:
        q = np.asarray(values["shape_index"], dtype=np.float64)
        ok = np.isfinite(q)
        vis.color_mapping_mode = SurfaceMeshVis.ColorMappingMode.Face
        vis.color_mapping_property = "shape_index"
        if ok.any():
            vis.color_mapping_interval = (float(q[ok].min()), float(q[ok].max()))
    mesh.vis = vis
    return mesh


def _cell_size(state):
    try:
        return float(np.sqrt(np.mean(state.mean_cell_area)))
    except NotImplementedError:
        return 1.0


def modify(frame, data, path=None, segments: int = SEGMENTS, side_by_side: bool = True):
    """An OVITO Python-script modifier (``modify(frame, data)``): adds the cells of the frame that
    OVITO loaded (file from the ``SourceFile`` attribute unless ``path`` is given) and, with
    ``side_by_side``, moves each replica's particles and cells beside the previous one along x."""
    _import_ovito()
    from .export import QUANTITIES, cell_values, replica_offsets
    from .gsdio import Reader
    path = path or data.attributes.get("SourceFile")
    if not path:
        raise ValueError("spherevm.ovito.modify: the data has no 'SourceFile' attribute; pass path=")
    index = int(data.attributes.get("SourceFrame", frame))
    with Reader(path) as reader:
        state = reader.state(index)
        stored = reader.cell_values(index)
    values = {q: cell_values(state, q, stored) for q in QUANTITIES if q != "energy" or q in stored}
    shift = replica_offsets(state) if side_by_side else None
    if shift is not None and data.particles is not None:
        data.particles_.positions_[...] += shift[state.vertex_replica_np()]
    add_cell_mesh(data, state, values, segments=segments, shift=shift)
    bonds = data.particles.bonds if data.particles is not None else None
    if bonds is not None and bonds.vis is not None:
        bonds.vis.width = BOND_WIDTH * _cell_size(state)


def pipeline(path, segments: int = SEGMENTS, add_to_scene: bool = False, side_by_side: bool = True):
    """An ``ovito.pipeline.Pipeline`` reading the spherevm GSD file ``path`` with the cell mesh added
    (and the replicas side by side unless ``side_by_side=False``)."""
    _import_ovito()
    import os

    from ovito.io import import_file
    from ovito.modifiers import PythonModifier
    path = os.path.abspath(os.fspath(path))

    def cells(frame, data):
        modify(frame, data, path=path, segments=segments, side_by_side=side_by_side)

    p = import_file(path)
    p.modifiers.append(PythonModifier(function=cells))
    if add_to_scene:
        p.add_to_scene()
    return p
