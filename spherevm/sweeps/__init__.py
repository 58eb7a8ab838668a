"""Parameter sweeps over any :class:`concurrent.futures.Executor`: the athermal rigidity transition.

A :class:`RigiditySweep` names the sizes N, the p0 grid, the replicas per point, kr, the seed and
the minimiser's stop criteria. :func:`run_sweep` splits it into chunks (batched ensembles: many
(p0, replica) tilings of one N in one State, so every step serves all of them), runs the chunks on
an executor and writes each one to ``<out>/chunks/`` as soon as it finishes; a rerun with the same
parameters finds the finished chunks and computes only what is missing. :func:`write_tables` then
turns the per-replica records into F(p0, N), the distributions of p0* and p0*(N) (CSV, and PNG
when matplotlib is installed), using :mod:`spherevm.analysis.rigidity`.

::

    from spherevm import sweeps
    sweep = sweeps.RigiditySweep(cells=[16, 32], p0=np.arange(3.5, 4.001, 0.05), replicas=8)
    result = sweeps.run_sweep(sweep, "sweep/")            # process pool on the CPU
    tables = sweeps.write_tables("sweep/", result.records)
    print(tables["p0star"]["p0_star"])

Executors: by default the chunks run in this process when the device is a GPU (one big batch after
another) and on a :class:`~concurrent.futures.ProcessPoolExecutor` on the CPU. Any executor works,
for example a Dask cluster's (``client.get_executor()``, or pass the ``distributed.Client``
itself), which needs the optional ``cluster`` extra. Results do not depend on the executor or on
the chunking: every (N, p0, replica) tiling has its own seed and every replica is minimised
independently. See docs/rigidity.md.

:class:`DynamicsSweep` runs the glassy-dynamics protocol over (N, T, p0, B) on the same store and
executors (:func:`run_sweep` takes either); :func:`write_dynamics_tables` then writes tau_alpha per
point and the averaged MSD and Q_s curves. See docs/dynamics.md.

Modules: :mod:`.spec` (the parameters, seeds and chunks; :class:`Sweep`, what a sweep kind
provides), :mod:`.store` (the folder on disk), :mod:`.execution` (running chunks and sweeps),
:mod:`.dynamics` (the dynamics sweep), :mod:`.states` (the inherent states, kept with
``save_states=True``), :mod:`.tables` (summaries and plots). The command ``spherevm rigidity``
(:mod:`spherevm.cli.rigidity`) runs a rigidity sweep from the shell, and ``spherevm dynamics`` with
several values or ``--gpus`` (:mod:`spherevm.cli.dynamics_sweep`) a dynamics sweep.
"""
from . import cluster
from .dynamics import DynamicsSweep, run_dynamics_chunk
from .execution import (CPU_BATCH_CELLS, GPU_BATCH_CELLS, InProcessExecutor, SweepProgress, SweepResult,
                        TextProgress, build_chunk_state, default_executor, run_chunk, run_sweep)
from .spec import Chunk, RigiditySweep, Sweep, parse_p0_grid, plan_chunks, tiling_seed
from .store import (CHUNK_DIR, CURVE_DIR, DYNAMICS_COLUMNS, FORMAT, FORMAT_VERSION, MANIFEST, RECORD_COLUMNS,
                    open_sweep_folder, read_curves, read_records, scan_chunks, write_columns)
from .states import STATE_DIR, load_state
from .tables import (classify_records, format_p0star_table, format_tau_table, summarize_dynamics,
                     summarize_records, write_dynamics_tables, write_tables)

__all__ = ["CHUNK_DIR", "CPU_BATCH_CELLS", "CURVE_DIR", "Chunk", "DYNAMICS_COLUMNS", "DynamicsSweep", "FORMAT",
           "FORMAT_VERSION", "GPU_BATCH_CELLS", "InProcessExecutor", "MANIFEST", "RECORD_COLUMNS", "RigiditySweep",
           "STATE_DIR", "Sweep", "SweepProgress", "SweepResult", "TextProgress", "build_chunk_state",
           "classify_records", "default_executor", "format_p0star_table", "format_tau_table", "load_state",
           "open_sweep_folder", "parse_p0_grid", "plan_chunks", "read_curves", "read_records", "run_chunk",
           "run_dynamics_chunk", "run_sweep", "scan_chunks", "summarize_dynamics", "summarize_records", "tiling_seed",
           "write_columns", "write_dynamics_tables", "write_tables"]
