"""The inherent states of a sweep (``run_sweep(save_states=True)``, ``spherevm rigidity
--save-states``): each chunk's minimised State as one GSD frame, ``<out>/states/<chunk id>.gsd``,
in the order of the chunk's records, and :func:`load_state` to open the state of one
(N, p0, replica) for a look at rigid and floppy configurations.

A worker builds the file and sends back its bytes (:func:`chunk_state_gsd`), so, as for the
records, only the main process writes to the folder and workers need no shared file system.
"""
from __future__ import annotations

import os
import tempfile

import numpy as np

from .store import CHUNK_DIR, read_records

STATE_DIR = "states"


def chunk_state_gsd(simulation, p0, p0_index, replica) -> bytes:
    """The Simulation's State as the bytes of a one-frame spherevm GSD file with, per replica,
    ``log/p0``, ``log/p0_index``, ``log/replica``, the energy per cell, the mean shape index, the
    largest force and the T1 flips, and the per-cell area, perimeter, shape index and energy."""
    from ..logging import Logger
    from ..plugins.writers import write_gsd
    logger = Logger(["energy_per_cell", "mean_shape_index", "max_force", "t1_total_flips"])
    for name, values in (("p0", p0), ("p0_index", p0_index), ("replica", replica)):
        logger[name] = lambda sim, v=np.asarray(values, dtype=np.float64): v
    with tempfile.TemporaryDirectory() as folder:
        path = os.path.join(folder, "state.gsd")
        write_gsd(simulation, path, logger=logger, checkpoint=False)
        with open(path, "rb") as fh:
            return fh.read()


def state_path(out, chunk_id) -> str:
    """Where the inherent states of chunk ``chunk_id`` are kept."""
    return os.path.join(os.fspath(out), STATE_DIR, f"{chunk_id}.gsd")


def save_chunk_state(out, chunk_id, data: bytes):
    """Write a chunk's state file atomically (a temporary file, then rename)."""
    path = state_path(out, chunk_id)
    os.makedirs(os.path.dirname(path), exist_ok=True)
    tmp = f"{path}.tmp{os.getpid()}"
    with open(tmp, "wb") as fh:
        fh.write(data)
    os.replace(tmp, path)


def load_state(out, n_cells, p0, replica, device="cpu"):
    """The inherent state of one tiling of a sweep run with ``save_states=True``.

    Parameters
    ----------
    out : str or path
        The sweep's folder.
    n_cells, p0, replica
        Which tiling.
    device : Device or str

    Returns
    -------
    (State, dict)
        A single-replica State and its record (energy per cell, reason, steps, ...)."""
    from ..init import from_gsd
    folder = os.path.join(os.fspath(out), CHUNK_DIR)
    names = sorted(n for n in os.listdir(folder) if n.endswith(".csv")) if os.path.isdir(folder) else []
    for name in names:
        rec = read_records(os.path.join(folder, name))
        hit = [i for i, (n, p, r) in enumerate(zip(rec["n_cells"], rec["p0"], rec["replica"]))
               if n == n_cells and r == replica and abs(p - p0) <= 1e-9]
        if hit:
            i = hit[0]
            path = state_path(out, rec["chunk"][i])
            if not os.path.isfile(path):
                raise FileNotFoundError(f"{path} does not exist: the chunk was run without save_states; rerun the "
                                        "sweep with save_states=True (spherevm rigidity --save-states)")
            return from_gsd(path, device=device).replica(i), {c: v[i] for c, v in rec.items()}
    raise KeyError(f"no finished minimisation of N = {n_cells}, p0 = {p0}, replica = {replica} in {out!r}")
