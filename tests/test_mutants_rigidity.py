"""Tests that kill mutants of spherevm/analysis/rigidity.py that survived the existing tests.

Found with ``python3 benchmarks/mutate.py spherevm/analysis/rigidity.py ...`` (docs/testing.md,
"Mutation testing"). Each test names what a user would have seen go wrong.
"""
import math

import numpy as np
import pytest

from spherevm.analysis import rigidity


def _logistic(x, p0c, w):
    return 1 / (1 + np.exp(-(x - p0c) / w))


X = np.round(np.arange(3.6, 4.0001, 0.02), 10)


# ------------------------------------------------------------------------------------ input checks
def test_p0_must_increase_strictly():
    # finite but not increasing: rejected (``or`` in place of ``and`` would need a NaN as well)
    with pytest.raises(ValueError, match="strictly increasing"):
        rigidity.p0_star(X[::-1], _logistic(X, 3.8, 0.03)[::-1])
    with pytest.raises(ValueError, match="strictly increasing"):
        rigidity.p0_star([3.7, 3.7, 3.8], [0.0, 0.5, 1.0])      # a repeated p0
    with pytest.raises(ValueError, match="strictly increasing"):
        rigidity.p0_star([3.7, np.nan, 3.8], [0.0, 0.5, 1.0])   # a non-finite p0


def test_p0_and_F_must_match():
    with pytest.raises(ValueError, match="equal length"):
        rigidity.p0_star(X, _logistic(X, 3.8, 0.03)[:-1])
    with pytest.raises(ValueError, match="equal length"):
        rigidity.p0_star(X[None, :], _logistic(X, 3.8, 0.03)[None, :])


def test_missing_F_is_interpolated_across_and_counted():
    F = _logistic(X, 3.8, 0.03)
    Fn = F.copy()
    Fn[3] = np.nan
    keep = np.isfinite(Fn)
    assert rigidity.p0_star(X, Fn).mean == pytest.approx(rigidity.p0_star(X[keep], F[keep]).mean, abs=1e-12)
    with pytest.raises(ValueError, match="two or more"):
        rigidity.p0_star([3.7, 3.8], [0.5, np.nan])      # one usable point


def test_sigma_must_be_positive_and_finite():
    F = _logistic(X, 3.8, 0.03)
    for bad in (0.0, -0.01, np.nan, np.inf):
        with pytest.raises(ValueError, match="sigma"):
            rigidity.transition_density(X, F, bad, X)


def test_mean_area_must_be_positive():
    with pytest.raises(ValueError, match="mean_area"):
        rigidity.critical_perimeter(3.8, 0.0)
    with pytest.raises(ValueError, match="mean_area"):
        rigidity.critical_perimeter(3.8, [1.0, -1.0])


# ------------------------------------------------------------------------------------ known answers
def test_wilson_interval_known_answers():
    # k = 3 of n = 10, z = 1 and z = 2, by the textbook formula
    for z in (1.0, 2.0):
        k, n = 3.0, 10.0
        f = k / n
        centre = (f + z * z / (2 * n)) / (1 + z * z / n)
        half = z / (1 + z * z / n) * math.sqrt(f * (1 - f) / n + z * z / (4 * n * n))
        lo, hi = rigidity.wilson_interval([3], [10], z=z)
        assert lo[0] == pytest.approx(centre - half, rel=1e-12)
        assert hi[0] == pytest.approx(centre + half, rel=1e-12)
    # the default is z = 1 (a 68 % interval); n = 0 gives NaN
    lo1, hi1 = rigidity.wilson_interval([3], [10], z=1.0)
    lo, hi = rigidity.wilson_interval([3, 0], [10, 0])
    assert lo[0] == lo1[0] and hi[0] == hi1[0]
    assert math.isnan(lo[1]) and math.isnan(hi[1])
    # exact at the ends: k = 0 has low 0, k = n has high 1
    lo, hi = rigidity.wilson_interval([0, 4], [4, 4], z=2.0)
    assert lo[0] == 0.0 and hi[1] == 1.0 and 0 < lo[1] < 1 and 0 < hi[0] < 1


def test_binomial_error_known_answer():
    err = rigidity.binomial_error([3, 0], [10, 0])
    assert err[0] == pytest.approx(math.sqrt(0.3 * 0.7 / 10), rel=1e-12)
    assert math.isnan(err[1])


