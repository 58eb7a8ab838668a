"""Timing helpers shared by the benchmarks: warm-up, device synchronisation, medians."""
from __future__ import annotations

import statistics
import time


def median_time(fn, device=None, repeat=11, warmup=2):
    """Median wall time of ``fn()`` in seconds, after ``warmup`` calls, synchronising the device."""
    for _ in range(warmup):
        fn()
    if device is not None:
        device.synchronize()
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        if device is not None:
            device.synchronize()
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def median_times(fns, device=None, repeat=11, warmup=2, clock=time.perf_counter):
    """Median times (seconds; wall time unless ``clock`` says otherwise, e.g. ``time.process_time``
    for the CPU time of all the process's threads) of several callables, timed in turn within each
    round (round robin), so that a change of machine load over the run affects them alike: for
    ratios on a shared machine."""
    for fn in fns:
        for _ in range(warmup):
            fn()
    if device is not None:
        device.synchronize()
    times = [[] for _ in fns]
    for _ in range(repeat):
        for fn, t in zip(fns, times):
            t0 = clock()
            fn()
            if device is not None:
                device.synchronize()
            t.append(clock() - t0)
    return [statistics.median(t) for t in times]


def run_step_time(sim, device, steps=1000, repeat=5, **run):
    """Median seconds per step of ``sim.run(steps, graphs=True, **run)`` (CUDA graphs, or the fused
    small-tissue steps where they apply unless ``fused=False``; checks every 100 steps as by default;
    each run captures its graphs again, so the capture is in the time)."""
    return median_time(lambda: sim.run(steps, graphs=True, **run), device, repeat=repeat, warmup=1) / steps


def minimize_step_time(sim, device, steps=1000, repeat=5, **minimize):
    """Median seconds per iteration of ``sim.minimize(max_steps=steps, graphs=True, **minimize)`` with the
    tolerances at zero (every replica iterates throughout), a convergence check every 100 iterations
    and no narrowing: CUDA graphs, or the fused small-tissue minimisation where it applies unless
    ``fused=False`` (each call captures its graphs again, so the capture is in the time)."""
    return median_time(lambda: sim.minimize(max_steps=steps, force_tol=0.0, energy_tol=0.0, check_every=100, narrow=False,
                                            graphs=True, **minimize), device, repeat=repeat, warmup=1) / steps
