"""The periodic plane from the command line and in the sweeps: ``--surface plane`` for minimize,
dynamics and rigidity, ``glassy_dynamics(surface="plane")`` and ``RigiditySweep(surface="plane")``."""
from __future__ import annotations

import json
import os

import numpy as np
import pytest

import spherevm as svm
from spherevm import cli, sweeps
from spherevm.constraints import PeriodicPlane
from spherevm.protocols import glassy_dynamics


def _rows(text):
    lines = [line for line in text.splitlines() if line.strip()]
    assert lines and lines[0].split()[0] == "replica", text
    return [line.split() for line in lines[1:]]


# ------------------------------------------------------------------------------------ minimize
def test_minimize_on_the_plane_writes_a_planar_gsd(tmp_path, capsys):
    pytest.importorskip("gsd")
    out = tmp_path / "plane.gsd"
    rc = cli.main(["minimize", "--surface", "plane", "--cells", "16", "--replicas", "2", "--max-steps", "300",
                   "--seed", "3", "--out", str(out), "--write-every", "0"])
    captured = capsys.readouterr()
    assert rc == 0, captured.err
    assert "on the plane" in captured.err
    rows = _rows(captured.out)
    assert [r[0] for r in rows] == ["0", "1"]
    state = svm.init.from_gsd(str(out))
    assert isinstance(state.constraint, PeriodicPlane) and state.n_cells == 32
    np.testing.assert_allclose(state.box_np(), 4.0)                         # side sqrt(16): <A> = 1
    from spherevm.plugins.forces import VertexModel
    res = VertexModel.dimensionless(kr=1.0, p0=3.8).compute(state)
    energy = np.asarray(res.energy) / 16
    printed = np.array([float(r[1]) for r in rows])
    assert printed == pytest.approx(energy, rel=1e-5)
    # the same tilings as the library's
    first = svm.init.random_planar_tiling(16, replicas=2, seed=3)
    np.testing.assert_array_equal(first.box_np(), state.box_np())


def test_plane_refuses_small_n_and_unknown_surfaces_cleanly(capsys):
    rc = cli.main(["minimize", "--surface", "plane", "--cells", "6"])
    err = capsys.readouterr().err
    assert rc == 2 and "n_cells" in err and "Traceback" not in err
    rc = cli.main(["minimize", "--surface", "klein"])
    assert rc == 2 and "--surface" in capsys.readouterr().err


# ------------------------------------------------------------------------------------ dynamics
def test_dynamics_on_the_plane(tmp_path, capsys):
    csv = tmp_path / "msd.csv"
    rc = cli.main(["dynamics", "--surface", "plane", "--cells", "16", "--replicas", "2", "--T", "0.05",
                   "--dt", "0.02", "--steps", "200", "--relax", "200", "--csv", str(csv), "--quiet"])
    captured = capsys.readouterr()
    assert rc == 0, captured.err
    data = np.loadtxt(csv, delimiter=",", skiprows=1)
    assert data[0, 1] == 0.0 and data[0, 2] == 1.0
    assert data[-1, 1] > data[1, 1] > 0                        # the MSD grows
    assert "tau_alpha" in captured.out


def test_glassy_dynamics_surface_plane_matches_a_hand_made_run():
    res = glassy_dynamics(16, 3.9, 1.0, 0.05, dt=0.02, steps=100, replicas=2, seed=1, relax_steps=100,
                          surface="plane")
    st = res.simulation.state
    assert isinstance(st.constraint, PeriodicPlane) and st.n_replicas == 2
    assert res.msd[0] == 0 and res.msd[-1] > 0 and res.self_overlap[0] == 1.0
    assert res.msd_per_replica.shape[1] == 2
    with pytest.raises(ValueError, match="surface"):
        glassy_dynamics(16, 3.9, 1.0, 0.05, steps=10, surface="klein")


# ------------------------------------------------------------------------------------ sweeps
PLANE = dict(cells=[16], p0=[3.6, 4.1], replicas=3, seed=2, surface="plane", max_steps=4000)


