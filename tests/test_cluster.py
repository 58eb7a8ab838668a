"""Sweeps on Dask clusters: a worker killed mid-chunk loses nothing, and a scheduler started the
way the SLURM recipe starts one (docs/rigidity.md) gives the same tables. The one-worker-per-GPU path (``--gpus``) needs
dask-cuda and GPUs: its tests are marked ``gpu`` (the killed worker needs two)."""
import os
import signal
import socket
import subprocess
import sys
import threading
import time

import numpy as np
import pytest

from spherevm import cli, sweeps

distributed = pytest.importorskip("distributed")

# 3 sizes x 2 p0 x 2 replicas, one chunk per (N, replica range): several chunks, each a second or two
SWEEP = dict(cells=[16, 20, 24], p0=[3.7, 3.9], replicas=2, seed=3)
COLUMNS = [c for c in sweeps.RECORD_COLUMNS if c not in ("chunk", "chunk_seconds")]


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    out = tmp_path_factory.mktemp("ref") / "sweep"
    return sweeps.run_sweep(sweeps.RigiditySweep(**SWEEP), out, executor=sweeps.InProcessExecutor(),
                            device="cpu", batch_cells=40).records


def same(records, reference):
    for col in COLUMNS:
        assert np.array_equal(np.asarray(records[col]), np.asarray(reference[col])), col


def kill_a_worker_mid_sweep(client, sweep, out, device, **run):
    """Run ``sweep`` on ``client``, SIGKILL one worker once the first chunk is on disk; returns the
    result (the chunk files finished before the kill are checked to be untouched)."""
    pids = client.run(os.getpid)
    box = {}

    def run_it():
        box["result"] = sweeps.run_sweep(sweep, out, executor=client, device=device, **run)

    worker = threading.Thread(target=run_it)
    worker.start()
    chunks = out / "chunks"
    deadline = time.time() + 120
    while time.time() < deadline and not (chunks.exists() and any(chunks.iterdir())):
        time.sleep(0.05)
    assert chunks.exists() and any(chunks.iterdir()), "no chunk finished in time"
    finished_before = {p.name: p.read_bytes() for p in chunks.iterdir()}
    busy = [address for address, keys in client.processing().items() if keys] or sorted(pids)
    os.kill(pids[busy[0]], signal.SIGKILL)                   # a worker dies in the middle of a chunk
    worker.join(timeout=300)
    assert not worker.is_alive()
    for name, data in finished_before.items():               # nothing finished before the kill was redone
        assert (chunks / name).read_bytes() == data
    return box["result"]


def test_a_worker_killed_mid_sweep_loses_no_chunk(tmp_path, reference):
    with sweeps.cluster.client(scheduler="local", workers=2) as client:
        result = kill_a_worker_mid_sweep(client, sweeps.RigiditySweep(**SWEEP), tmp_path / "sweep", "cpu",
                                         batch_cells=40)
    same(result.records, reference)


def _free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_scheduler_and_workers_started_like_the_slurm_recipe(tmp_path, reference, capsys):
    """docs/rigidity.md's recipe runs ``dask scheduler`` on one node and ``dask worker`` in each job;
    here both run on this machine's loopback address, and ``spherevm rigidity --scheduler`` uses them."""
    port = _free_port()
    address = f"tcp://127.0.0.1:{port}"
    recipe = {**os.environ, "DASK_DISTRIBUTED__SCHEDULER__WORKER_SATURATION": "2"}
    procs = [subprocess.Popen([sys.executable, "-m", "distributed.cli.dask_scheduler", "--host", "127.0.0.1",
                               "--port", str(port), "--no-dashboard"],
                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=recipe)]
    try:
        procs.append(subprocess.Popen([sys.executable, "-m", "distributed.cli.dask_worker", address, "--nworkers", "2",
                                       "--nthreads", "1", "--no-dashboard"],
                                      stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL))
        from distributed import Client
        with Client(address, timeout=60) as c:
            c.wait_for_workers(2, timeout=60)
            assert c.run_on_scheduler(lambda dask_scheduler: dask_scheduler.WORKER_SATURATION) == 2.0
        out = tmp_path / "sweep"
        rc = cli.main(["rigidity", "--cells", *map(str, SWEEP["cells"]), "--p0", *map(str, SWEEP["p0"]), "--replicas", "2",
                       "--seed", "3", "--scheduler", address, "--device", "cpu", "--batch-cells", "40", "--out", str(out),
                       "--no-plots", "--quiet"])
        assert rc == 0, capsys.readouterr().err
        resumed = sweeps.run_sweep(sweeps.RigiditySweep(**SWEEP), out, executor=sweeps.InProcessExecutor(),
                                   device="cpu", batch_cells=40)
        assert resumed.computed == []                    # every chunk came from the cluster run
        same(resumed.records, reference)
    finally:
        for p in procs[::-1]:
            p.terminate()
        for p in procs:
            p.wait(timeout=30)


