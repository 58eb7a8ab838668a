"""Rigidity sweeps: F(p0, N), p0* distributions, chunked resumable runs on any executor."""
import csv
import json
import math
import os
import shutil
import warnings

import numpy as np
import pytest

import spherevm as svm
from spherevm import sweeps
from spherevm.analysis import pentagon_perimeter, rigidity
from spherevm.provenance import source_fingerprint

# Tiny sweeps: N = 16 far from the transition (p0 = 3.3 rigid, 4.2 floppy) converge in a few
# hundred steps; the comparisons below are exact, since results do not depend on the chunking.
TINY = dict(cells=[16], p0=[3.3, 4.2], replicas=2)


def _same_records(a, b):
    for col in sweeps.RECORD_COLUMNS:
        if col in ("chunk", "chunk_seconds"):
            continue
        assert np.array_equal(np.asarray(a[col]), np.asarray(b[col])), col


@pytest.fixture(scope="module")
def tiny_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("tiny") / "sweep"
    seen = []
    result = sweeps.run_sweep(sweeps.RigiditySweep(**TINY), out, executor=sweeps.InProcessExecutor(),
                              device="cpu", batch_cells=32, progress=lambda p: seen.append(p.units_done))
    return out, result, seen


# ------------------------------------------------------------------------------------ statistics
def test_binomial_error_and_wilson_interval():
    assert sweeps  # the module imports without dask or matplotlib being used
    err = rigidity.binomial_error([0, 5, 10, 3], [10, 10, 10, 0])
    assert err[0] == 0 and err[2] == 0 and math.isnan(err[3])
    assert err[1] == pytest.approx(math.sqrt(0.25 / 10))
    lo, hi = rigidity.wilson_interval([0, 5, 10], [10, 10, 10])
    assert lo[0] == 0 and 0 < hi[0] < 0.2          # F = 0 still gets an upper error bar
    assert lo[1] < 0.5 < hi[1] and hi[1] - 0.5 == pytest.approx(0.5 - lo[1])
    assert hi[2] == 1 and 0.8 < lo[2] < 1


def test_classify_separates_unconverged():
    e = [1e-20, 3e-3, 1e-20, 2e-2, 1e-9, 5e-13]
    reason = ["energy", "force", "max_steps", "t1_oscillation", "force", "force"]
    status = rigidity.classify(e, reason, zero_tol=1e-12)
    assert list(status) == ["zero", "rigid", "max_steps", "t1_oscillation", "rigid", "zero"]
    with pytest.raises(ValueError, match="zero_tol"):
        rigidity.classify(e, reason, zero_tol=0)
    with pytest.raises(ValueError, match="same shape"):
        rigidity.classify(e, reason[:2])
    # a sweep's tissues that end with inverted cells, on request: left out of F; -1 (not measured) is not one
    records = {"energy_per_cell": e, "reason": reason, "inverted_cells": [3, 1, 2, 0, -1, 0]}
    assert list(sweeps.classify_records(records, 1e-12)) == list(status)
    assert list(sweeps.classify_records(records, 1e-12, exclude_inverted=True)) == [
        "inverted", "inverted", "max_steps", "t1_oscillation", "rigid", "zero"]


def test_zero_fraction_counts_unconverged_separately():
    n = [16] * 6 + [32] * 2
    p0 = [3.7, 3.7, 3.7, 3.7, 3.8, 3.8, 3.7, 3.7]
    status = ["zero", "rigid", "max_steps", "t1_oscillation", "zero", "zero", "rigid", "rigid"]
    f = rigidity.zero_fraction(n, p0, status)
    assert list(f["n_cells"]) == [16, 16, 32] and list(f["p0"]) == [3.7, 3.8, 3.7]
    assert list(f["F"]) == [0.5, 1.0, 0.0]                   # unconverged not in the denominator
    assert list(f["n_unconverged"]) == [2, 0, 0]
    assert list(f["n_max_steps"]) == [1, 0, 0] and list(f["n_t1_oscillation"]) == [1, 0, 0]
    assert f["F_unconverged_rigid"][0] == 0.25 and f["F_unconverged_zero"][0] == 0.75
    assert f["F_err"][0] == pytest.approx(math.sqrt(0.25 / 2))


def _logistic(x, p0c, w):
    return 1 / (1 + np.exp(-(x - p0c) / w))


