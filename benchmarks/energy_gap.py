"""The energy gap between zero-energy and rigid inherent states, per N, near the rigidity transition.

Runs a rigidity sweep with the project's own protocol (``spherevm.sweeps``, the defaults of
``RigiditySweep``) and prints, per N, among the *converged* replicas:

* the largest energy per cell of a state that stopped as zero energy (reason ``energy``, or any
  state below ``ZERO_ENERGY_TOL``): the top of the floppy side;
* the smallest energy per cell of a state that stopped on the force criterion (reason ``force``)
  above the tolerance: the rigid floor, with the (p0, replica, tiling seed) of that state, so it
  can be minimised again alone (``sweeps.run_chunk``);
* the widest empty interval (in decades) of the sorted energies, and whether
  ``ZERO_ENERGY_TOL`` lies inside it.

    python benchmarks/energy_gap.py                      # N = 32, 64; p0 = 3.70:3.90:0.02; 20 replicas
    python benchmarks/energy_gap.py --cells 16 32 64 --p0 3.55:3.95:0.025 --replicas 20 --seed 0

The table in docs/rigidity.md ("Zero energy or rigid") and the floor quoted next to
``spherevm.analysis.rigidity.ZERO_ENERGY_TOL`` come from this script.
"""
from __future__ import annotations

import argparse
import datetime
import math
import os
import platform
import shlex
import sys
import tempfile
import time

import numpy as np


def gap_table(records, zero_tol):
    """Per N: counts and the edges of the gap (see the module docstring); a list of dicts."""
    from spherevm.analysis.rigidity import classify
    status = classify(records["energy_per_cell"], records["reason"], zero_tol)
    e = np.asarray(records["energy_per_cell"], dtype=np.float64)
    reason = np.asarray(records["reason"]).astype(str)
    n_cells = np.asarray(records["n_cells"])
    rows = []
    for n in sorted(set(n_cells.tolist())):
        m = n_cells == n
        zero, rigid = m & (status == "zero"), m & (status == "rigid")
        rigid_force = rigid & (reason == "force")
        row = {"N": n, "n": int(m.sum()), "n_zero": int(zero.sum()), "n_rigid": int(rigid.sum()),
               "n_unconverged": int((m & ~np.isin(status, ["zero", "rigid"])).sum()),
               "zero_max": float(e[zero].max()) if zero.any() else math.nan,
               "rigid_min": float(e[rigid_force].min()) if rigid_force.any() else math.nan,
               "rigid_min_at": None, "rigid_low": []}
        if rigid_force.any():
            idx = np.flatnonzero(rigid_force)
            order = idx[np.argsort(e[idx])]
            for i in order[:5]:
                row["rigid_low"].append((float(e[i]), float(records["p0"][i]), int(records["replica"][i]),
                                         int(records["tiling_seed"][i]), int(records["steps"][i])))
            row["rigid_min_at"] = row["rigid_low"][0]
        conv = e[m & np.isin(status, ["zero", "rigid"])]
        conv = np.sort(conv[conv > 0])
        if len(conv) > 1:
            lg = np.log10(conv)
            k = int(np.argmax(np.diff(lg)))
            row["gap_low"], row["gap_high"], row["gap_decades"] = float(conv[k]), float(conv[k + 1]), float(lg[k + 1] - lg[k])
        else:
            row["gap_low"] = row["gap_high"] = row["gap_decades"] = math.nan
        rows.append(row)
    return rows


def main(argv=None):
    ap = argparse.ArgumentParser(allow_abbrev=False, description=__doc__.splitlines()[0])
    ap.add_argument("--cells", type=int, nargs="+", default=[32, 64])
    ap.add_argument("--p0", nargs="+", default=["3.70:3.90:0.02"])
    ap.add_argument("--replicas", type=int, default=20)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--kr", type=float, default=0.0)
    ap.add_argument("--device", default="cpu")
    ap.add_argument("--workers", type=int, default=None)
    ap.add_argument("--out", default=None, help="sweep folder (default: a temporary one, removed)")
    args = ap.parse_args(argv)

    from spherevm import sweeps
    from spherevm.analysis.rigidity import ZERO_ENERGY_TOL
    from spherevm.provenance import source_fingerprint

    sweep = sweeps.RigiditySweep(cells=tuple(args.cells), p0=tuple(sweeps.parse_p0_grid(args.p0)),
                                 replicas=args.replicas, kr=args.kr, seed=args.seed)
    print("# command: python " + " ".join(shlex.quote(a) for a in [sys.argv[0], *sys.argv[1:]]))
    print(f"# {datetime.date.today()}  {platform.machine()} {os.cpu_count()} cores, Python "
          f"{platform.python_version()}, device={args.device}, code {source_fingerprint()[:12]}")
    print(f"# sweep: N = {list(sweep.cells)}, {len(sweep.p0)} p0 from {sweep.p0[0]} to {sweep.p0[-1]}, "
          f"{sweep.replicas} replicas, kr = {sweep.kr}, seed = {sweep.seed}, force_tol = {sweep.force_tol}, "
          f"energy_tol = {sweep.energy_tol}; ZERO_ENERGY_TOL = {ZERO_ENERGY_TOL:g}")
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:
        out = args.out or os.path.join(tmp, "sweep")
        result = sweeps.run_sweep(sweep, out, device=args.device, workers=args.workers)
    print(f"# {sweep.total_units} minimisations in {time.perf_counter() - t0:.0f} s")
    rows = gap_table(result.records, ZERO_ENERGY_TOL)
    print(f"{'N':>5} {'zero':>5} {'rigid':>5} {'unconv':>6} {'largest zero':>13} {'smallest rigid':>15} "
          f"{'widest gap (decades)':>22}  tol inside")
    for r in rows:
        inside = r["gap_low"] < ZERO_ENERGY_TOL < r["gap_high"]
        print(f"{r['N']:5d} {r['n_zero']:5d} {r['n_rigid']:5d} {r['n_unconverged']:6d} {r['zero_max']:13.2e} "
              f"{r['rigid_min']:15.2e} {r['gap_low']:9.1e}..{r['gap_high']:7.1e} ({r['gap_decades']:4.1f})  {inside}")
    allz = [r["zero_max"] for r in rows if np.isfinite(r["zero_max"])]
    allr = [r["rigid_min"] for r in rows if np.isfinite(r["rigid_min"])]
    if allz and allr:
        print(f"# all N: largest zero-energy state {max(allz):.2e}, smallest rigid (reason force) {min(allr):.2e} "
              "per cell")
    print("# lowest rigid states (energy per cell, p0, replica, tiling_seed, steps):")
    for r in rows:
        for low in r["rigid_low"]:
            print(f"#   N = {r['N']:4d}: {low[0]:.3e}  p0 = {low[1]:.3f}  replica {low[2]:3d}  "
                  f"tiling_seed {low[3]}  steps {low[4]}")
    return rows


if __name__ == "__main__":
    main()
