"""Host process pools for sweeps: their workers start from a fork server that has imported
spherevm once, so a pool of one process a core is ready in a fraction of a second instead of each
worker importing NumPy, SciPy and spherevm on its own (docs/performance.md, "Several GPUs")."""
from __future__ import annotations

import concurrent.futures as cf
import multiprocessing
import signal

#: what the fork server imports once, before it forks the pools' workers (none of them touches CUDA)
PRELOAD = ["spherevm.init", "spherevm.simulation", "spherevm.plugins", "spherevm.sweeps"]


def process_pool(workers: int, initializer=None, initargs=()) -> cf.ProcessPoolExecutor:
    """A ProcessPoolExecutor of ``workers`` processes forked from the preloaded fork server, or
    spawned where there is no fork server (Windows). Never plain fork: the sweep's process may hold a
    CUDA context or a Dask client's threads."""
    if "forkserver" in multiprocessing.get_all_start_methods():
        context = multiprocessing.get_context("forkserver")
        context.set_forkserver_preload(PRELOAD)
    else:
        context = multiprocessing.get_context("spawn")
    return cf.ProcessPoolExecutor(max_workers=workers, mp_context=context, initializer=initializer,
                                  initargs=initargs)


def ignore_interrupts():
    """In a pool worker: Ctrl-C is the main process's business (it stops the workers), so a worker
    neither prints a traceback nor reports a chunk as failed when the terminal sends SIGINT to all."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