def test_planar_sweep_runs_resumes_and_refuses_another_surface(tmp_path):
    out = tmp_path / "plane"
    sweep = sweeps.RigiditySweep(**PLANE)
    first = sweeps.run_sweep(sweep, out, executor=sweeps.InProcessExecutor(), device="cpu", batch_cells=48)
    assert len(first.records["n_cells"]) == 6 and len(first.computed) == 2
    manifest = json.loads((out / "manifest.json").read_text())
    assert manifest["parameters"]["surface"] == "plane"
    # each replica is the planar tiling of its own seed
    from spherevm.sweeps.execution import build_chunk_state
    state, _, _, _, seeds = build_chunk_state(sweep, sweeps.plan_chunks(sweep, batch_cells=48)[0])
    assert isinstance(state.constraint, PeriodicPlane)
    for i, seed in enumerate(seeds):
        one = svm.init.random_planar_tiling(16, seed=seed)
        v0, v1 = state.vertex_start[i], state.vertex_start[i + 1]
        assert np.array_equal(np.asarray(state.positions)[v0:v1], np.asarray(one.positions))
    tables = sweeps.write_tables(out, first.records, plots=False)
    for name in ("replicas.csv", "fraction.csv", "p0star.csv", "p0star_density.csv"):
        assert (out / name).is_file()
    assert tables["p0star"]["pentagon_perimeter"][0] == pytest.approx(np.sqrt(20 * np.tan(np.pi / 5)))
    # resume: nothing left to do, the same records
    again = sweeps.run_sweep(sweep, out, executor=sweeps.InProcessExecutor(), device="cpu", batch_cells=48)
    assert again.computed == [] and again.reused == 2
    np.testing.assert_array_equal(again.records["energy_per_cell"], first.records["energy_per_cell"])
    # another surface: a clear refusal, nothing written
    listing = sorted(os.listdir(out / "chunks"))
    with pytest.raises(ValueError, match="holds a sweep on the plane, not on the sphere"):
        sweeps.run_sweep(sweeps.RigiditySweep(**{**PLANE, "surface": "sphere"}), out,
                         executor=sweeps.InProcessExecutor())
    assert sorted(os.listdir(out / "chunks")) == listing
    with pytest.raises(ValueError, match=">= 8 on the periodic plane"):
        sweeps.RigiditySweep(**{**PLANE, "cells": [6]})
    with pytest.raises(ValueError, match="unknown surface 'klein'"):
        sweeps.RigiditySweep(**{**PLANE, "surface": "klein"})


def test_old_sweep_folder_without_surface_resumes_as_sphere(tmp_path):
    out = tmp_path / "old"
    sphere = dict(cells=[16], p0=[3.3], replicas=1)
    sweep = sweeps.RigiditySweep(**sphere)
    sweeps.run_sweep(sweep, out, executor=sweeps.InProcessExecutor(), device="cpu")
    manifest = json.loads((out / "manifest.json").read_text())
    assert manifest["parameters"].pop("surface") == "sphere"            # as written before the plane
    (out / "manifest.json").write_text(json.dumps(manifest))
    again = sweeps.run_sweep(sweep, out, executor=sweeps.InProcessExecutor(), device="cpu")
    assert again.computed == [] and again.reused == 1
    assert sweeps.write_tables(out, again.records, plots=False)["p0star"]["pentagon_perimeter"][0] == \
        pytest.approx(svm.shapes.pentagon_perimeter(16))
    with pytest.raises(ValueError, match="holds a sweep on the sphere, not on the plane"):
        sweeps.open_sweep_folder(sweeps.RigiditySweep(**{**sphere, "surface": "plane"}), out)


def test_rigidity_cli_on_the_plane_and_p0_classification(tmp_path, capsys):
    """p0 = 3.6 mostly rigid, 4.1 mostly floppy on the plane at N = 16 and 24."""
    out = tmp_path / "cli"
    argv = ["rigidity", "--surface", "plane", "--cells", "16", "24", "--p0", "3.6", "4.1", "--replicas", "4",
            "--out", str(out), "--no-plots", "--workers", "1", "--device", "cpu", "--quiet"]
    rc = cli.main(argv)
    captured = capsys.readouterr()
    assert rc == 0, captured.err
    frac = np.genfromtxt(out / "fraction.csv", delimiter=",", names=True)
    for n in (16, 24):
        f = dict(zip(frac["p0"][frac["n_cells"] == n], frac["F"][frac["n_cells"] == n]))
        assert f[3.6] <= 0.25 and f[4.1] >= 0.75, (n, f)
    assert "3.8119" in captured.out                                     # the flat pentagon beside p0*
    rc = cli.main(argv)                                                 # resume: nothing recomputed
    assert rc == 0
    rc = cli.main([a if a != "plane" else "sphere" for a in argv])
    err = capsys.readouterr().err
    assert rc == 2 and "holds a sweep on the plane" in err
