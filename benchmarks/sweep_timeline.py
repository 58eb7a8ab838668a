"""Where a rigidity sweep's time goes on one or several GPUs: a per-chunk timeline.

    python benchmarks/sweep_timeline.py --gpus 1 2 --replicas 100 --out /tmp/timeline

For each ``--gpus`` value (alternated ``--repeat`` times) it starts the cluster (timed), runs the
sweep into a fresh folder with ``run_sweep(..., timeline=True)`` and prints: the cluster's start,
the sweep's wall time, per worker its busy share (tilings built in the worker, minimisation) and its
first start and last end, how long the sweep waited for prefetched tilings, the delay between
submitting a chunk and its worker starting it (queue and transfer), and the tail (the last worker's
end after the first worker ran out of work). It writes each run's timeline as CSV (one row a chunk,
seconds from the sweep's start) and checks that every run gave the same tables. Needs dask-cuda;
``--cpu-workers N`` times a LocalCluster of N processes on the CPU instead (``--gpus`` ignored).

A ``--gpus`` value may carry the tiling pool's settings, to compare them in one alternated call:
``4:nice=0`` (the tiling workers' niceness, default ``TILING_NICENESS``), ``4:tilers=16`` (the pool's
processes, default one a core not driving a GPU), or both (``4:nice=0:tilers=16``).
"""
import argparse
import csv
import hashlib
import os
import shutil
import statistics
import time

from spherevm.sweeps import RigiditySweep, cluster, parse_p0_grid, tilings, run_sweep, write_tables

PAPER_CELLS = (32, 48, 64, 96, 128, 192, 256, 512, 1024)


def summarize(result, cluster_start):
    """One run's figures (seconds) from its timeline."""
    t0, rows = result.started, result.timeline
    workers = {}
    for r in rows:
        workers.setdefault(r["pid"], []).append(r)
    end = max(r["written"] for r in rows) - t0
    busy = {pid: sum(r["ended"] - r["started"] for r in rs) for pid, rs in workers.items()}
    last_ends = sorted(max(r["ended"] for r in rs) - t0 for rs in workers.values())
    return {
        "cluster_start": cluster_start, "sweep": result.elapsed, "chunks": len(rows), "workers": len(workers),
        "busy_share": statistics.mean(b / end for b in busy.values()),
        "minimize_share": statistics.mean(sum(r["minimized"] - r["built"] for r in rs) / end for rs in workers.values()),
        "build_in_worker": sum(r["built"] - r["started"] for r in rows),
        "first_start": min(r["started"] for r in rows) - t0,
        "waiting_for_tilings": sum(r["submitted"] - r["asked"] for r in rows),
        "submit_to_start_median": statistics.median(r["started"] - r["submitted"] for r in rows),
        "result_lag_median": statistics.median(r["received"] - r["ended"] for r in rows),
        "tail": last_ends[-1] - last_ends[0],
    }


def parse_run(text):
    """``"4:nice=0:tilers=16"`` -> (label, gpus, niceness or None, tiling processes or None)."""
    gpus, *options = text.split(":")
    settings = dict(o.split("=", 1) for o in options)
    unknown = set(settings) - {"nice", "tilers"}
    if unknown:
        raise SystemExit(f"unknown run setting(s) {sorted(unknown)} in {text!r}: use nice= and tilers=")
    as_int = {k: int(v) for k, v in settings.items()}
    return text.replace(":", "_").replace("=", ""), int(gpus), as_int.get("nice"), as_int.get("tilers")


def write_timeline(path, result):
    keys = ["chunk", "n_cells", "size", "pid", "asked", "submitted", "started", "built", "minimized", "ended",
            "received", "written"]
    with open(path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(keys)
        for r in result.timeline:
            w.writerow([r[k] if k in ("chunk", "n_cells", "size", "pid") else f"{r[k] - result.started:.4f}"
                        for k in keys])


def tables_digest(folder):
    h = hashlib.sha256()
    for name in ("fraction.csv", "p0star.csv"):
        with open(os.path.join(folder, name), "rb") as f:
            h.update(f.read())
    return h.hexdigest()[:12]


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter,
                                 allow_abbrev=False)
    ap.add_argument("--gpus", nargs="+", default=["1", "2"], help="GPUs per run, e.g. 1 4 4:nice=0 4:tilers=16")
    ap.add_argument("--cells", type=int, nargs="+", default=list(PAPER_CELLS))
    ap.add_argument("--p0", default="3.60:3.95:0.01")
    ap.add_argument("--replicas", type=int, default=100)
    ap.add_argument("--batch-cells", type=int, default=None)
    ap.add_argument("--prefetch", choices=("auto", "yes", "no"), default="auto")
    ap.add_argument("--repeat", type=int, default=1)
    ap.add_argument("--cpu-workers", type=int, default=None)
    ap.add_argument("--out", default="sweep_timeline")
    args = ap.parse_args()
    sweep = RigiditySweep(cells=args.cells, p0=parse_p0_grid([args.p0]), replicas=args.replicas, kr=0.0)
    prefetch = {"auto": None, "yes": True, "no": False}[args.prefetch]
    os.makedirs(args.out, exist_ok=True)
    digests, figures = set(), {}
    device = "gpu" if args.cpu_workers is None else "cpu"
    default_niceness = tilings.TILING_NICENESS
    runs = [parse_run(g) for g in args.gpus] if device == "gpu" else [(f"cpu{args.cpu_workers}", args.cpu_workers,
                                                                      None, None)]
    for rep in range(args.repeat):
        for label, g, niceness, tilers in runs:
            folder = os.path.join(args.out, f"gpus{label}_run{rep}")
            shutil.rmtree(folder, ignore_errors=True)
            tilings.TILING_NICENESS = default_niceness if niceness is None else niceness
            t = time.perf_counter()
            client = cluster.client(gpus=g) if device == "gpu" else cluster.client(scheduler="local", workers=g)
            started = time.perf_counter() - t
            try:
                result = run_sweep(sweep, folder, executor=client, device=device, batch_cells=args.batch_cells,
                                   prefetch=prefetch, timeline=True, workers=tilers)
            finally:
                client.close()
            write_tables(folder, result.records, plots=False)
            digests.add(tables_digest(folder))
            write_timeline(os.path.join(args.out, f"timeline_gpus{label}_run{rep}.csv"), result)
            s = summarize(result, started)
            figures.setdefault(label, []).append(s)
            print(f"gpus={label} run {rep}: " + ", ".join(f"{k}={v:.3g}" if isinstance(v, float) else f"{k}={v}"
                                                          for k, v in s.items()), flush=True)
    for label, rs in figures.items():
        print(f"gpus={label}: sweep median {statistics.median(r['sweep'] for r in rs):.2f} s over {len(rs)} run(s); "
              f"cluster start median {statistics.median(r['cluster_start'] for r in rs):.2f} s")
    print(f"tables identical across runs: {len(digests) == 1} ({sorted(digests)})")


if __name__ == "__main__":
    main()