def test_p0_star_of_a_logistic_step():
    x = np.round(np.arange(3.55, 4.0501, 0.01), 10)
    w = 0.02
    F = _logistic(x, 3.8, w)
    est = rigidity.p0_star(x, F)
    assert est.mean == pytest.approx(3.8, abs=2e-4)
    assert est.p0_half == pytest.approx(3.8, abs=1e-3)
    assert est.bracketed
    true_std = math.pi * w / math.sqrt(3)                    # the logistic distribution's
    assert est.std_unsmoothed == pytest.approx(true_std, rel=0.03)
    assert est.sigma == pytest.approx(0.5 * est.std_unsmoothed, rel=0.05)   # the documented rule
    assert est.std == pytest.approx(math.hypot(est.std_unsmoothed, est.sigma), rel=1e-9)
    # the smoothed density is normalised, and its numerical moments match the exact ones
    grid = np.linspace(3.3, 4.3, 4001)
    d = rigidity.transition_density(x, F, est.sigma, grid)
    h = grid[1] - grid[0]
    assert d.sum() * h == pytest.approx(1, abs=1e-3)
    mean = (grid * d).sum() * h
    assert mean == pytest.approx(est.mean, abs=1e-4)
    assert math.sqrt(((grid - mean) ** 2 * d).sum() * h) == pytest.approx(est.std, rel=1e-3)
    # the mean does not depend on sigma; the peak sits at p0c
    assert grid[np.argmax(d)] == pytest.approx(3.8, abs=5e-3)
    assert rigidity.p0_star(x, F, sigma=0.05).mean == pytest.approx(est.mean, abs=1e-12)


def test_p0_star_with_binomial_noise_and_sharp_step():
    rng = np.random.default_rng(3)
    x = np.round(np.arange(3.6, 4.0001, 0.02), 10)
    n = np.full(len(x), 200)
    k = rng.binomial(n, _logistic(x, 3.78, 0.03))
    est = rigidity.p0_star(x, k / n, n)
    assert est.mean == pytest.approx(3.78, abs=3 * est.mean_err + 1e-3)
    assert 0 < est.mean_err < 0.01
    # a step inside one interval: sigma falls back to half the spacing, mean at the interval centre
    F = (x > 3.79).astype(float)
    est = rigidity.p0_star(x, F)
    assert est.sigma == pytest.approx(0.01) and est.mean == pytest.approx(3.79)
    # F not reaching 1 in the grid is flagged
    assert not rigidity.p0_star(x, 0.5 * _logistic(x, 3.8, 0.03)).bracketed
    with pytest.raises(ValueError, match="two or more"):
        rigidity.p0_star([3.7], [0.5])


def test_summarize_and_critical_perimeter():
    x = np.round(np.arange(3.6, 3.9001, 0.02), 10)
    n_cells, p0, status = [], [], []
    for N, pc in ((32, 3.72), (64, 3.76)):
        for p in x:
            k = int(round(20 * _logistic(p, pc, 0.01)))
            n_cells += [N] * 20
            p0 += [p] * 20
            status += ["zero"] * k + ["rigid"] * (20 - k)
    frac, p0star, density = rigidity.summarize(n_cells, p0, status, resamples=50)
    assert list(p0star["n_cells"]) == [32, 64]
    assert p0star["p0_star"][0] == pytest.approx(3.72, abs=0.005)
    assert p0star["p0_star"][1] == pytest.approx(3.76, abs=0.005)
    assert list(p0star["pentagon_perimeter"]) == pytest.approx(list(pentagon_perimeter([32, 64])))
    assert set(density["n_cells"]) == {32, 64}
    assert rigidity.critical_perimeter(3.8, 4.0) == pytest.approx(7.6)
    assert np.allclose(rigidity.critical_perimeter(np.array([3.7]), np.array([0.25, 1.0])), [1.85, 3.7])


# ------------------------------------------------------------------------------------ bad input
@pytest.mark.parametrize("kwargs, match", [
    (dict(p0=[]), "empty"),
    (dict(p0=[3.8, 3.7]), "strictly increasing"),
    (dict(p0=[3.7, 3.7]), "strictly increasing"),
    (dict(p0=[3.7, float("nan")]), "finite"),
    (dict(replicas=0), "replicas"),
    (dict(replicas=1.5), "replicas"),
    (dict(cells=[3]), "cells"),
    (dict(cells=[]), "cells"),
    (dict(cells=[16, 16]), "repeat"),
    (dict(kr=-1), "kr"),
    (dict(dt=0), "dt"),
    (dict(seed=-1), "seed"),
])
def test_bad_sweep_parameters(kwargs, match):
    with pytest.raises(ValueError, match=match):
        sweeps.RigiditySweep(**{**TINY, **kwargs})


