"""A sweep on disk: ``manifest.json`` (the parameters), ``chunks/*.csv`` (one row per replica),
written atomically, checked against the requested sweep, and scanned to resume. The same store
serves every sweep kind (:class:`spherevm.sweeps.spec.Sweep`): each names its manifest format and
its record :class:`Columns`."""
from __future__ import annotations

import csv
import json
import os
import time
import warnings
from dataclasses import dataclass

import numpy as np

from ..provenance import source_fingerprint

FORMAT = "spherevm-rigidity-sweep"
FORMAT_VERSION = 1
MANIFEST = "manifest.json"
CHUNK_DIR = "chunks"

RECORD_COLUMNS = ("n_cells", "p0", "p0_index", "replica", "tiling_seed", "energy_per_cell", "max_force",
                  "mean_shape_index", "steps", "reason", "t1_flips", "inverted_cells", "chunk", "chunk_seconds")
_INT_COLUMNS = {"n_cells", "p0_index", "replica", "tiling_seed", "steps", "t1_flips", "inverted_cells"}
_STR_COLUMNS = {"reason", "chunk"}


@dataclass(frozen=True)
class Columns:
    """The record columns of a sweep kind: their order, which are integers and which strings (the
    rest are floats), the columns records are sorted by, most significant first, and ``added``:
    ``(name, value)`` pairs of columns that files written before them lack, read as ``value``."""
    names: tuple
    ints: frozenset
    strs: frozenset
    sort: tuple
    added: tuple = ()


#: the rigidity sweep's records, one row per minimised tiling
#: (``inverted_cells``: cells of signed area <= 0 at the end; -1 in files written before it was kept)
RIGIDITY_COLUMNS = Columns(RECORD_COLUMNS, frozenset(_INT_COLUMNS), frozenset(_STR_COLUMNS),
                           ("n_cells", "p0_index", "replica"), added=(("inverted_cells", -1),))
#: the dynamics sweep's records, one row per tissue (tau_alpha NaN: Q_s stayed above 1/e)
DYNAMICS_COLUMNS = Columns(
    ("n_cells", "point", "T", "p0", "B", "replica", "tiling_seed", "noise_seed", "tau_alpha", "msd_end",
     "overlap_end", "t1_flips", "chunk", "chunk_seconds"),
    frozenset({"n_cells", "point", "replica", "tiling_seed", "noise_seed", "t1_flips"}), frozenset({"chunk"}),
    ("n_cells", "point", "replica"))
#: a dynamics chunk's MSD and Q_s, averaged over its ``tissues``, one row per lag
CURVE_COLUMNS = ("n_cells", "point", "tissues", "time", "msd", "self_overlap")
#: where a dynamics sweep keeps each chunk's averaged curves
CURVE_DIR = "curves"


def _format(value):
    if isinstance(value, float):
        return repr(value)
    return str(value)


