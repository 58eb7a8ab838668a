"""examples/curvature_gradients.py --tiny: the tables' structure and what binning must conserve."""
import csv
import pathlib
import runpy

import numpy as np
import pytest

from spherevm.analysis import pentagon_perimeter_at_curvature, torus_curvature_range

EXAMPLE = pathlib.Path(__file__).resolve().parent.parent / "examples" / "curvature_gradients.py"


@pytest.fixture(scope="module")
def tiny(tmp_path_factory):
    pytest.importorskip("matplotlib")
    out = tmp_path_factory.mktemp("curvature_gradients")
    runpy.run_path(str(EXAMPLE))["main"](["--tiny", "--out", str(out)])
    return out


def read(path):
    return list(csv.DictReader(open(path)))


def test_tiny_writes_every_table_and_the_figure(tiny):
    for name in ("curvature_cells.csv", "curvature_bins.csv", "curvature_fraction.csv", "curvature_dynamics.csv"):
        assert read(tiny / name), name
    assert (tiny / "curvature_gradients.png").stat().st_size > 10_000
    fractions = read(tiny / "curvature_fraction.csv")
    assert {r["surface"] for r in fractions} == {"plane", "torus R/r=3"}
    for r in fractions:           # every replica is zero, rigid or unconverged
        assert int(r["n_zero"]) + int(r["n_rigid"]) + int(r["n_unconverged"]) == int(r["n_replicas"]) == 1


def test_bins_hold_every_cell_and_a_torus_has_both_signs(tiny):
    cells = read(tiny / "curvature_cells.csv")
    bins = read(tiny / "curvature_bins.csv")
    for surface in ("plane", "torus R/r=3"):
        ks = np.array([float(c["K_A"]) for c in cells if c["surface"] == surface])
        assert len(ks) == 64
        for quantity in ("q", "perimeter", "area", "sides"):
            rows = [b for b in bins if b["surface"] == surface and b["quantity"] == quantity]
            assert sum(int(b["n_cells_in_bin"]) for b in rows) == 64, (surface, quantity)
    torus = [b for b in bins if b["surface"] == "torus R/r=3" and b["quantity"] == "q"]
    k_min, k_max = torus_curvature_range(3.0, 64)
    assert float(torus[0]["K_low"]) < 0 < float(torus[-1]["K_high"])
    assert k_min - 1e-9 <= float(torus[0]["K_low"]) and float(torus[-1]["K_high"]) <= k_max + 1e-9
    for b in torus:               # the local bound is the pentagon's at the bin's mean K <A>
        assert float(b["p_penta"]) == pytest.approx(float(pentagon_perimeter_at_curvature(float(b["K_A"]))), rel=1e-5)
    plane = [b for b in bins if b["surface"] == "plane" and b["quantity"] == "area"]
    assert len(plane) == 1 and float(plane[0]["K_A"]) == 0.0
    dyn = read(tiny / "curvature_dynamics.csv")
    assert {b["quantity"] for b in dyn} == {"msd", "overlap", "t1_rate"}
    for b in dyn:                 # a fraction of time origins
        assert b["quantity"] != "overlap" or 0.0 <= float(b["mean"]) <= 1.0
    assert sum(int(b["n_cells_in_bin"]) for b in dyn if b["quantity"] == "msd") == 64


def test_displacements_on_a_periodic_bump_are_minimum_images():
    """Cells whose centroids cross the bump's periodic box do not count the box length as motion."""
    dynamics = runpy.run_path(str(EXAMPLE))["dynamics"]
    d = dynamics("bump:h=2,w=1,box=6.5", 64, 1, 400, 100, device="cpu")
    assert np.all(np.isfinite(d["msd"])) and d["msd"].max() < 1.0     # a box length would be 8^2 / 6.5^2 ~ 1.5^2 x 64
    assert np.all((d["overlap"] >= 0) & (d["overlap"] <= 1))


def test_transition_is_the_rigidity_sweeps_estimator_over_the_converged_points():
    """p0* of a surface from zero_fraction's table: the p0 without a converged tissue are left out,
    and fewer than two such p0 give None."""
    from spherevm.analysis.rigidity import p0_star, zero_fraction
    transition = runpy.run_path(str(EXAMPLE))["transition"]
    p0 = np.repeat([3.80, 3.82, 3.84, 3.86, 3.88], 4)
    status = np.array(["rigid"] * 4 + ["rigid", "rigid", "rigid", "zero"] + ["max_steps"] * 4
                      + ["zero", "zero", "rigid", "zero"] + ["zero"] * 4)
    f = zero_fraction(np.full(len(p0), 64), p0, status)
    est = transition(f)
    keep = [0, 1, 3, 4]                       # p0 = 3.84: every tissue unconverged
    want = p0_star(f["p0"][keep], f["F"][keep], n=np.full(4, 4))
    assert est.mean == want.mean and est.mean_err == want.mean_err
    assert 3.82 < est.mean < 3.88
    none = zero_fraction(np.full(8, 64), np.repeat([3.80, 3.82], 4), np.array(["zero"] * 4 + ["max_steps"] * 4))
    assert transition(none) is None


def test_surfaces_selects_the_quenched_surfaces_and_writes_p0_star(tmp_path):
    pytest.importorskip("matplotlib")
    main = runpy.run_path(str(EXAMPLE))["main"]
    main(["--tiny", "--surfaces", "plane", "--no-dynamics", "--out", str(tmp_path)])
    assert {r["surface"] for r in read(tmp_path / "curvature_fraction.csv")} == {"plane"}
    assert not (tmp_path / "curvature_p0star.csv").exists()       # one p0: no transition to estimate
    with pytest.raises(SystemExit):
        main(["--tiny", "--surfaces", "torus", "--out", str(tmp_path)])   # not one of SURFACES' names