def test_unwritable_or_foreign_output_folder(tmp_path):
    sweep = sweeps.RigiditySweep(**TINY)
    afile = tmp_path / "afile"
    afile.write_text("x")
    before = sorted(os.listdir(tmp_path))
    for out in (afile, afile / "sub" / "sweep", ""):
        with pytest.raises(ValueError, match="folder|path"):
            sweeps.run_sweep(sweep, out, executor=sweeps.InProcessExecutor(), device="cpu")
    assert sorted(os.listdir(tmp_path)) == before          # nothing created
    foreign = tmp_path / "foreign"
    foreign.mkdir()
    (foreign / "notes.txt").write_text("mine")
    with pytest.raises(ValueError, match="not a rigidity sweep folder"):
        sweeps.run_sweep(sweep, foreign, executor=sweeps.InProcessExecutor(), device="cpu")
    assert os.listdir(foreign) == ["notes.txt"]
    with pytest.raises(ValueError, match="device"):
        sweeps.run_sweep(sweep, tmp_path / "new", device="tpu")
    with pytest.raises(ValueError, match="workers"):
        sweeps.run_sweep(sweep, tmp_path / "new", workers=0)
    assert not (tmp_path / "new").exists()


def test_unwritable_output_place(tmp_path):
    """An output folder that cannot be created (its parent is a file: true for root too) is refused
    before anything runs, naming the path."""
    parent = tmp_path / "notes.txt"
    parent.write_text("mine")
    with pytest.raises(ValueError, match="cannot create output folder .*notes.txt.* is not a folder"):
        sweeps.run_sweep(sweeps.RigiditySweep(**TINY), parent / "sweep", executor=sweeps.InProcessExecutor())
    assert parent.read_text() == "mine"


# ------------------------------------------------------------------------------------ running
def test_tiny_sweep_records_and_manifest(tiny_run):
    out, result, seen = tiny_run
    rec = result.records
    assert len(rec["n_cells"]) == 4 and result.reused == 0
    assert sorted(result.computed) == ["N00016_u000000-000002", "N00016_u000002-000004"]
    assert seen == [0, 2, 4]
    status = rigidity.classify(rec["energy_per_cell"], rec["reason"])
    assert list(status) == ["rigid", "rigid", "zero", "zero"]     # p0 = 3.3 rigid, 4.2 floppy at N = 16
    assert np.all(rec["energy_per_cell"][:2] > 1e-3) and np.all(rec["energy_per_cell"][2:] < 1e-15)
    manifest = json.loads((out / "manifest.json").read_text())
    assert manifest["parameters"] == sweeps.RigiditySweep(**TINY).parameters()
    assert manifest["code"] == source_fingerprint()
    assert sorted(os.listdir(out / "chunks")) == ["N00016_u000000-000002.csv", "N00016_u000002-000004.csv"]
    # every (N, p0, replica) has its own tiling
    assert len(set(rec["tiling_seed"])) == 4


def test_tiling_depends_on_n_p0_replica_only(tiny_run, tmp_path):
    """Another grid (one more p0 before the others, one more replica, other chunks): the same (N, p0, replica) gets the
    same tiling seed and the same minimised energy; and the seed is what builds the tiling."""
    _, result, _ = tiny_run
    other = sweeps.run_sweep(sweeps.RigiditySweep(cells=[16], p0=[3.0, 3.3, 4.2], replicas=3), tmp_path / "other",
                             executor=sweeps.InProcessExecutor(), device="cpu", batch_cells=16)

    def by_unit(rec):
        return {(round(float(p), 9), int(r)): (int(s), float(e)) for p, r, s, e in
                zip(rec["p0"], rec["replica"], rec["tiling_seed"], rec["energy_per_cell"])}
    mine, theirs = by_unit(result.records), by_unit(other.records)
    assert len(mine) == 4 and len(theirs) == 9
    for key, (seed, energy) in mine.items():
        assert theirs[key][0] == seed, key
        assert theirs[key][1] == pytest.approx(energy, rel=1e-9, abs=1e-15), key
    from spherevm.sweeps.execution import build_chunk_state
    sweep = sweeps.RigiditySweep(**TINY)
    chunk = sweeps.plan_chunks(sweep, batch_cells=32)[0]
    state, _, _, _, seeds = build_chunk_state(sweep, chunk)
    for i, seed in enumerate(seeds):
        one = svm.init.random_tiling(16, seed=seed)
        v0, v1 = state.vertex_start[i], state.vertex_start[i + 1]
        assert np.array_equal(np.asarray(state.positions)[v0:v1], np.asarray(one.positions))


