"""Compare two sweep folders record by record: same outcome for every (N, p0, replica)?

    python benchmarks/compare_sweeps.py sweepA/ sweepB/ [--zero-tol 1e-12]

Reads every chunk file of both folders (``<folder>/chunks/*.csv``) and reports, over the units
both hold, how many differ in reason, in T1 flips, and in zero energy or not
(``analysis.rigidity.classify``), and the largest relative difference of energy per cell among
states that are rigid in both. docs/results.md ("two runs compared record by record") used it on
two ``spherevm rigidity`` folders of the same parameters.
"""
import argparse
import glob
import os

import numpy as np

from spherevm.analysis.rigidity import ZERO_ENERGY_TOL, classify
from spherevm.sweeps import read_records


def load(folder):
    out = {}
    for f in sorted(glob.glob(os.path.join(folder, "chunks", "*.csv"))):
        r = read_records(f)
        for i in range(len(r["n_cells"])):
            out[(int(r["n_cells"][i]), round(float(r["p0"][i]), 6), int(r["replica"][i]))] = (
                float(r["energy_per_cell"][i]), str(r["reason"][i]), int(r["t1_flips"][i]))
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(allow_abbrev=False, description=__doc__.splitlines()[0])
    ap.add_argument("a")
    ap.add_argument("b")
    ap.add_argument("--zero-tol", type=float, default=ZERO_ENERGY_TOL)
    args = ap.parse_args(argv)
    a, b = load(args.a), load(args.b)
    keys = sorted(set(a) & set(b))
    if not keys:
        raise SystemExit("no common units")
    ea, ra, fa = (np.array(v) for v in zip(*(a[k] for k in keys)))
    eb, rb, fb = (np.array(v) for v in zip(*(b[k] for k in keys)))
    sa, sb = classify(ea, ra, args.zero_tol), classify(eb, rb, args.zero_tol)
    both_rigid = (sa == "rigid") & (sb == "rigid")
    rel = np.abs(ea - eb)[both_rigid] / np.abs(ea)[both_rigid]
    print(f"units in both: {len(keys)} (only in A: {len(set(a) - set(b))}, only in B: {len(set(b) - set(a))})")
    print(f"different reason: {int((ra != rb).sum())}, different T1 flips: {int((fa != fb).sum())}, "
          f"different status (zero/rigid/...): {int((sa != sb).sum())}")
    if rel.size:
        print(f"rigid in both: {rel.size}, largest relative energy difference {rel.max():.1e}")


if __name__ == "__main__":
    main()
