"""From per-replica records to F(p0, N), p0* and p0*(N): tables, plots and a text summary
(the statistics themselves are in :mod:`spherevm.analysis.rigidity`)."""
from __future__ import annotations

import json
import math
import os

import numpy as np

from ..analysis import rigidity
from .store import DYNAMICS_COLUMNS, MANIFEST, RECORD_COLUMNS, read_curves, sorted_records, write_columns


def classify_records(records: dict, zero_tol=None, exclude_inverted: bool = False):
    """Each record's status (:func:`spherevm.analysis.rigidity.classify`); with ``exclude_inverted``,
    a converged tissue that ends with inverted cells (``inverted_cells`` > 0; -1, not measured, is
    not) is ``"inverted"``, left out of F like the unconverged ones."""
    tol = rigidity.ZERO_ENERGY_TOL if zero_tol is None else zero_tol
    status = rigidity.classify(records["energy_per_cell"], records["reason"], tol)
    if exclude_inverted:
        inverted = np.asarray(records["inverted_cells"]) > 0
        status = np.where(np.isin(status, ("zero", "rigid")) & inverted, "inverted", status)
    return status


def summarize_records(records: dict, zero_tol=None, sigma=None, resamples: int = 400, surface: str = "sphere",
                      exclude_inverted: bool = False):
    """``(fractions, p0star, density)`` from per-replica records (see analysis.rigidity.summarize;
    ``exclude_inverted``: :func:`classify_records`)."""
    status = classify_records(records, zero_tol, exclude_inverted)
    return rigidity.summarize(records["n_cells"], records["p0"], status, sigma=sigma, resamples=resamples,
                              surface=surface)


def folder_surface(out) -> str:
    """The surface recorded in the sweep folder's manifest ("sphere" for folders without one)."""
    try:
        with open(os.path.join(os.fspath(out), MANIFEST)) as fh:
            return json.load(fh).get("parameters", {}).get("surface", "sphere")
    except (OSError, ValueError):
        return "sphere"


def write_tables(out, records: dict, zero_tol=None, plots=True, sigma=None, surface=None,
                 exclude_inverted: bool = False) -> dict:
    """Write ``replicas.csv``, ``fraction.csv`` (F(p0,N)), ``p0star.csv`` (p0*(N) beside the pentagon
    bound), ``p0star_density.csv`` and, with matplotlib, ``fraction.png``, ``p0star_distribution.png``
    (Fig. 2 style, F in the inset) and ``p0star_vs_N.png``. (Fig. 4's ``P0* = sqrt(<A>) p0*(N)``
    curves hold nothing p0star_vs_N.png does not: :func:`spherevm.analysis.rigidity.plot_critical_perimeter`
    and ``examples/fig4_critical_perimeter.py`` draw them.)

    ``surface`` (None: the folder manifest's, else "sphere") picks the pentagon bound: spherical per
    N, or the flat one on the plane (and no pentagon markers on the planar distributions).
    ``exclude_inverted``: tissues that end with inverted cells are left out of F (status
    ``"inverted"``, counted in ``n_other``; :func:`classify_records`).

    Returns a dict with the tables (``fractions``, ``p0star``, ``density``), the ``files`` written
    and ``plot_note`` (why plots were skipped, or None).
    """
    path = os.path.abspath(os.fspath(out))
    os.makedirs(path, exist_ok=True)
    records = sorted_records(records)
    surface = folder_surface(path) if surface is None else surface
    status = classify_records(records, zero_tol, exclude_inverted)
    frac, p0star, density = rigidity.summarize(records["n_cells"], records["p0"], status, sigma=sigma,
                                               surface=surface)
    files = []
    rec = dict(records)
    write_columns(os.path.join(path, "replicas.csv"), {**rec, "status": status}, RECORD_COLUMNS + ("status",))
    files.append(os.path.join(path, "replicas.csv"))
    for name, table in (("fraction.csv", frac), ("p0star.csv", p0star), ("p0star_density.csv", density)):
        write_columns(os.path.join(path, name), table)
        files.append(os.path.join(path, name))
    note = None
    if plots:
        try:
            import matplotlib
            matplotlib.use("Agg", force=False)
            import matplotlib.pyplot as plt
        except ImportError:
            note = "matplotlib is not installed: plots skipped (pip install 'spherevm[plot]')"
        else:
            for name, fig in (("fraction.png", lambda: rigidity.plot_fraction(frac)),
                              ("p0star_distribution.png", lambda: rigidity.plot_transition(frac, p0star, density,
                                                                                      pentagons=surface != "plane")),
                              ("p0star_vs_N.png", lambda: rigidity.plot_p0_star(p0star, surface=surface))):
                f = fig()
                f.tight_layout()
                f.savefig(os.path.join(path, name), dpi=150)
                plt.close(f)
                files.append(os.path.join(path, name))
    return {"fractions": frac, "p0star": p0star, "density": density, "status": status, "files": files,
            "plot_note": note}


def _note(p0star, i) -> str:
    if p0star["bracketed"][i]:
        return ""
    if math.isnan(p0star["p0_star"][i]) and math.isnan(p0star["F_first"][i]):
        return "F at fewer than two p0 values: no p0*"
    return "transition not inside the p0 grid"


