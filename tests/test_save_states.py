"""``save_states`` / ``spherevm rigidity --save-states`` (issue 14.9): the inherent states of a sweep
kept as GSD files, each one the very state its record describes."""
import csv
import os

import gsd.hoomd
import numpy as np
import pytest

import spherevm as svm
from spherevm import cli, simplicity, sweeps
from spherevm.plugins.forces import VertexModel

SWEEP = dict(cells=[16, 20], p0=[3.6, 3.95], replicas=2, kr=0.5, seed=3)


def _energy_per_cell(state, p0, kr):
    """The sweep's energy (docs/rigidity.md, Protocol) of a single-replica state, recomputed."""
    area = float(state.mean_cell_area[0])
    sim = svm.Simulation(device="cpu")
    sim.state = state
    sim.operations.forces.append(VertexModel(kA=kr / area, kP=1.0, A0=area, P0=p0 * np.sqrt(area)))
    return float(sim.log("energy_per_cell")[0]), float(sim.log("max_force")[0])


def test_saved_states_are_the_minimised_ones(tmp_path):
    out = tmp_path / "sweep"
    result = sweeps.run_sweep(sweeps.RigiditySweep(**SWEEP), out, executor=sweeps.InProcessExecutor(),
                              device="cpu", batch_cells=40, save_states=True)
    rec = result.records
    assert len(rec["n_cells"]) == 8
    files = sorted(os.listdir(out / sweeps.STATE_DIR))
    assert files == sorted(f"{c}.gsd" for c in set(rec["chunk"]))       # one file per chunk, no leftovers
    kinds = set()
    for i in range(len(rec["n_cells"])):
        n, p0, r = int(rec["n_cells"][i]), float(rec["p0"][i]), int(rec["replica"][i])
        state, record = sweeps.load_state(out, n, p0, r)
        assert state.n_replicas == 1 and state.n_cells == n
        assert record["reason"] == rec["reason"][i] and record["steps"] == rec["steps"][i]
        e, fmax = _energy_per_cell(state, p0, SWEEP["kr"])
        assert e == pytest.approx(rec["energy_per_cell"][i], rel=1e-10, abs=1e-18)
        assert fmax == pytest.approx(rec["max_force"][i], rel=1e-8, abs=1e-15)
        kinds.add("zero" if e < 1e-12 else "rigid")
    assert kinds == {"zero", "rigid"}           # both kinds of configuration can be looked at
    # the file describes itself: per-replica p0, p0 index and replica, per-cell shape index
    with gsd.hoomd.open(out / sweeps.STATE_DIR / files[0]) as f:
        frame = f[0]
        chunk = sweeps.read_records(out / sweeps.CHUNK_DIR / files[0].replace(".gsd", ".csv"))
        np.testing.assert_array_equal(frame.log["p0"], chunk["p0"])
        np.testing.assert_array_equal(frame.log["replica"], chunk["replica"])
        np.testing.assert_allclose(frame.log["energy_per_cell"], chunk["energy_per_cell"], rtol=1e-12, atol=1e-20)


def test_records_count_the_inverted_cells_of_the_saved_states(tmp_path, device):
    """``inverted_cells``: tissues of 48 cells on a 3:1 torus reach zero energy at p0 = 3.60 with
    cells turned over (docs/surfaces.md); each record counts the cells of signed area <= 0 that the
    tiling checks (``simplicity.faults``) find in its saved state."""
    sweep = sweeps.RigiditySweep(cells=[48], p0=[3.6], replicas=3, kr=0.0, surface="torus:R=3,r=1", max_steps=2000)
    result = sweeps.run_sweep(sweep, tmp_path / "torus", executor=sweeps.InProcessExecutor(), device=device,
                              save_states=True)
    rec = result.records
    for r in range(3):
        state, record = sweeps.load_state(tmp_path / "torus", 48, 3.6, r)
        assert record["inverted_cells"] == rec["inverted_cells"][r] == len(simplicity.faults(state)["inverted"])
    assert min(rec["inverted_cells"]) > 0 and set(rec["reason"]) == {"energy"}


def _counts(folder):
    """fraction.csv's (n_zero, n_other) of its one row."""
    with open(folder / "fraction.csv", newline="") as fh:
        row = next(csv.DictReader(fh))
    return int(row["n_zero"]), int(row["n_other"])


def test_cli_says_how_many_replicas_end_with_inverted_cells(tmp_path, capsys):
    args = ["rigidity", "--cells", "48", "--p0", "3.6", "--replicas", "2", "--device", "cpu", "--workers", "1",
            "--no-plots", "--max-steps", "2000", "--kr", "0"]
    assert cli.main(args + ["--surface", "torus:R=3,r=1", "--out", str(tmp_path / "torus")]) == 0
    assert "note: 2 replica(s) end with inverted cells" in capsys.readouterr().err
    assert _counts(tmp_path / "torus") == (2, 0)        # both reached zero energy, with inverted cells
    # the same folder again, tabulated without them: nothing recomputed, F has no tissue left
    assert cli.main(args + ["--surface", "torus:R=3,r=1", "--out", str(tmp_path / "torus"), "--exclude-inverted"]) == 0
    err = capsys.readouterr().err
    assert "0 chunk(s) computed" in err and "left out of F (--exclude-inverted)" in err
    assert _counts(tmp_path / "torus") == (0, 2)
    assert cli.main(args + ["--out", str(tmp_path / "sphere")]) == 0
    assert "inverted cells" not in capsys.readouterr().err


def test_resuming_with_save_states_fills_in_the_states(tmp_path):
    out = tmp_path / "sweep"
    sweep = sweeps.RigiditySweep(**SWEEP)
    first = sweeps.run_sweep(sweep, out, executor=sweeps.InProcessExecutor(), device="cpu", batch_cells=40)
    assert not (out / sweeps.STATE_DIR).exists()
    with pytest.raises(FileNotFoundError, match="without save_states"):
        sweeps.load_state(out, 16, 3.6, 0)
    # a process pool: the states travel back as bytes, the main process writes them
    again = sweeps.run_sweep(sweep, out, device="cpu", workers=2, batch_cells=80, save_states=True)
    assert len(again.computed) >= 2 and again.reused == 0
    for c in sweeps.RECORD_COLUMNS:
        if c not in ("chunk", "chunk_seconds"):
            np.testing.assert_array_equal(again.records[c], first.records[c])   # bitwise, on the CPU
    chunk_files = sorted(f[:-4] for f in os.listdir(out / sweeps.CHUNK_DIR))
    assert chunk_files == sorted(f[:-4] for f in os.listdir(out / sweeps.STATE_DIR))
    state, record = sweeps.load_state(out, 20, 3.95, 1)
    assert state.n_cells == 20 and record["p0_index"] == 1
    # a third run finds everything on disk
    assert sweeps.run_sweep(sweep, out, device="cpu", workers=1, save_states=True).computed == []
    with pytest.raises(KeyError, match="no finished minimisation of N = 16, p0 = 3.7"):
        sweeps.load_state(out, 16, 3.7, 0)


def test_cli_save_states(tmp_path, capsys):
    out = tmp_path / "cli"
    assert cli.main(["rigidity", "--cells", "16", "--p0", "3.6", "3.95", "--replicas", "1", "--device", "cpu",
                     "--workers", "1", "--no-plots", "--out", str(out), "--save-states"]) == 0
    err = capsys.readouterr().err
    assert f"the inherent states are in {out / 'states'}" in err
    assert len(os.listdir(out / "states")) == 1
    state, record = sweeps.load_state(out, 16, 3.95, 0)
    assert state.n_cells == 16 and record["reason"] in ("energy", "force")