def test_resume_with_other_code_warns(tmp_path):
    out = tmp_path / "sweep"
    sweep = sweeps.RigiditySweep(**TINY)
    sweeps.open_sweep_folder(sweep, out)
    manifest = json.loads((out / "manifest.json").read_text())
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        sweeps.open_sweep_folder(sweep, out)              # same code: silent
    manifest["code"] = "000000000000"
    (out / "manifest.json").write_text(json.dumps(manifest))
    with pytest.warns(UserWarning, match="started by spherevm code 000000000000"):
        sweeps.open_sweep_folder(sweep, out)
    fp = source_fingerprint()
    assert len(fp) == 12 and int(fp, 16) >= 0 and fp == source_fingerprint()


def test_resume_recomputes_only_the_missing_chunk(tiny_run, tmp_path):
    out, first, _ = tiny_run
    sweep = sweeps.RigiditySweep(**TINY)
    again = sweeps.run_sweep(sweep, out, executor=sweeps.InProcessExecutor(), device="cpu", batch_cells=32)
    assert again.computed == [] and again.reused == 2
    _same_records(first.records, again.records)
    victim = out / "chunks" / "N00016_u000002-000004.csv"
    keep = out / "chunks" / "N00016_u000000-000002.csv"
    stamp = keep.stat().st_mtime_ns
    victim.unlink()
    (out / "chunks" / "N00016_u000002-000004.csv.tmp123").write_text("half-written")   # a crash's leftover
    resumed = sweeps.run_sweep(sweep, out, executor=sweeps.InProcessExecutor(), device="cpu", batch_cells=32)
    assert resumed.computed == ["N00016_u000002-000004"] and resumed.reused == 1
    assert keep.stat().st_mtime_ns == stamp                 # the finished chunk was not rewritten
    assert sorted(os.listdir(out / "chunks")) == ["N00016_u000000-000002.csv", "N00016_u000002-000004.csv"]
    _same_records(first.records, resumed.records)


def test_chunk_files_from_before_inverted_cells_are_read_and_resumed(tiny_run, tmp_path):
    """Chunk files written before the ``inverted_cells`` column existed: resumed without recomputing,
    the column read as -1 (not measured), every other column as it was."""
    out, first, _ = tiny_run
    old = tmp_path / "old"
    shutil.copytree(out, old)
    for f in (old / "chunks").iterdir():
        with open(f, newline="") as fh:
            rows = list(csv.reader(fh))
        k = rows[0].index("inverted_cells")
        with open(f, "w", newline="") as fh:
            csv.writer(fh).writerows([r[:k] + r[k + 1:] for r in rows])
    again = sweeps.run_sweep(sweeps.RigiditySweep(**TINY), old, executor=sweeps.InProcessExecutor(), device="cpu",
                             batch_cells=32)
    assert again.computed == [] and again.reused == 2
    assert list(again.records["inverted_cells"]) == [-1] * 4 and list(first.records["inverted_cells"]) == [0] * 4
    for col in sweeps.RECORD_COLUMNS:
        if col not in ("inverted_cells", "chunk_seconds"):
            assert np.array_equal(np.asarray(again.records[col]), np.asarray(first.records[col])), col
    f = next((old / "chunks").iterdir())
    f.write_text(f.read_text().replace("t1_flips", "flips", 1))          # any other header is refused
    with pytest.raises(ValueError, match="not a sweep record file"):
        sweeps.read_records(f)


