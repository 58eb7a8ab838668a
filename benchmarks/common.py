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