def test_gpus_without_dask_cuda_is_a_clean_error(tmp_path, capsys):
    try:
        import dask_cuda  # noqa: F401
        pytest.skip("dask-cuda is installed here")
    except ImportError:
        pass
    rc = cli.main(["rigidity", "--cells", "16", "--p0", "3.7", "3.9", "--replicas", "1", "--gpus", "2",
                   "--out", str(tmp_path / "s"), "--quiet"])
    err = capsys.readouterr().err
    assert rc == 2 and "dask-cuda" in err and "cluster-cuda" in err
    with pytest.raises(ValueError, match="exactly one of scheduler"):
        sweeps.cluster.client(scheduler="local", gpus=1)


def test_tilings_prefetched_for_a_cluster_give_the_same_tables(tmp_path, reference):
    """``prefetch=True`` (the default for GPU workers): this machine builds the tilings in a process
    pool and sends each chunk its State, at most two chunks per worker in flight."""
    with sweeps.cluster.client(scheduler="local", workers=2) as client:
        result = sweeps.run_sweep(sweeps.RigiditySweep(**SWEEP), tmp_path / "sweep", executor=client, device="cpu",
                                  batch_cells=40, prefetch=True, workers=2)
    assert len(result.computed) > 4                  # more chunks than the four in flight at once
    same(result.records, reference)


def test_each_worker_holds_its_next_chunk():
    """The clusters this module starts let a worker hold two chunks (the one it runs and the next,
    whose tilings travel meanwhile), not Dask's default 1.1."""
    with sweeps.cluster.client(scheduler="local", workers=1) as client:
        saturation = client.run_on_scheduler(lambda dask_scheduler: dask_scheduler.WORKER_SATURATION)
    assert saturation == sweeps.cluster.WORKER_SATURATION == 2.0


def test_prefetch_must_be_a_bool(tmp_path):
    with pytest.raises(TypeError, match="prefetch must be True, False or None"):
        sweeps.run_sweep(sweeps.RigiditySweep(**SWEEP), tmp_path / "s", device="cpu", prefetch="yes")


@pytest.mark.gpu
def test_one_worker_per_gpu_gives_the_one_gpu_tables(tmp_path):
    """``--gpus N`` (dask-cuda, N = every GPU of this host, at most 2): the same records as the
    in-process GPU sweep."""
    pytest.importorskip("dask_cuda")
    cupy = pytest.importorskip("cupy")
    n = min(2, cupy.cuda.runtime.getDeviceCount())
    sweep = sweeps.RigiditySweep(cells=[48, 64], p0=[3.7, 3.85, 4.0], replicas=24, seed=5)
    one = sweeps.run_sweep(sweep, tmp_path / "one", device="gpu", batch_cells=2000, prefetch=True, workers=2)
    with sweeps.cluster.client(gpus=n) as client:
        many = sweeps.run_sweep(sweep, tmp_path / "many", executor=client, device="gpu", batch_cells=2000, workers=2)
    same(many.records, one.records)


