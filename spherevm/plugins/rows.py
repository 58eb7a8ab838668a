"""Per-row data of operations (one row per replica, vertex or cell): following rows through growth,
moving arrays between host and device for checkpoints."""
from __future__ import annotations

import numpy as np

from ..validation import stored


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


def saved_where(op, data, name) -> str:
    """Where saved field ``name`` came from: file, frame and chunk, or the operation's class."""
    return data.where(name) if hasattr(data, "where") else f"{type(op).__name__}: saved field {name!r}"


def saved_field(op, data, name, dtype, shape=None, **bounds):
    """Field ``name`` of ``op``'s saved state ``data``, checked by :func:`spherevm.validation.stored`
    (dtype, shape, finite, ``low``/``high``/``above``); the ValueError names the file, frame and
    chunk when ``data`` was read from a file (a :class:`spherevm.gsdio.Saved`), and what was expected."""
    where = saved_where(op, data, name)
    if name not in data:
        raise ValueError(f"{where}: missing; {type(op).__name__} saves it in every checkpoint (the checkpoint was "
                         "written by another version of the operation, or is damaged)")
    return stored(where, data[name], dtype, shape, **bounds)


def _restored(op, name, data):
    """Saved field ``name`` of ``op`` as the attribute it replaces: same shape, dtype and device
    (a bool attribute is saved as uint8 0 or 1)."""
    current = getattr(op, name)
    if current is None:
        return np.asarray(saved_field(op, data, name, np.asarray(data.get(name, 0.0)).dtype))
    flag = current.dtype == bool
    shape = tuple(current.shape)
    if name in data and np.shape(data[name]) != shape:
        raise ValueError(f"{saved_where(op, data, name)}: expected shape {shape} for this State, got {np.shape(data[name])}; the "
                         "checkpoint belongs to another State")
    value = saved_field(op, data, name, np.uint8 if flag else current.dtype, shape,
                        **({"high": 1} if flag else {})).astype(current.dtype)
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


def saved_convergence(op, data, n_replicas) -> dict:
    """A Minimizer's saved convergence state, checked: ``iteration`` >= 0, ``checked_at`` and
    ``steps`` in [-1, iteration], the flags 0 or 1, one reason per replica ("running", "force",
    "energy" or an operation's ``halt_reason``), and per replica stopped == (steps >= 0) ==
    (reason != "running") and converged == (reason is "force" or "energy")."""
    n = n_replicas
    iteration = int(saved_field(op, data, "iteration", np.int64, (1,), low=0)[0])
    out = {"iteration": iteration,
           "checked_at": int(saved_field(op, data, "checked_at", np.int64, (1,), low=-1, high=iteration)[0]),
           "steps": saved_field(op, data, "steps", np.int64, (n,), low=-1, high=iteration).copy()}
    for name in ("replica_converged", "stopped", "active"):
        out[name] = saved_field(op, data, name, np.uint8, (n,), high=1).astype(bool)
    raw = saved_field(op, data, "reason", np.uint8, (None,))
    where = saved_where(op, data, "reason")
    try:
        reason = bytes(raw).decode("utf-8").split("\n")
    except UnicodeDecodeError as exc:
        raise ValueError(f"{where}: expected UTF-8 text, got {exc}") from None
    if len(reason) != n or not all(r.isidentifier() for r in reason):
        raise ValueError(f"{where}: expected {n} reason(s), one per replica, each a name such as 'running' "
                         f"or 'force', got {reason!r}")
    out["reason"] = np.array(reason, dtype=object)
    running = out["reason"] == "running"
    by_tolerance = np.isin(out["reason"], ("force", "energy"))
    bad = (out["stopped"] == running) | (out["stopped"] != (out["steps"] >= 0)) | \
        (out["replica_converged"] != by_tolerance)
    if bad.any():
        r = int(np.flatnonzero(bad)[0])
        raise ValueError(f"{where}: expected replica {r}'s stopped flag, steps, converged flag and reason to "
                         f"agree, got stopped={bool(out['stopped'][r])}, steps={int(out['steps'][r])}, "
                         f"converged={bool(out['replica_converged'][r])}, reason={reason[r]!r}")
    return out