def test_parameter_mismatch_is_a_clear_error(tiny_run):
    out, _, _ = tiny_run
    listing = sorted(os.listdir(out / "chunks"))
    with pytest.raises(ValueError, match=r"different parameters \(replicas: 2 in the folder, 3 requested"):
        sweeps.run_sweep(sweeps.RigiditySweep(**{**TINY, "replicas": 3}), out, executor=sweeps.InProcessExecutor())
    with pytest.raises(ValueError, match="kr: 0.0 in the folder, 1.0 requested"):
        sweeps.run_sweep(sweeps.RigiditySweep(**{**TINY, "kr": 1.0}), out, executor=sweeps.InProcessExecutor())
    assert sorted(os.listdir(out / "chunks")) == listing


def test_results_do_not_depend_on_chunking(tiny_run, tmp_path):
    _, first, _ = tiny_run
    one = sweeps.run_sweep(sweeps.RigiditySweep(**TINY), tmp_path / "one", executor=sweeps.InProcessExecutor(),
                           device="cpu", batch_cells=1000)
    assert one.computed == ["N00016_u000000-000004"]
    _same_records(first.records, one.records)


def test_dask_cluster_gives_the_same_table(tiny_run, tmp_path):
    distributed = pytest.importorskip("distributed")
    _, first, _ = tiny_run
    with distributed.LocalCluster(n_workers=1, threads_per_worker=2, processes=False,
                                  dashboard_address=None) as cluster, distributed.Client(cluster) as client:
        result = sweeps.run_sweep(sweeps.RigiditySweep(**TINY), tmp_path / "dask", executor=client,
                                  device="cpu", batch_cells=32)
    assert result.executor == "ClientExecutor" and len(result.computed) == 2
    _same_records(first.records, result.records)
    a = rigidity.zero_fraction(first.records["n_cells"], first.records["p0"],
                               rigidity.classify(first.records["energy_per_cell"], first.records["reason"]))
    b = rigidity.zero_fraction(result.records["n_cells"], result.records["p0"],
                               rigidity.classify(result.records["energy_per_cell"], result.records["reason"]))
    for col in a:
        assert np.array_equal(a[col], b[col], equal_nan=True), col


def test_process_pool_default_on_cpu(tiny_run, tmp_path):
    _, first, _ = tiny_run
    result = sweeps.run_sweep(sweeps.RigiditySweep(**TINY), tmp_path / "pool", device="cpu", workers=2,
                              batch_cells=32)
    assert result.executor == "ProcessPoolExecutor"
    _same_records(first.records, result.records)


def test_unconverged_replicas_reported_not_folded_in(tmp_path):
    sweep = sweeps.RigiditySweep(cells=[16], p0=[3.3], replicas=2, max_steps=20)
    result = sweeps.run_sweep(sweep, tmp_path / "s", executor=sweeps.InProcessExecutor(), device="cpu")
    assert list(result.records["reason"]) == ["max_steps", "max_steps"]
    frac, p0star, _ = result.summarize()
    assert frac["n_max_steps"][0] == 2 and frac["n_rigid"][0] == 0 and math.isnan(frac["F"][0])
    assert frac["F_unconverged_rigid"][0] == 0 and frac["F_unconverged_zero"][0] == 1


def test_chunk_failure_names_the_chunk_and_keeps_finished_ones(tmp_path, monkeypatch):
    calls = []
    real = sweeps.run_chunk

    def flaky(params, n, start, stop, device):
        calls.append(start)
        if len(calls) == 2:
            raise FloatingPointError("NaN energy")
        return real(params, n, start, stop, device)

    monkeypatch.setattr(sweeps.execution, "run_chunk", flaky)   # what run_sweep calls
    out = tmp_path / "s"
    with pytest.raises(RuntimeError, match=r"chunk N00016_u00000\d-00000\d .*failed: FloatingPointError"):
        sweeps.run_sweep(sweeps.RigiditySweep(**TINY), out, executor=sweeps.InProcessExecutor(), device="cpu",
                         batch_cells=32)
    assert len(os.listdir(out / "chunks")) == 1


# ------------------------------------------------------------------------------------ p0 grids
def test_parse_p0_grid():
    assert sweeps.parse_p0_grid(["3.60:3.90:0.01"]) == pytest.approx(np.arange(31) * 0.01 + 3.6)
    assert len(sweeps.parse_p0_grid(["3.60:3.90:0.01"])) == 31
    assert sweeps.parse_p0_grid(["3.5:4.0:0.05"])[-1] == 4.0
    assert sweeps.parse_p0_grid(["3.7", "3.8"]) == [3.7, 3.8]
    for bad in (["3.9:3.6:0.1"], ["3.6:3.9"], ["3.6:3.9:0"], ["x"]):
        with pytest.raises(ValueError, match="p0"):
            sweeps.parse_p0_grid(bad)