@pytest.mark.gpu
def test_a_gpu_worker_killed_mid_sweep_loses_no_chunk(tmp_path):
    """``--gpus 2``: one GPU worker's process killed mid-sweep; its chunk is redone (by its restarted
    worker or the other GPU's), and the sweep ends with every chunk and the in-process sweep's records."""
    pytest.importorskip("dask_cuda")
    cupy = pytest.importorskip("cupy")
    if cupy.cuda.runtime.getDeviceCount() < 2:
        pytest.skip("needs two GPUs")
    sweep = sweeps.RigiditySweep(cells=[64, 128], p0=[3.7, 3.8, 3.9], replicas=64, seed=7)
    one = sweeps.run_sweep(sweep, tmp_path / "one", device="gpu", batch_cells=2000, prefetch=False)
    with sweeps.cluster.client(gpus=2) as client:
        result = kill_a_worker_mid_sweep(client, sweep, tmp_path / "two", "gpu", batch_cells=2000, prefetch=False)
    same(result.records, one.records)
    assert sorted(result.computed) == sorted(one.computed)


# dynamics: 2 temperatures x 3 tissues of N = 16, four chunks (tests/test_dynamics_sweep.py)
DYNAMICS = dict(cells=[16], T=[0.1, 0.2], p0=[3.9], replicas=3, chunk_replicas=2, steps=600, relax_steps=200,
                dt=0.02, seed=1)
DYNAMICS_ARGS = ["dynamics", "--cells", "16", "--T", "0.1", "0.2", "--p0", "3.9", "--replicas", "3",
                 "--chunk-replicas", "2", "--steps", "600", "--relax", "200", "--dt", "0.02", "--seed", "1",
                 "--device", "cpu", "--quiet"]


@pytest.fixture(scope="module")
def dynamics_reference(tmp_path_factory):
    out = tmp_path_factory.mktemp("dyn") / "sweep"
    result = sweeps.run_sweep(sweeps.DynamicsSweep(**DYNAMICS), out, executor=sweeps.InProcessExecutor(), device="cpu")
    sweeps.write_dynamics_tables(out, result.records)
    return out


def same_tables(out, reference):
    for name in ("tau_alpha.csv", "curves.csv"):
        assert (out / name).read_bytes() == (reference / name).read_bytes(), name


def test_a_dynamics_sweep_on_a_local_cluster_gives_the_in_process_tables(tmp_path, dynamics_reference, capsys):
    out = tmp_path / "sweep"
    rc = cli.main(DYNAMICS_ARGS + ["--scheduler", "local", "--workers", "2", "--out", str(out)])
    assert rc == 0, capsys.readouterr().err
    same_tables(out, dynamics_reference)


def test_a_worker_killed_mid_dynamics_chunk_has_its_chunk_redone(tmp_path, dynamics_reference):
    out = tmp_path / "sweep"
    with sweeps.cluster.client(scheduler="local", workers=2) as client:
        result = kill_a_worker_mid_sweep(client, sweeps.DynamicsSweep(**DYNAMICS), out, "cpu")
    assert len(result.computed) == 4
    sweeps.write_dynamics_tables(out, result.records)
    same_tables(out, dynamics_reference)


@pytest.mark.gpu
def test_a_dynamics_sweep_on_two_gpus_gives_the_one_gpu_tables(tmp_path):
    """``spherevm dynamics ... --gpus 2``: tau_alpha and the curves byte for byte as on one GPU."""
    pytest.importorskip("dask_cuda")
    cupy = pytest.importorskip("cupy")
    if cupy.cuda.runtime.getDeviceCount() < 2:
        pytest.skip("needs two GPUs")
    argv = [a for a in DYNAMICS_ARGS if a not in ("--device", "cpu")]
    assert cli.main(argv + ["--device", "gpu", "--out", str(tmp_path / "one")]) == 0
    assert cli.main(argv + ["--gpus", "2", "--out", str(tmp_path / "two")]) == 0
    same_tables(tmp_path / "two", tmp_path / "one")