def write_columns(path, columns: dict, order=None):
    """Write a dict of equal-length columns as CSV, atomically (a temporary file, then rename)."""
    order = list(order or columns)
    n = len(next(iter(columns.values()))) if columns else 0
    tmp = f"{path}.tmp{os.getpid()}"
    with open(tmp, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(order)
        for i in range(n):
            row = []
            for c in order:
                v = columns[c][i]
                if isinstance(v, (np.floating,)):
                    v = float(v)
                elif isinstance(v, (np.integer,)):
                    v = int(v)
                elif isinstance(v, np.bool_):
                    v = bool(v)
                row.append(_format(v))
            w.writerow(row)
    os.replace(tmp, path)


def read_records(path, columns: Columns = RIGIDITY_COLUMNS) -> dict:
    """Read a chunk (or replicas.csv) file back into typed columns (lists); a file written before
    ``columns.added`` existed gets their values."""
    with open(path, newline="") as fh:
        rows = list(csv.reader(fh))
    added = dict(columns.added)
    header = tuple(rows[0]) if rows else None
    if header not in (columns.names, tuple(c for c in columns.names if c not in added)):
        raise ValueError(f"{path}: not a sweep record file (header {list(header) if rows else 'missing'})")
    out = {c: [] for c in columns.names}
    for row in rows[1:]:
        if len(row) != len(header):
            raise ValueError(f"{path}: malformed row {row}")
        for c, v in zip(header, row):
            out[c].append(v if c in columns.strs else int(v) if c in columns.ints else float(v))
    for c in set(columns.names) - set(header):
        out[c] = [added[c]] * (len(rows) - 1)
    return out


def merge_records(parts, columns: Columns = RIGIDITY_COLUMNS) -> dict:
    """One dict of record columns from several (chunk order kept)."""
    out = {c: [] for c in columns.names}
    for p in parts:
        for c in columns.names:
            out[c].extend(p[c])
    return out


def sorted_records(records: dict, columns: Columns = RIGIDITY_COLUMNS) -> dict:
    """Records as NumPy columns, sorted by ``columns.sort`` (rigidity: N, p0 index, replica)."""
    cols = {c: np.asarray(records[c]) for c in columns.names}
    if len(cols[columns.sort[0]]) == 0:
        return cols
    order = np.lexsort(tuple(cols[c] for c in columns.sort[::-1]))
    return {c: v[order] for c, v in cols.items()}


def check_out_folder(out):
    """Fail (ValueError) before anything is created when ``out`` cannot become a sweep folder."""
    if out is None or str(out) == "":
        raise ValueError("out must name a folder for the sweep's results, got an empty path")
    path = os.path.abspath(os.fspath(out))
    if os.path.exists(path):
        if not os.path.isdir(path):
            raise ValueError(f"output folder {out!r} exists and is not a folder")
        if not os.access(path, os.W_OK | os.X_OK):
            raise ValueError(f"output folder {out!r} is not writable (permission denied)")
        return path
    parent = os.path.dirname(path)
    while not os.path.exists(parent):
        up = os.path.dirname(parent)
        if up == parent:
            break
        parent = up
    if not os.path.isdir(parent):
        raise ValueError(f"cannot create output folder {out!r}: {parent!r} is not a folder")
    if not os.access(parent, os.W_OK | os.X_OK):
        raise ValueError(f"cannot create output folder {out!r}: {parent!r} is not writable (permission denied)")
    return path


def _manifest_mismatch(old: dict, new: dict):
    diffs = []
    for key in sorted(set(old) | set(new)):
        a, b = old.get(key, "<missing>"), new.get(key, "<missing>")
        if a != b:
            diffs.append(f"{key}: {a!r} in the folder, {b!r} requested")
    return diffs


def open_sweep_folder(sweep, out, create: bool = True) -> str:
    """Check ``out`` against ``sweep`` (ValueError on a mismatch) and write its manifest.

    A new or empty folder gets ``manifest.json``; a folder with a manifest must hold the same
    parameters (else the differences are listed); any other non-empty folder is refused.
    """
    path = check_out_folder(out)
    manifest_path = os.path.join(path, MANIFEST)
    params = sweep.parameters()
    form = sweep.FORMAT
    if os.path.isdir(path) and os.listdir(path):
        if not os.path.exists(manifest_path):
            raise ValueError(f"output folder {out!r} is not empty and holds no {MANIFEST}: not a {sweep.KIND} sweep "
                             "folder; choose a new or empty folder")
        try:
            with open(manifest_path) as fh:
                manifest = json.load(fh)
        except (OSError, json.JSONDecodeError) as exc:
            raise ValueError(f"cannot read {manifest_path}: {exc}") from None
        if manifest.get("format") != form:
            raise ValueError(f"{manifest_path} is not a {form} manifest (it holds a {manifest.get('format')})")
        if manifest.get("version") != FORMAT_VERSION:
            raise ValueError(f"{manifest_path} has format version {manifest.get('version')}, "
                             f"this spherevm writes {FORMAT_VERSION}")
        old = dict(manifest.get("parameters", {}))
        old.setdefault("surface", "sphere")          # folders from before the plane are sphere sweeps
        if old["surface"] != params.get("surface", "sphere"):
            raise ValueError(f"output folder {out!r} holds a sweep on the {old['surface']}, not on the "
                             f"{params.get('surface', 'sphere')} requested; use another folder (or resume it with "
                             f"surface={old['surface']!r})")
        diffs = _manifest_mismatch(old, params)
        if diffs:
            raise ValueError(f"output folder {out!r} holds a sweep with different parameters ("
                             + "; ".join(diffs) + "); use another folder, or the folder's parameters to resume it")
        started_with = manifest.get("code")
        if started_with is not None and started_with != source_fingerprint():
            warnings.warn(f"{out!r} was started by spherevm code {started_with}, this is {source_fingerprint()}: "
                          "the records of both will be mixed (individual minimisations may differ in their "
                          "last digits or, near the transition, in their outcome)", stacklevel=2)
        return path
    if not create:
        return path
    from .. import __version__
    os.makedirs(os.path.join(path, CHUNK_DIR), exist_ok=True)
    manifest = {"format": form, "version": FORMAT_VERSION, "spherevm": __version__, "code": source_fingerprint(),
                "created": time.strftime("%Y-%m-%dT%H:%M:%S%z"), "parameters": params,
                "layout": {"chunks": f"{CHUNK_DIR}/N<cells>_u<first unit>-<end unit>.csv, one row per replica; "
                                     f"unit u = {sweep.UNIT} * replicas + replica"}}
    tmp = manifest_path + f".tmp{os.getpid()}"
    with open(tmp, "w") as fh:
        json.dump(manifest, fh, indent=2)
        fh.write("\n")
    os.replace(tmp, manifest_path)
    return path


def scan_chunks(sweep, path: str, clean: bool = False):
    """Finished chunk files of a sweep folder: ``(done, records, bad)``.

    ``done`` maps N to a bool array over its units; ``records`` lists the parsed files; ``bad``
    lists files that could not be read or do not match the sweep (they are recomputed).
    ``clean=True`` (run_sweep) removes temporary files an interrupted write left behind.
    """
    folder = os.path.join(path, CHUNK_DIR)
    done = {n: np.zeros(sweep.units_per_size, dtype=bool) for n in sweep.cells}
    records, bad = [], []
    if not os.path.isdir(folder):
        return done, records, bad
    for name in sorted(os.listdir(folder)):
        full = os.path.join(folder, name)
        if ".tmp" in name:          # left over by an interrupted write
            if clean:
                try:
                    os.remove(full)
                except OSError:
                    pass
            continue
        if not name.endswith(".csv"):
            continue
        try:
            rec = read_records(full, sweep.columns)
            n = set(rec["n_cells"])
            if len(n) != 1 or next(iter(n)) not in done or not rec["n_cells"]:
                raise ValueError("size not in this sweep")
            n = next(iter(n))
            u = sweep.chunk_units(rec)
            if np.any(done[n][u]):
                raise ValueError("units already covered by another chunk file")
        except (ValueError, OSError) as exc:
            bad.append((full, str(exc)))
            continue
        done[n][u] = True
        records.append(rec)
    return done, records, bad


def read_curves(out, records: dict) -> dict:
    """The MSD and Q_s of every point, averaged over its tissues (each chunk's curve weighed by its
    tissues, chunks in the order of their first tissue): columns ``n_cells, point, T, p0, B, time,
    msd, self_overlap``, sorted by (N, point, time)."""
    folder = os.path.join(os.fspath(out), CURVE_DIR)
    chunks = {}
    for i, c in enumerate(records["chunk"]):
        chunks.setdefault(c, i)
    points = {}
    for cid in sorted(chunks, key=lambda c: (int(records["n_cells"][chunks[c]]), int(records["point"][chunks[c]]),
                                             int(records["replica"][chunks[c]]))):
        path = os.path.join(folder, cid + ".csv")
        try:
            with open(path, newline="") as fh:
                rows = list(csv.reader(fh))
        except OSError:
            raise ValueError(f"{path} is missing: the chunk's curves were lost; remove chunks/{cid}.csv "
                             "and rerun the sweep to recompute it") from None
        cols = {c: np.array([float(r[j]) for r in rows[1:]]) for j, c in enumerate(rows[0])}
        i = chunks[cid]
        key = (int(records["n_cells"][i]), int(records["point"][i]))
        w = cols["tissues"][0]
        total = points.setdefault(key, [i, cols["time"], np.zeros(len(cols["time"])), np.zeros(len(cols["time"])), 0.0])
        total[2] = total[2] + w * cols["msd"]
        total[3] = total[3] + w * cols["self_overlap"]
        total[4] += w
    out_cols = {c: [] for c in ("n_cells", "point", "T", "p0", "B", "time", "msd", "self_overlap")}
    for (n, k), (i, lag, msd, overlap, w) in sorted(points.items()):
        m = len(lag)
        for c in ("T", "p0", "B"):
            out_cols[c].extend([float(records[c][i])] * m)
        out_cols["n_cells"].extend([n] * m)
        out_cols["point"].extend([k] * m)
        out_cols["time"].extend(lag.tolist())
        out_cols["msd"].extend((msd / w).tolist())
        out_cols["self_overlap"].extend((overlap / w).tolist())
    return out_cols