def test_reference_t1_rule_runs():
    sweep = sweeps.RigiditySweep(cells=[16], p0=[4.2], replicas=1, **sweeps.RigiditySweep.reference_t1())
    rec = sweeps.run_chunk(sweep.parameters(), 16, 0, 1, "cpu")
    assert rec["reason"] == ["energy"] and rec["energy_per_cell"][0] < 1e-15


# ------------------------------------------------------------------------------------ physics
@pytest.mark.slow
def test_p0_star_increases_with_n(tmp_path):
    """The paper's finite-size effect: p0*(N) grows with N, tracking the pentagon perimeter."""
    sweep = sweeps.RigiditySweep(cells=[16, 64], p0=sweeps.parse_p0_grid(["3.50:3.95:0.025"]), replicas=16)
    result = sweeps.run_sweep(sweep, tmp_path / "slow", device="cpu")
    _, p0star, _ = result.summarize()
    p16, p64 = p0star["p0_star"]
    err = math.hypot(*p0star["p0_star_err"])
    assert p64 - p16 > 3 * err and p64 - p16 > 0.05
    assert all(p0star["bracketed"])
    # close to (not equal to) the regular-pentagon perimeter
    assert np.all(np.abs(p0star["p0_star"] - p0star["pentagon_perimeter"]) < 0.1)


@pytest.mark.parametrize("surface", ["sphere", "plane"])
def test_prefetched_tilings_are_the_chunk_states(surface):
    """TilingPrefetch (GPU sweeps build tilings in a process pool, cut into parts per worker) gives
    each chunk exactly the State that build_chunk_state builds alone, in the order asked."""
    from spherevm.sweeps.tilings import TilingPrefetch
    sweep = sweeps.RigiditySweep(cells=[16, 24], p0=[3.7, 3.9], replicas=5, seed=4, surface=surface)
    chunks = sweeps.plan_chunks(sweep, batch_cells=100)
    assert len(chunks) > 2
    prefetch = TilingPrefetch(sweep, chunks, workers=2, ahead=1)
    try:
        for c in chunks:
            prepared = prefetch.get(c)
            ref_state, _, _, _, ref_seeds = sweeps.build_chunk_state(sweep, c)
            got, ref = prepared["state"].arrays_np(), ref_state.arrays_np()
            assert prepared["seeds"] == ref_seeds
            assert got.keys() == ref.keys()
            for key in ref:
                assert np.array_equal(got[key], ref[key]), (c.id, key)
    finally:
        prefetch.close()


def test_prefetch_runs_ahead_by_chunks_and_then_by_cells():
    """TilingPrefetch submits the chunk asked for and ``ahead`` more, then more while the tilings it
    holds stay within ``cells`` (the chunk asked for counted in); asking for the next moves the window."""
    from spherevm.sweeps.tilings import TilingPrefetch
    sweep = sweeps.RigiditySweep(cells=[16], p0=[3.7, 3.8, 3.9], replicas=4, seed=4)
    chunks = sweeps.plan_chunks(sweep, batch_cells=32)          # 6 chunks of two 16-cell tilings
    ids = [c.id for c in chunks]
    assert len(ids) == 6 and all(c.n_cells * c.size == 32 for c in chunks)
    for cells, expected in ((0, 2), (96, 3), (10 ** 9, 6)):
        prefetch = TilingPrefetch(sweep, chunks, workers=1, ahead=1, cells=cells)
        try:
            assert prefetch.pending == ids[:expected], cells
            prefetch.get(chunks[0])
            assert prefetch.pending == ids[1:expected], cells
            prefetch.get(chunks[1])                             # the window moves on from chunk 1
            assert prefetch.pending == ids[2:expected + 1], cells
        finally:
            prefetch.close()


@pytest.mark.gpu
def test_gpu_sweep_matches_cpu(tiny_run, tmp_path):
    """Same classification and steps on the GPU; energies agree to round-off (not run here: no GPU)."""
    _, first, _ = tiny_run
    result = sweeps.run_sweep(sweeps.RigiditySweep(**TINY), tmp_path / "gpu", device="gpu")
    assert result.executor == "InProcessExecutor"          # the default on a GPU
    assert list(result.records["reason"]) == list(first.records["reason"])
    status = rigidity.classify(result.records["energy_per_cell"], result.records["reason"])
    assert list(status) == list(rigidity.classify(first.records["energy_per_cell"], first.records["reason"]))
    rigid = status == "rigid"
    assert np.allclose(result.records["energy_per_cell"][rigid], first.records["energy_per_cell"][rigid], rtol=1e-6)


