"""examples/torus_tube.py --tiny: a torus of tube circumference C has C^2 R/r cells, and the tables
count every tissue."""
import csv
import math
import pathlib
import runpy

import numpy as np

import spherevm as svm

EXAMPLE = pathlib.Path(__file__).resolve().parent.parent / "examples" / "torus_tube.py"


def test_tiny_counts_every_tissue_and_estimates_where_it_can(tmp_path):
    runpy.run_path(str(EXAMPLE))["main"](["--tiny", "--out", str(tmp_path)])
    fractions = list(csv.DictReader(open(tmp_path / "tube_fraction.csv")))
    stars = list(csv.DictReader(open(tmp_path / "tube_p0star.csv")))
    assert {(r["surface"], r["n_cells"]) for r in fractions} == {("torus R/r=3", "78"), ("plane", "78")}
    for r in fractions:
        assert int(r["n_zero"]) + int(r["n_rigid"]) + int(r["n_unconverged"]) == int(r["n_replicas"]) == 1
    for r in stars:               # an estimate lies inside the grid; a flat F gives none
        assert math.isnan(float(r["p0_star"])) or 3.8 <= float(r["p0_star"]) <= 3.9


def test_the_tube_is_c_cells_round():
    """N = C^2 R/r at <A> = 1: the tiling's minor radius r gives 2 pi r = C (to N's rounding)."""
    state = svm.init.tilings_on("torus:R=3,r=1", 78, [(0, 0)])
    assert np.isclose(state.mean_cell_area[0], 1.0)
    assert math.isclose(2 * math.pi * float(np.asarray(state.size)[0, 1]), math.sqrt(78 / 3), rel_tol=1e-12)
