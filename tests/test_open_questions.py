"""The studies of the paper's open questions: the Arrhenius fit, examples/stiff_bending.py and
examples/fig3_relaxation.py --until-relaxed (tiny runs: the plumbing, not the physics)."""
import csv
import importlib.util
import pathlib

import numpy as np
import pytest

from spherevm.analysis import arrhenius_fit

EXAMPLES = pathlib.Path(__file__).resolve().parent.parent / "examples"


def example(name):
    spec = importlib.util.spec_from_file_location(name, EXAMPLES / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_arrhenius_fit_recovers_the_curvature_and_its_scatter():
    T = np.array([0.007, 0.008, 0.01, 0.0125, 0.015, 0.02, 0.025, 0.03])
    rng = np.random.default_rng(1)
    for c in (-1e-4, 0.0, 1e-4):
        true = 1.0 + 0.06 / T + c / T ** 2
        tau = np.exp(true[:, None] + 0.1 * rng.normal(size=(len(T), 16)))
        fit = arrhenius_fit(T, tau, n_boot=400)
        assert abs(fit.c - c) < 4 * fit.c_err
        assert 2e-6 < fit.c_err < 4e-5          # 0.1 scatter over 16 tissues: about 1e-5
    word = {-1: "sub-Arrhenius", 0: "consistent with Arrhenius", 1: "super-Arrhenius"}
    for sign in (-1, 0, 1):
        tau = np.exp(0.05 / T + sign * 3e-4 / T ** 2)[:, None] * np.exp(0.01 * rng.normal(size=(len(T), 8)))
        assert arrhenius_fit(T, tau).verdict().startswith(word[sign])


def test_arrhenius_fit_leaves_out_temperatures_with_unrelaxed_tissues():
    T = np.array([0.01, 0.015, 0.02, 0.03, 0.04])
    tau = np.exp(0.05 / T)[:, None] * np.ones((5, 3))
    tau[0, 1] = np.nan
    fit = arrhenius_fit(T, tau)
    assert np.array_equal(fit.T, T[1:]) and fit.c == pytest.approx(0.0, abs=1e-9)
    tau[1, 0] = np.nan
    assert arrhenius_fit(T, tau) is None


def test_msd_slope_tells_diffusion_from_a_plateau():
    slopes = example("fig3_relaxation").msd_slopes
    t = np.logspace(0, 4, 41)
    ts, s = slopes(t, 0.1 * t)
    assert np.allclose(s, 1.0) and len(ts) == 35
    caged = 0.01 * t / (1 + t / 10) + 1e-4 * t       # diffusive, a plateau at 0.1, diffusive after t = 1e3
    ts, s = slopes(t, caged)
    assert s.min() < 0.4 and 30 < ts[s.argmin()] < 1000 and s[-1] > 0.7


def test_stiff_bending_writes_its_tables(tmp_path, capsys):
    example("stiff_bending").main(["--cells", "16", "--B", "0.2", "--T", "0.1", "0.12", "--replicas", "1",
                                   "--max-time", "8", "--relax", "100", "--device", "cpu", "--out", str(tmp_path)])
    with open(tmp_path / "stiff_bending_fits.csv") as f:
        (row,) = list(csv.DictReader(f))
    assert row["N"] == "16" and float(row["B"]) == 0.2 and 0.005 < float(row["dt"]) < 0.05
    assert row["verdict"].startswith("no fit")
    with open(tmp_path / "stiff_bending_tau.csv") as f:
        assert len(list(csv.DictReader(f))) == 2
    assert "B/R^2 = 0.157" in capsys.readouterr().out


def test_fig3_runs_until_relaxed_or_its_cap(tmp_path, capsys):
    example("fig3_relaxation").main(["--sizes", "16", "--T", "0.03", "--until-relaxed", "--max-time", "100",
                                     "--no-inset", "--device", "cpu", "--out", str(tmp_path)])
    out = capsys.readouterr().out
    assert "stopped: relaxed" in out or "stopped: steps" in out
    with open(tmp_path / "fig3_tau_alpha.csv") as f:
        (row,) = list(csv.DictReader(f))
    assert row["N"] == "16" and row["replicas"] == "2"
    with open(tmp_path / "fig3_fits.csv") as f:
        assert list(csv.DictReader(f))[0]["verdict"].startswith("fewer than 4")


def test_collapse_measure_finds_a_dependence_on_the_shift_alone():
    """tau depending on p0 - p0*(N) only: S on the shifted axis is the tissues' noise, on the raw axis more."""
    ex = example("curvature_collapse")
    cells, p0s, temps = [32, 64, 256], np.array([3.70, 3.75, 3.80, 3.85]), np.array([0.02, 0.015])
    p0 = np.tile(p0s, len(cells))
    star = np.repeat([ex.P0STAR[n] for n in cells], len(p0s))
    rng = np.random.default_rng(2)
    curve = 5.0 - 8.0 * (p0 - star) + 30.0 * (p0 - star) ** 2
    logs = curve[None, :, None] + 0.02 / temps[:, None, None] + 0.01 * rng.normal(size=(2, len(p0), 4))
    m = ex.collapse(p0, star, logs, n_boot=200)
    assert m["temperatures_used"] == 2 and m["S_shifted"] < 2 * m["noise"] < m["S_raw"]
    assert m["shifted_better"] == 1.0
    logs[0, 0, 1] = np.nan                                   # a tissue that did not relax: its point goes
    assert ex.collapse(p0, star, logs, n_boot=20)["temperatures_used"] == 2
    logs[1, :9, 0] = np.nan                                  # only 3 points left at that T: it goes
    assert ex.collapse(p0, star, logs, n_boot=20)["temperatures_used"] == 1
