"""examples/curvature_growth.py, a tiny run: the tables' structure and what they must conserve."""
import csv
import pathlib
import runpy

import pytest

EXAMPLE = pathlib.Path(__file__).resolve().parent.parent / "examples" / "curvature_growth.py"


@pytest.fixture(scope="module")
def tiny(tmp_path_factory):
    pytest.importorskip("matplotlib")
    out = tmp_path_factory.mktemp("curvature_growth")
    runpy.run_path(str(EXAMPLE))["main"](["--replicas", "2", "--measure", "72", "--max-steps", "400",
                                          "--surfaces", "torus R/r=3", "--device", "cpu", "--out", str(out)])
    return out


def read(path):
    return list(csv.DictReader(open(path)))


def test_growth_tables_and_figure(tiny):
    assert (tiny / "curvature_growth.png").stat().st_size > 10_000
    fractions = read(tiny / "curvature_growth_fraction.csv")
    assert {(r["rule"], int(r["N"])) for r in fractions} == {(rule, n) for rule in ("random", "largest") for n in (64, 72)}
    for r in fractions:               # each tissue zero, rigid or neither (not converged)
        assert int(r["zero"]) + int(r["rigid"]) <= int(r["n_replicas"]) == 2
    for rule in ("random", "largest"):
        rows = [r for r in read(tiny / "curvature_growth_divisions.csv") if r["rule"] == rule]
        assert len(rows) == 4 and int(rows[0]["n_divisions"]) >= 8          # 64 -> 72 in both tissues
        for key in ("cells", "divisions"):                                  # shares of every cell, every division
            assert sum(float(r[key]) for r in rows) == pytest.approx(1.0)