def test_reference_t1_is_the_t1_preset():
    from spherevm.plugins.updaters.t1 import PRESETS
    ref = PRESETS["reference"]
    assert ref["new_length"] is None
    assert sweeps.RigiditySweep.reference_t1() == {"t1_threshold": ref["threshold"],
                                                   "t1_length_factor": ref["length_factor"]}


def test_timeline_orders_each_chunks_stages_and_changes_no_record(tiny_run, tmp_path):
    _, reference, _ = tiny_run
    res = sweeps.run_sweep(sweeps.RigiditySweep(**TINY), tmp_path / "t", executor=sweeps.InProcessExecutor(),
                           device="cpu", batch_cells=32, timeline=True)
    _same_records(reference.records, res.records)
    assert [e["chunk"] for e in res.timeline] == res.computed and len(res.computed) == 2
    stages = ("asked", "submitted", "started", "built", "minimized", "ended", "received", "written")
    for e in res.timeline:
        times = [res.started] + [e[s] for s in stages]
        assert times == sorted(times), e
        assert e["pid"] == os.getpid() and e["size"] == 2 and e["n_cells"] == 16
    assert not reference.timeline           # only when asked


def test_pool_workers_fork_from_a_preloaded_server_that_never_touches_cuda():
    """Sweep pools fork their workers from a fork server that imported spherevm once (where the
    platform has one); what it preloads must not import CuPy (no CUDA state in a forked worker)."""
    import multiprocessing
    import subprocess
    import sys
    from spherevm.sweeps.pools import PRELOAD, process_pool
    pool = process_pool(1)
    try:
        assert pool.submit(abs, -2).result() == 2
        expected = "forkserver" if "forkserver" in multiprocessing.get_all_start_methods() else "spawn"
        assert pool._mp_context.get_start_method() == expected
    finally:
        pool.shutdown()
    code = f"import sys; [__import__(m) for m in {PRELOAD!r}]; print('cupy' in sys.modules)"
    assert subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          check=True).stdout.strip() == "False"


def test_prefetching_pool_is_capped_on_many_cores(tmp_path, monkeypatch):
    """On a host of many cores the prefetching pool stops at MAX_TILING_PROCESSES (this process
    gathers every part of every chunk); an explicit ``workers`` is taken as given."""
    from spherevm.sweeps import execution
    seen = []

    class Recorder(execution.TilingPrefetch):
        def __init__(self, sweep, chunks, workers, **options):
            seen.append(workers)
            super().__init__(sweep, chunks, 1, **options)

    monkeypatch.setattr(execution, "TilingPrefetch", Recorder)
    monkeypatch.setattr(execution.os, "cpu_count", lambda: 64)
    for out, workers in (("auto", None), ("given", 40)):
        sweeps.run_sweep(sweeps.RigiditySweep(**TINY), tmp_path / out, executor=sweeps.InProcessExecutor(),
                         device="cpu", batch_cells=16, prefetch=True, workers=workers)
    assert seen == [execution.MAX_TILING_PROCESSES, 40]


@pytest.mark.skipif(not hasattr(os, "nice"), reason="os.nice: POSIX only")
def test_tiling_workers_yield_to_the_processes_driving_the_gpus():
    """TilingPrefetch's workers run at TILING_NICENESS below the sweep's priority."""
    from spherevm.sweeps.tilings import TILING_NICENESS, TilingPrefetch
    sweep = sweeps.RigiditySweep(cells=[16], p0=[3.7], replicas=2)
    prefetch = TilingPrefetch(sweep, sweeps.plan_chunks(sweep, batch_cells=100), workers=1, ahead=0)
    try:
        assert prefetch.pool.submit(os.nice, 0).result() == min(19, os.nice(0) + TILING_NICENESS)
    finally:
        prefetch.close()
    level = TilingPrefetch(sweep, sweeps.plan_chunks(sweep, batch_cells=100), workers=1, ahead=0, niceness=0)
    try:
        assert level.pool.submit(os.nice, 0).result() == os.nice(0)
    finally:
        level.close()
