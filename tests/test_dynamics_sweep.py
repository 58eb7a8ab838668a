"""Dynamics sweeps (spherevm.sweeps.DynamicsSweep): the chunk layout and seeds, a resumed sweep
gives the same tables byte for byte, a point does not depend on the rest of the grid, and the
``spherevm dynamics`` sweep mode. The Dask executors are in tests/test_cluster.py."""
import math

import numpy as np
import pytest

from spherevm import cli, sweeps

# 2 temperatures x 3 tissues of N = 16 in chunks of 2 and 1: four chunks, about a second in all;
# at T = 0.2 most tissues relax within the run, at T = 0.1 most do not
SWEEP = dict(cells=[16], T=[0.1, 0.2], p0=[3.9], replicas=3, chunk_replicas=2, steps=600, relax_steps=200,
             dt=0.02, seed=1)
TABLES = ("tau_alpha.csv", "curves.csv")
COLUMNS = [c for c in sweeps.DYNAMICS_COLUMNS.names if c != "chunk_seconds"]


def run(out, **kwargs):
    sweep = sweeps.DynamicsSweep(**{**SWEEP, **kwargs})
    result = sweeps.run_sweep(sweep, out, executor=sweeps.InProcessExecutor(), device="cpu")
    sweeps.write_dynamics_tables(out, result.records)
    return result


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    out = tmp_path_factory.mktemp("dyn") / "sweep"
    return out, run(out)


def same_records(a, b):
    for col in COLUMNS:
        assert np.array_equal(np.asarray(a[col]), np.asarray(b[col]), equal_nan=col in ("tau_alpha",)), col


def test_chunks_are_fixed_runs_of_one_point_and_seeds_depend_on_the_point_only():
    sweep = sweeps.DynamicsSweep(**SWEEP)
    assert [(c.start, c.stop) for c in sweep.plan()] == [(0, 2), (2, 3), (3, 5), (5, 6)]
    done = {16: np.array([True, True, False, False, False, True])}
    assert [(c.start, c.stop) for c in sweep.plan(done=done)] == [(2, 3), (3, 5)]
    tilings, noise = sweep.seeds(16, 1, [0, 1])
    assert len(set(tilings)) == 2 and 0 <= noise < 2**32
    assert sweep.seeds(16, 1, [1])[0] == tilings[1:]               # a tissue's tiling: its own seed
    other = sweeps.DynamicsSweep(**{**SWEEP, "T": [0.2, 0.3]})      # T = 0.2 is point 0 there
    assert other.seeds(16, 0, [0, 1]) == (tilings, noise)
    assert sweep.seeds(16, 0, [0, 1])[0] != tilings


def test_tables_agree_with_the_tissue_records(reference):
    out, result = reference
    rec = result.records
    assert list(rec["replica"]) == [0, 1, 2, 0, 1, 2] and list(rec["T"]) == [0.1, 0.1, 0.1, 0.2, 0.2, 0.2]
    relaxed = np.isfinite(rec["tau_alpha"])
    assert 0 < relaxed.sum() < len(relaxed)                          # both kinds in this small sweep
    assert np.all(rec["overlap_end"][relaxed] <= 1 / math.e) and np.all(rec["overlap_end"][~relaxed] > 1 / math.e)
    tau = sweeps.read_records(out / "tau_alpha.csv", sweeps.store.Columns(
        sweeps.tables.TAU_COLUMNS, frozenset({"n_cells", "tissues", "relaxed"}), frozenset(), ("n_cells",)))
    assert tau["tissues"] == [3, 3] and tau["relaxed"] == [int(relaxed[:3].sum()), int(relaxed[3:].sum())]
    curves = sweeps.read_curves(out, rec)
    for i, mine in enumerate((slice(0, 3), slice(3, 6))):
        taus = rec["tau_alpha"][mine]
        assert (np.isnan(tau["tau_alpha"][i]) if np.isnan(taus).any() else tau["tau_alpha"][i] == np.mean(taus))
        # a point's curve is the mean over its tissues (chunks of 2 and 1 weighed by their tissues)
        last = np.flatnonzero(np.asarray(curves["point"]) == i)[-1]
        assert curves["msd"][last] == pytest.approx(np.mean(rec["msd_end"][mine]), rel=1e-12)
        assert curves["self_overlap"][last] == pytest.approx(np.mean(rec["overlap_end"][mine]), rel=1e-12)


def test_a_point_does_not_depend_on_the_rest_of_the_grid(tmp_path, reference):
    result = sweeps.run_sweep(sweeps.DynamicsSweep(**{**SWEEP, "T": [0.2]}), tmp_path / "alone",
                              executor=sweeps.InProcessExecutor(), device="cpu", timeline=True)
    alone = result.records
    assert [e["chunk"] for e in result.timeline] == result.computed and len(result.computed) == 2
    assert all(e["submitted"] <= e["started"] <= e["built"] <= e["minimized"] <= e["ended"] <= e["written"]
               for e in result.timeline)
    rec = reference[1].records
    hot = rec["T"] == 0.2
    for col in ("tiling_seed", "noise_seed", "tau_alpha", "msd_end", "overlap_end", "t1_flips"):
        assert np.array_equal(alone[col], rec[col][hot], equal_nan=True), col