def test_moments_of_a_piecewise_linear_step():
    # F rises linearly from 0 at 3.7 to 1 at 3.9 (uniform density on [3.7, 3.9]), flat elsewhere
    x = np.array([3.5, 3.7, 3.9, 4.0])
    F = np.array([0.0, 0.0, 1.0, 1.0])
    est = rigidity.p0_star(x, F, sigma=0.01)
    assert est.mean == pytest.approx(3.8, abs=1e-12)
    assert est.std_unsmoothed == pytest.approx(0.2 / math.sqrt(12), rel=1e-9)
    assert est.std == pytest.approx(math.hypot(0.2 / math.sqrt(12), 0.01), rel=1e-9)
    assert est.sigma == 0.01
    assert est.p0_half == pytest.approx(3.8, abs=1e-12)
    assert est.F_first == 0.0 and est.F_last == 1.0 and est.bracketed
    # density: the uniform density 5 convolved with a narrow Gaussian, exact at the centre
    d = rigidity.transition_density(x, F, 0.01, np.array([3.8, 3.7, 3.3, 4.2]))
    assert d[0] == pytest.approx(5.0, rel=1e-9)
    assert d[1] == pytest.approx(2.5, rel=1e-9)         # half the Gaussian inside at the edge
    assert d[2] == pytest.approx(0.0, abs=1e-12) and d[3] == pytest.approx(0.0, abs=1e-12)


def test_p0_half_interpolates_between_grid_points():
    x = np.array([3.6, 3.7, 3.8, 3.9])
    F = np.array([0.0, 0.2, 0.6, 1.0])
    est = rigidity.p0_star(x, F, sigma=0.05)
    assert est.p0_half == pytest.approx(3.7 + 0.3 / 0.4 * 0.1, abs=1e-12)
    # exactly 1/2 on a grid point, with a plateau after it
    est = rigidity.p0_star(x, np.array([0.0, 0.5, 0.5, 1.0]), sigma=0.05)
    assert est.p0_half == pytest.approx(3.7, abs=1e-12)
    # exactly 1/2 at the first point
    est = rigidity.p0_star(x, np.array([0.5, 0.6, 0.8, 1.0]), sigma=0.05)
    assert est.p0_half == pytest.approx(3.6, abs=1e-12)


def test_p0_half_is_nan_when_F_does_not_cross_one_half():
    est = rigidity.p0_star(X, 0.4 * _logistic(X, 3.8, 0.03))
    assert math.isnan(est.p0_half) and not est.bracketed
    est = rigidity.p0_star(X, 0.6 + 0.4 * _logistic(X, 3.8, 0.03))
    assert math.isnan(est.p0_half) and not est.bracketed


def test_bracketed_thresholds():
    x = np.array([3.6, 3.7, 3.8, 3.9])
    assert rigidity.p0_star(x, np.array([0.05, 0.3, 0.7, 0.95]), sigma=0.05).bracketed
    assert not rigidity.p0_star(x, np.array([0.06, 0.3, 0.7, 0.95]), sigma=0.05).bracketed
    assert not rigidity.p0_star(x, np.array([0.05, 0.3, 0.7, 0.94]), sigma=0.05).bracketed


def test_decreasing_F_gives_nan_not_a_number():
    x = np.array([3.6, 3.7, 3.8])
    est = rigidity.p0_star(x, np.array([1.0, 0.5, 0.0]), sigma=0.05)
    assert math.isnan(est.mean) and math.isnan(est.std)
    assert np.all(np.isnan(rigidity.transition_density(x, [1.0, 0.5, 0.0], 0.05, x)))
    assert np.all(np.isnan(rigidity.transition_density(x, [0.5, 0.5, 0.5], 0.05, x)))
    assert math.isnan(rigidity.smoothing_width(x, [0.5, 0.5, 0.5]))