def format_p0star_table(p0star) -> str:
    """p0*(N) beside the pentagon bound, as plain text."""
    head = ("N", "p0*", "+-", "spread", "p0(F=1/2)", "pentagon", "p0*-pent", "replicas", "unconv", "note")
    rows = []
    for i in range(len(p0star["n_cells"])):
        p, pent = p0star["p0_star"][i], p0star["pentagon_perimeter"][i]
        rows.append((str(int(p0star["n_cells"][i])), f"{p:.4f}", f"{p0star['p0_star_err'][i]:.4f}",
                     f"{p0star['std'][i]:.4f}", f"{p0star['p0_half'][i]:.4f}", f"{pent:.4f}", f"{p - pent:+.4f}",
                     str(int(p0star["n_replicas"][i])), str(int(p0star["n_unconverged"][i])),
                     _note(p0star, i)))
    return _text_table(head, rows)


def _text_table(head, rows) -> str:
    """Right-aligned columns, the last one left as it is (a note)."""
    widths = [max(len(h), *(len(r[j]) for r in rows)) if rows else len(h) for j, h in enumerate(head)]
    lines = ["  ".join(h.rjust(w) for h, w in zip(head, widths)).rstrip()]
    lines += ["  ".join(v.rjust(w) if j < len(head) - 1 else v for j, (v, w) in enumerate(zip(r, widths))).rstrip()
              for r in rows]
    return "\n".join(lines)


# ---------------------------------------------------------------------------------------- dynamics
TAU_COLUMNS = ("n_cells", "T", "p0", "B", "tissues", "relaxed", "tau_alpha", "tau_alpha_err", "tau_alpha_curve")


def summarize_dynamics(records: dict, curves: dict) -> dict:
    """tau_alpha per point (N, T, p0, B) from per-tissue records (:data:`DYNAMICS_COLUMNS`) and the
    points' averaged curves (:func:`spherevm.sweeps.dynamics.read_curves`): ``tissues``, ``relaxed``
    (tissues whose Q_s reached 1/e), ``tau_alpha`` (the mean over the tissues; NaN unless every
    tissue relaxed, since a mean over the relaxed ones only is biased low), ``tau_alpha_err`` (its
    standard error; NaN below two tissues) and ``tau_alpha_curve`` (where the point's averaged Q_s
    reaches 1/e, NaN if it does not)."""
    from ..analysis.dynamics import tau_alpha
    records = sorted_records(records, DYNAMICS_COLUMNS)
    out = {c: [] for c in TAU_COLUMNS}
    curve = {c: np.asarray(v) for c, v in curves.items()}
    for n, k in sorted(set(zip(records["n_cells"].tolist(), records["point"].tolist()))):
        mine = (records["n_cells"] == n) & (records["point"] == k)
        sel = (curve["n_cells"] == n) & (curve["point"] == k)
        tau = records["tau_alpha"][mine]
        every = bool(np.isfinite(tau).all())
        mean = float(np.mean(tau)) if every else math.nan
        err = float(np.std(tau, ddof=1) / math.sqrt(len(tau))) if every and len(tau) > 1 else math.nan
        row = (int(n), *(float(records[c][mine][0]) for c in ("T", "p0", "B")), len(tau),
               int(np.isfinite(tau).sum()), mean, err,
               float(tau_alpha(curve["time"][sel], curve["self_overlap"][sel], warn=False)))
        for c, v in zip(TAU_COLUMNS, row):
            out[c].append(v)
    return out


def write_dynamics_tables(out, records: dict) -> dict:
    """Write ``tissues.csv`` (every tissue's record), ``curves.csv`` (each point's MSD and Q_s,
    averaged over its tissues) and ``tau_alpha.csv`` (:func:`summarize_dynamics`) to the sweep folder.

    Parameters
    ----------
    out : str or path
        The sweep's folder (its ``curves/`` are read).
    records : dict
        The per-tissue records, such as :attr:`SweepResult.records` of a dynamics sweep.

    Returns
    -------
    dict
        ``tau_alpha`` and ``curves`` (the tables, dicts of columns) and the ``files`` written."""
    path = os.path.abspath(os.fspath(out))
    records = sorted_records(records, DYNAMICS_COLUMNS)
    curves = read_curves(path, records)
    tau = summarize_dynamics(records, curves)
    files = []
    for name, table, order in (("tissues.csv", records, DYNAMICS_COLUMNS.names), ("curves.csv", curves, None),
                               ("tau_alpha.csv", tau, TAU_COLUMNS)):
        write_columns(os.path.join(path, name), table, order)
        files.append(os.path.join(path, name))
    return {"tau_alpha": tau, "curves": curves, "files": files}


def format_tau_table(tau: dict) -> str:
    """tau_alpha per point as plain text."""
    head = ("N", "T", "p0", "B", "tau_alpha", "+-", "relaxed", "tau(<Q_s>)")
    rows = [(str(tau["n_cells"][i]), f"{tau['T'][i]:g}", f"{tau['p0'][i]:g}", f"{tau['B'][i]:g}",
             f"{tau['tau_alpha'][i]:.5g}", f"{tau['tau_alpha_err'][i]:.2g}",
             f"{tau['relaxed'][i]}/{tau['tissues'][i]}", f"{tau['tau_alpha_curve'][i]:.5g}")
            for i in range(len(tau["n_cells"]))]
    return _text_table(head, rows)