def test_an_interrupted_sweep_resumes_to_the_same_tables(tmp_path, reference):
    out = tmp_path / "sweep"

    def stop_after_two(p):
        if p.chunks_done == 2:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        sweeps.run_sweep(sweeps.DynamicsSweep(**SWEEP), out, executor=sweeps.InProcessExecutor(), device="cpu",
                         progress=stop_after_two)
    assert len(list((out / "chunks").iterdir())) == 2
    resumed = run(out)
    assert len(resumed.computed) == 2 and resumed.reused == 2
    same_records(resumed.records, reference[1].records)
    for name in TABLES:
        assert (out / name).read_bytes() == (reference[0] / name).read_bytes(), name


def test_a_folder_of_another_sweep_is_refused(tmp_path, reference):
    with pytest.raises(ValueError, match="chunk_replicas: 2 in the folder, 3 requested"):
        sweeps.open_sweep_folder(sweeps.DynamicsSweep(**{**SWEEP, "chunk_replicas": 3}), reference[0])
    rigid = tmp_path / "rigid"
    sweeps.open_sweep_folder(sweeps.RigiditySweep(cells=[16], p0=[3.9], replicas=1), rigid)
    with pytest.raises(ValueError, match="not a spherevm-dynamics-sweep manifest"):
        sweeps.run_sweep(sweeps.DynamicsSweep(**SWEEP), rigid, device="cpu")


@pytest.mark.parametrize("change, message", [
    ({"T": [-0.1]}, r"T values must be finite numbers in \[0, inf\], got -0.1"),
    ({"p0": [0.0]}, r"p0 values must be finite numbers in \(0, 100\], got 0.0"),
    ({"B": [1.0, 1.0]}, "B must not repeat a value"),
    ({"cells": [4], "surface": "plane"}, "cells must be an integer >= 8"),
    ({"chunk_replicas": 0}, "chunk_replicas must be an integer >= 1"),
])
def test_bad_parameters_are_named(change, message):
    with pytest.raises(ValueError, match=message):
        sweeps.DynamicsSweep(**{**SWEEP, **change})


@pytest.mark.parametrize("option", ["prefetch", "save_states"])
def test_rigidity_only_options_are_refused(tmp_path, option):
    with pytest.raises(ValueError, match=f"{option}=True is for rigidity sweeps"):
        sweeps.run_sweep(sweeps.DynamicsSweep(**SWEEP), tmp_path / "s", device="cpu", **{option: True})
    assert not (tmp_path / "s").exists()


def test_the_command_runs_the_sweep_and_prints_tau_alpha(tmp_path, reference, capsys):
    out = tmp_path / "cli"
    argv = ["dynamics", "--cells", "16", "--T", "0.1", "0.2", "--p0", "3.9", "--replicas", "3", "--chunk-replicas", "2",
            "--steps", "600", "--relax", "200", "--dt", "0.02", "--seed", "1", "--device", "cpu", "--workers", "1",
            "--out", str(out), "--quiet"]
    assert cli.main(argv) == 0
    printed = capsys.readouterr().out
    assert printed.splitlines()[0].split() == ["N", "T", "p0", "B", "tau_alpha", "+-", "relaxed", "tau(<Q_s>)"]
    for name in TABLES:
        assert (out / name).read_bytes() == (reference[0] / name).read_bytes(), name
    assert cli.main(argv[:-3] + ["--quiet"]) == 2
    assert "a dynamics sweep writes its tables to a folder; give --out FOLDER" in capsys.readouterr().err
    assert cli.main(argv + ["--restart", str(out / "x.gsd")]) == 2
    assert "argument --restart: belongs to a single run" in capsys.readouterr().err


def test_a_chunk_runs_on_the_device(device):
    """One chunk on each device: on the GPU the same tissues as on the CPU, to rounding."""
    params = sweeps.DynamicsSweep(**{**SWEEP, "B": [0.5]}).parameters()
    cpu = sweeps.run_dynamics_chunk(params, 16, 0, 2, "cpu")
    rec = cpu if device == "cpu" else sweeps.run_dynamics_chunk(params, 16, 0, 2, device)
    assert rec["replica"] == [0, 1] and rec["B"] == [0.5, 0.5] and len(rec["curves"]["time"]) > 10
    assert np.allclose(rec["msd_end"], cpu["msd_end"], rtol=1e-6) and rec["t1_flips"] == cpu["t1_flips"]
