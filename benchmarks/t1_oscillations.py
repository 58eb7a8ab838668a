"""How often floppy states are stopped for T1 flip-back cycles, per T1 rule (docs/t1.md).

    python benchmarks/t1_oscillations.py [--cells 256] [--p0 3.88 3.81] [--replicas 16] [--seed 0]
    python benchmarks/t1_oscillations.py --cells 64 --p0 3.8 3.85 3.925 --replicas 8 \
        --rules "max flip-backs 10" "max flip-backs 100 (default)"

For each p0 and each rule (fresh edge 0.06 = the earlier default, 0.12 = ``T1()``'s default, and
the paper code's ``reference`` rule), a sweep of ``replicas`` random tilings (``spherevm.sweeps``,
kr = 0, other parameters at their defaults) is minimised (the second command: the flip-back
limit, 10 against the sweep default 100); printed: how many reached zero energy,
were rigid, or stopped as ``t1_oscillation`` / ``max_steps``.
"""
import argparse
import datetime
import os
import platform
import tempfile
import time

from spherevm import sweeps
from spherevm.analysis.rigidity import classify

RULES = {"new edge 0.06": dict(t1_new_length=0.06), "new edge 0.12 (default)": {},
         "reference": sweeps.RigiditySweep.reference_t1(),
         "max flip-backs 10": dict(t1_max_flip_backs=10), "max flip-backs 100 (default)": {}}


def main(argv=None):
    ap = argparse.ArgumentParser(allow_abbrev=False, description=__doc__.splitlines()[0])
    ap.add_argument("--cells", type=int, default=256)
    ap.add_argument("--p0", type=float, nargs="+", default=[3.88, 3.81])
    ap.add_argument("--replicas", type=int, default=16)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--rules", nargs="+", default=list(RULES)[:3], choices=list(RULES))
    ap.add_argument("--device", default="cpu")
    args = ap.parse_args(argv)
    print(f"# {datetime.date.today()} {platform.machine()} {os.cpu_count()} cores, device={args.device}, "
          f"N = {args.cells}, {args.replicas} replicas, seed {args.seed}, kr = 0")
    print(f"{'p0':>6}  {'rule':<29} {'zero':>5} {'rigid':>5} {'t1_osc':>6} {'max_steps':>9} {'s':>5}")
    for p0 in args.p0:
        for name in args.rules:
            sweep = sweeps.RigiditySweep(cells=(args.cells,), p0=(p0,), replicas=args.replicas, seed=args.seed,
                                         **RULES[name])
            t0 = time.perf_counter()
            with tempfile.TemporaryDirectory() as tmp:
                rec = sweeps.run_sweep(sweep, os.path.join(tmp, "s"), device=args.device).records
            st = classify(rec["energy_per_cell"], rec["reason"]).tolist()
            print(f"{p0:6.3f}  {name:<29} {st.count('zero'):5d} {st.count('rigid'):5d} "
                  f"{st.count('t1_oscillation'):6d} {st.count('max_steps'):9d} {time.perf_counter() - t0:5.0f}",
                  flush=True)


if __name__ == "__main__":
    main()
