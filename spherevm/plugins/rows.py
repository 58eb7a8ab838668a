"""Per-row data of operations (one row per replica, vertex or cell): following rows through growth,
moving arrays between host and device for checkpoints."""
from __future__ import annotations

import numpy as np


def follow_rows(op, change):
    """Rebuild ``op``'s ``per_cell`` arrays through ``change.cell_source`` (a daughter cell takes
    its mother's row) and its ``per_vertex`` arrays through ``change.vertex_source`` (a created
    vertex gets a zero row); ``per_replica`` rows stay (replicas are neither added nor removed)."""
    for name, axis in op.row_attributes():
        full = getattr(op, name)
        if axis == "replicas" or full is None:
            continue
        source = change.cell_source if axis == "cells" else change.vertex_source
        out = full[_index_like(full, np.maximum(source, 0))]
        if axis == "vertices":
            out[_index_like(full, np.flatnonzero(source < 0))] = 0
        setattr(op, name, out)


def _host(value):
    """A NumPy copy of a NumPy array, a CuPy array or a scalar."""
    value = value.get() if hasattr(value, "get") else value
    return np.array(value, copy=True)


def _restored(op, name, data):
    """Saved field ``name`` of ``op`` as the attribute it replaces: same shape, dtype and device."""
    if name not in data:
        raise ValueError(f"{type(op).__name__}: the checkpoint lacks field {name!r}; it was written by another "
                         f"version of the operation")
    current = getattr(op, name)
    value = np.asarray(data[name])
    if current is None:
        return value
    if tuple(value.shape) != tuple(current.shape):
        raise ValueError(f"{type(op).__name__}: saved {name!r} has shape {value.shape}, but the operation "
                         f"needs {tuple(current.shape)} for this State; the checkpoint belongs to another State")
    value = value.astype(current.dtype)
    if isinstance(current, np.ndarray):
        return value
    import cupy
    return cupy.asarray(value)


def _index_like(array, index):
    """``index`` (NumPy) on the device of ``array``."""
    if isinstance(array, np.ndarray):
        return index
    import cupy
    return cupy.asarray(index)
