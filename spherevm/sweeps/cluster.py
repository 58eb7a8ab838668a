"""Dask clusters for sweeps: this machine's cores, one worker per GPU of this host, or a running
scheduler (a SLURM allocation started as docs/rigidity.md shows).

Each worker runs whole chunks (:func:`spherevm.sweeps.execution.run_chunk`): it builds the chunk's
tilings on its own host cores and minimises them on its device. A worker that dies mid-chunk loses
only that chunk: Dask gives the task to another worker, and every chunk already finished is on
disk, so a sweep's tables do not depend on what failed on the way (tests/test_cluster.py).
"""
from __future__ import annotations

from ..validation import integer

#: chunks a single-threaded worker holds at once: the one it minimises and the next, whose tilings
#: travel to it meanwhile (Dask's ``distributed.scheduler.worker-saturation``; its default, 1.1,
#: sends the next chunk only when the worker asks, and the worker waits for the transfer)
WORKER_SATURATION = 2.0


def client(scheduler: str | None = None, gpus: int | None = None, workers: int | None = None):
    """A ``distributed.Client``: ``gpus=N`` starts one worker per GPU of this host (dask-cuda's
    ``LocalCUDACluster``, each worker pinned to its GPU); ``scheduler="local"`` one single-threaded
    worker process per core (or ``workers``); any other ``scheduler`` is an address such as
    ``tcp://host:8786`` of a scheduler whose workers are already running (start that scheduler with
    :data:`WORKER_SATURATION` in its Dask config to overlap the chunks' transfers with their runs)."""
    if (scheduler is None) == (gpus is None):
        raise ValueError("give exactly one of scheduler (an address or 'local') and gpus")
    try:
        import dask
        from distributed import Client, LocalCluster
    except ImportError:
        raise ValueError("a Dask cluster needs spherevm[cluster] (dask[distributed])") from None
    with dask.config.set({"distributed.scheduler.worker-saturation": WORKER_SATURATION}):
        if gpus is not None:
            gpus = integer("gpus", gpus, minimum=1)
            try:
                from dask_cuda import LocalCUDACluster
            except ImportError:
                raise ValueError("gpus needs dask-cuda: pip install 'spherevm[cluster-cuda]'") from None
            return Client(LocalCUDACluster(CUDA_VISIBLE_DEVICES=list(range(gpus)), threads_per_worker=1))
        if scheduler == "local":
            n = None if workers is None else integer("workers", workers, minimum=1)
            return Client(LocalCluster(n_workers=n, threads_per_worker=1, processes=True))
    return Client(scheduler)