def test_smoothing_width_rule():
    # uniform density on [3.6, 4.0]: w = 0.4 / sqrt(12) = 0.115; 0.5 w = 0.058 > 0.5 x spacing (0.05)
    x = np.array([3.5, 3.6, 3.7, 3.8, 3.9, 4.0, 4.1])
    F = np.array([0.0, 0.0, 0.25, 0.5, 0.75, 1.0, 1.0])
    w = 0.4 / math.sqrt(12)
    assert rigidity.smoothing_width(x, F) == pytest.approx(0.5 * w, rel=1e-9)
    assert rigidity.smoothing_width(x, F, fraction=1.0) == pytest.approx(w, rel=1e-9)
    # a narrow kernel: the floor min_spacing x median spacing
    assert rigidity.smoothing_width(x, F, fraction=0.1) == pytest.approx(0.05, rel=1e-9)
    assert rigidity.smoothing_width(x, F, min_spacing=1.0, fraction=0.1) == pytest.approx(0.1, rel=1e-9)


def test_mean_err_uses_the_replica_counts():
    rng = np.random.default_rng(3)
    n = np.full(len(X), 200)
    k = rng.binomial(n, _logistic(X, 3.78, 0.03))
    few = rigidity.p0_star(X, k / n, n // 10 + 1)
    many = rigidity.p0_star(X, k / n, n)
    assert many.mean_err < few.mean_err           # more replicas, smaller error
    assert math.isnan(rigidity.p0_star(X, k / n).mean_err)
    assert math.isnan(rigidity.p0_star(X, k / n, n, resamples=0).mean_err)
    # the error is the spread of means of Beta(k + 1/2, n - k + 1/2) draws
    rng = np.random.default_rng(0)
    draws = rng.beta(k + 0.5, n - k + 0.5, size=(400, len(X)))
    means = []
    for d in draws:
        dF = np.diff(d)
        means.append(np.sum(dF * (X[1:] + X[:-1]) / 2) / (d[-1] - d[0]))
    assert many.mean_err == pytest.approx(np.std(means, ddof=1), rel=1e-9)


# ------------------------------------------------------------------------------------ tables
def test_zero_fraction_columns_and_other_reasons():
    n = [16] * 5
    p0 = [3.7] * 5
    status = ["zero", "rigid", "rigid", "nan_energy", "max_steps"]
    f = rigidity.zero_fraction(n, p0, status)
    assert list(f) == list(rigidity.FRACTION_COLUMNS)
    assert f["n_replicas"][0] == 5 and f["n_zero"][0] == 1 and f["n_rigid"][0] == 2
    assert f["n_unconverged"][0] == 2 and f["n_max_steps"][0] == 1 and f["n_other"][0] == 1
    assert f["F"][0] == pytest.approx(1 / 3)
    assert f["F_unconverged_rigid"][0] == pytest.approx(1 / 5)
    assert f["F_unconverged_zero"][0] == pytest.approx(3 / 5)
    lo, hi = rigidity.wilson_interval([1], [3])
    assert f["F_low"][0] == lo[0] and f["F_high"][0] == hi[0]
    # every replica unconverged: F is NaN, not an error
    f = rigidity.zero_fraction([16, 16], [3.7, 3.7], ["max_steps", "t1_oscillation"])
    assert math.isnan(f["F"][0]) and f["n_other"][0] == 0
    with pytest.raises(ValueError, match="one entry per replica"):
        rigidity.zero_fraction([16], [3.7, 3.8], ["zero", "zero"])


def test_classify_nan_energy_and_boundary():
    status = rigidity.classify([np.nan, 1e-12, np.inf, 0.999e-12], ["force", "force", "energy", "energy"])
    assert list(status) == ["nan_energy", "rigid", "nan_energy", "zero"]
    with pytest.raises(ValueError, match="zero_tol"):
        rigidity.classify([0.0], ["force"], zero_tol=np.inf)
    with pytest.raises(ValueError, match="zero_tol"):
        rigidity.classify([0.0], ["force"], zero_tol=-1e-12)


def test_summarize_density_grid_and_unusable_sizes():
    x = np.round(np.arange(3.6, 3.9001, 0.02), 10)
    n_cells, p0, status = [], [], []
    for p in x:
        k = int(round(20 * _logistic(p, 3.72, 0.01)))
        n_cells += [32] * 20
        p0 += [p] * 20
        status += ["zero"] * k + ["rigid"] * (20 - k)
    # N = 64 at a single p0: no estimate (NaN row), no density
    n_cells += [64] * 3
    p0 += [3.7] * 3
    status += ["zero", "rigid", "max_steps"]
    frac, p0star, density = rigidity.summarize(n_cells, p0, status, resamples=20, grid_points=11, sigma=0.01)
    assert list(p0star) == list(rigidity.P0STAR_COLUMNS)
    assert list(p0star["n_cells"]) == [32, 64]
    assert math.isnan(p0star["p0_star"][1]) and not p0star["bracketed"][1]
    assert p0star["n_replicas"][1] == 3 and p0star["n_unconverged"][1] == 1
    assert p0star["n_replicas"][0] == 20 * len(x) and p0star["n_unconverged"][0] == 0
    assert p0star["sigma"][0] == 0.01
    assert list(density["n_cells"]) == [32] * 11
    # the grid spans the data padded by sigma on each side
    assert density["p0"][0] == pytest.approx(3.6 - 0.01) and density["p0"][-1] == pytest.approx(3.9 + 0.01)
    assert np.allclose(density["density"], rigidity.transition_density(x, frac["F"][frac["n_cells"] == 32],
                                                                       0.01, density["p0"]))


def test_two_p0_values_are_enough():
    est = rigidity.p0_star([3.7, 3.8], [0.0, 1.0], sigma=0.01)
    assert est.mean == pytest.approx(3.75, abs=1e-12) and est.p0_half == pytest.approx(3.75, abs=1e-12)
    assert rigidity.smoothing_width([3.7, 3.8], [0.0, 1.0]) == pytest.approx(0.05, rel=1e-9)


def test_p0_half_when_F_ends_at_one_half():
    est = rigidity.p0_star([3.6, 3.7, 3.8], [0.0, 0.2, 0.5], sigma=0.05)
    assert est.p0_half == pytest.approx(3.8, abs=1e-12)


def test_mean_err_from_two_resamples():
    n = np.full(len(X), 50)
    k = np.rint(_logistic(X, 3.8, 0.03) * n)
    assert np.isfinite(rigidity.p0_star(X, k / n, n, resamples=2).mean_err)
    assert math.isnan(rigidity.p0_star(X, k / n, n, resamples=1).mean_err)


def test_density_is_normalised_by_the_whole_rise_of_F():
    # F still rising at the last point: normalised by F_last - F_first, not by an inner difference
    x = np.array([3.6, 3.7, 3.8])
    F = np.array([0.0, 0.25, 1.0])
    grid = np.linspace(3.0, 4.4, 14001)
    d = rigidity.transition_density(x, F, 0.01, grid)
    assert d.sum() * (grid[1] - grid[0]) == pytest.approx(1.0, abs=1e-6)
    assert d[np.searchsorted(grid, 3.75)] == pytest.approx(7.5, rel=1e-6)   # slope 7.5 / mass 1


def test_std_with_a_kernel_wider_than_the_transition():
    x = np.array([3.5, 3.7, 3.9, 4.0])
    F = np.array([0.0, 0.0, 1.0, 1.0])
    est = rigidity.p0_star(x, F, sigma=0.3)
    assert est.std == pytest.approx(math.hypot(0.2 / math.sqrt(12), 0.3), rel=1e-12)


def test_p0_half_on_a_plateau_at_one_half_and_the_ends_of_F():
    est = rigidity.p0_star([3.6, 3.7, 3.8], [0.5, 0.5, 1.0], sigma=0.05)
    assert est.p0_half == pytest.approx(3.7, abs=1e-12)
    est = rigidity.p0_star([3.6, 3.7, 3.8, 3.9], [0.0, 0.2, 0.6, 1.0], sigma=0.05)
    assert est.F_first == 0.0 and est.F_last == 1.0
    est = rigidity.p0_star([3.6, 3.7, 3.8, 3.9], [0.1, 0.2, 0.6, 0.9], sigma=0.05)
    assert est.F_first == pytest.approx(0.1) and est.F_last == pytest.approx(0.9)


def test_summarize_without_any_usable_size():
    frac, p0star, density = rigidity.summarize([16, 16], [3.7, 3.7], ["zero", "rigid"], resamples=10)
    assert list(p0star["n_cells"]) == [16] and math.isnan(p0star["p0_star"][0])
    for col in ("n_cells", "p0", "density"):
        assert density[col].shape == (0,)


def test_flat_F_gives_nan_density_without_a_warning():
    import warnings
    x = np.array([3.6, 3.7, 3.8])
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        d = rigidity.transition_density(x, [0.5, 0.5, 0.5], 0.05, x)
    assert np.all(np.isnan(d))


# ------------------------------------------------------------------ the full pass (every site outside the plots)
def test_binomial_error_of_a_single_replica_is_zero():
    assert rigidity.binomial_error([0, 1], [1, 1]).tolist() == [0.0, 0.0]


def test_density_normalised_by_a_partial_rise_of_F():
    x = np.array([3.6, 3.7, 3.8])
    F = np.array([0.2, 0.45, 0.7])                       # mass 0.5, slope 2.5 everywhere
    grid = np.linspace(3.0, 4.4, 14001)
    d = rigidity.transition_density(x, F, 0.01, grid)
    assert d.sum() * (grid[1] - grid[0]) == pytest.approx(1.0, abs=1e-6)
    assert d[np.searchsorted(grid, 3.7)] == pytest.approx(5.0, rel=1e-6)    # slope 2.5 / mass 0.5


def test_F_back_where_it_started_gives_nan_not_infinity():
    import warnings
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        est = rigidity.p0_star([3.6, 3.7, 3.8], [0.0, 1.0, 0.0], sigma=0.05)
        flat = rigidity.p0_star([3.6, 3.7, 3.8], [0.5, 0.5, 0.5], sigma=0.05)
    assert math.isnan(est.mean) and math.isnan(est.std)
    assert math.isnan(flat.mean) and math.isnan(flat.p0_half)


def test_one_resample_gives_nan_without_a_warning():
    import warnings
    n = np.full(len(X), 50)
    k = np.rint(_logistic(X, 3.8, 0.03) * n)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert math.isnan(rigidity.p0_star(X, k / n, n, resamples=1).mean_err)


def test_std_at_zero_and_negative_variance():
    # noisy (non-monotone) F on a grid where the moments are exact in binary:
    # variance exactly 0, and exactly -1
    zero = rigidity.p0_star([0.0, 3.0, 6.0, 9.0], [0.0, 0.25, 0.875, 0.75], sigma=0.5)
    assert zero.std_unsmoothed == 0.0 and zero.std == 0.5
    negative = rigidity.p0_star([0.0, 3.0, 6.0], [0.0, 0.875, 0.75], sigma=1.0)
    assert math.isnan(negative.std_unsmoothed) and negative.std == 0.0
    assert math.isnan(rigidity.p0_star([0.0, 3.0, 6.0], [0.0, 0.875, 0.75], sigma=0.5).std)


def test_summarize_defaults_and_no_density_for_a_flat_F_with_a_given_sigma():
    import inspect
    defaults = {k: p.default for k, p in inspect.signature(rigidity.summarize).parameters.items()}
    assert defaults["grid_points"] == 401 and defaults["resamples"] == 400
    n_cells = [16] * 40 + [32] * 40
    p0 = list(np.repeat([3.7, 3.8, 3.9, 4.0], 10)) * 2
    status = ["zero" if (p > 3.75 + 0.01 * (i % 10)) else "rigid" for i, p in enumerate(p0[:40])] + ["rigid"] * 40
    frac, p0star, density = rigidity.summarize(n_cells, p0, status, sigma=0.05)
    assert np.unique(density["n_cells"]).tolist() == [16] and len(density["p0"]) == 401
    sel = frac["n_cells"] == 16
    est = rigidity.p0_star(frac["p0"][sel], frac["F"][sel], frac["n_zero"][sel] + frac["n_rigid"][sel],
                           sigma=0.05, resamples=400)
    assert p0star["p0_star_err"][0] == est.mean_err and np.isfinite(est.mean_err)
    assert math.isnan(p0star["p0_star"][1])


def test_wilson_interval_of_a_single_replica():
    lo, hi = rigidity.wilson_interval([0, 1], [1, 1])
    assert lo.tolist() == [0.0, 0.5] and hi.tolist() == [0.5, 1.0]


def test_density_on_a_grid_of_any_shape():
    x, F = np.array([3.6, 3.7, 3.8, 3.9]), np.array([0.0, 0.2, 0.9, 1.0])
    grid = np.linspace(3.5, 4.0, 12)
    flat = rigidity.transition_density(x, F, 0.05, grid)
    square = rigidity.transition_density(x, F, 0.05, grid.reshape(3, 4))
    assert square.shape == (3, 4) and np.array_equal(square.reshape(-1), flat)
