"""The athermal rigidity transition: F(p0, N), the distribution of p0* and P0*(N, <A>).

The paper's protocol (Results, "Athermal rigidity transition"): minimise many random tilings at each
p0, call an inherent state *zero energy* (floppy) when its energy per cell is below a tolerance and
*rigid* otherwise, and let F(p0, N) be the fraction of zero-energy states. Its derivative is the
distribution of transition points p0*; to take it without amplifying the noise, the linear
interpolation of F is convolved with the derivative of a Gaussian whose width follows the shape of
F (after Merkel and Manning, New J. Phys. 20, 022002, 2018).

Everything here works on plain NumPy arrays; the sweep machinery is :mod:`spherevm.sweeps`.
See docs/rigidity.md for the choices (tolerance, smoothing width, treatment of non-converged
replicas) and the measurements behind them.

Conventions:

* ``status`` of a replica is ``"zero"`` or ``"rigid"`` when the minimisation converged (reason
  ``"force"`` or ``"energy"``), else the minimiser's reason (``"max_steps"``,
  ``"t1_oscillation"``, ...). Non-converged replicas are left out of F and counted separately.
* The derivative of the piecewise-linear F is piecewise constant; convolving it with a Gaussian
  of width sigma is done exactly (differences of normal CDFs), so no fine grid enters the
  estimate, only the plot. The mean of the distribution does not depend on sigma at all, and its
  variance is the unsmoothed variance plus sigma^2.
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np

from ..shapes import pentagon_perimeter, surface_pentagon_perimeter

#: Energy per cell (units kP <A>^2) below which a minimised state counts as zero energy. The
#: measured distribution is bimodal with a gap of many decades: floppy states stop at the
#: sweep's energy_tol (1e-16, well below this); the lowest rigid state (reason "force") had
#: 2.2e-8 per cell (N = 16, p0 = 3.70), measured with
#: ``python benchmarks/energy_gap.py --cells 16 32 64 --p0 3.55:3.95:0.025 --replicas 20 --seed 0``
#: (docs/rigidity.md, "Zero energy or rigid"). tests/test_rigidity_tolerance.py pins it.
ZERO_ENERGY_TOL = 1e-12
#: sigma = SIGMA_FRACTION x (width of the transition measured from the data), see smoothing_width.
SIGMA_FRACTION = 0.5
#: sigma is never below this fraction of the p0 grid spacing (median).
SIGMA_MIN_SPACING = 0.5
CONVERGED_REASONS = ("force", "energy")


# ---------------------------------------------------------------------------------------- classification
def classify(energy_per_cell, reason, zero_tol: float = ZERO_ENERGY_TOL):
    """Status of each minimised replica: ``"zero"``, ``"rigid"`` or the non-convergence reason.

    A replica converged when its ``reason`` is "force" or "energy"; it is then zero energy when
    ``energy_per_cell < zero_tol``. Others keep their reason (``max_steps``, ``t1_oscillation``).

    Parameters
    ----------
    energy_per_cell, reason : array
        Per replica (``MinimizeResult`` or a sweep's records).
    zero_tol : float

    Returns
    -------
    numpy.ndarray of str"""
    e = np.asarray(energy_per_cell, dtype=np.float64)
    r = np.asarray(reason).astype(str)
    if e.shape != r.shape:
        raise ValueError(f"energy_per_cell and reason must have the same shape, got {e.shape} and {r.shape}")
    tol = float(zero_tol)
    if not np.isfinite(tol) or tol <= 0:
        raise ValueError(f"zero_tol must be positive and finite, got {zero_tol!r}")
    converged = np.isin(r, CONVERGED_REASONS)
    status = np.where(e < tol, "zero", "rigid").astype(object)
    status[~np.isfinite(e)] = "nan_energy"
    status[~converged] = r[~converged]
    return status.astype(str)


# ---------------------------------------------------------------------------------------- binomial errors
def binomial_error(k, n):
    """Standard error sqrt(F (1 - F) / n) of the fraction F = k / n (NaN where n = 0)."""
    k, n = np.asarray(k, dtype=np.float64), np.asarray(n, dtype=np.float64)
    with np.errstate(invalid="ignore", divide="ignore"):
        f = k / n
        return np.where(n > 0, np.sqrt(f * (1 - f) / n), np.nan)


def wilson_interval(k, n, z: float = 1.0):
    """Wilson score interval of k successes in n trials (z = 1: a 68 % interval).

    Unlike F +- standard error it stays inside [0, 1] and does not shrink to zero width at
    F = 0 or 1. Returns ``(low, high)``, NaN where n = 0.
    """
    k, n = np.asarray(k, dtype=np.float64), np.asarray(n, dtype=np.float64)
    with np.errstate(invalid="ignore", divide="ignore"):
        f = k / n
        denom = 1 + z * z / n
        centre = (f + z * z / (2 * n)) / denom
        half = z * np.sqrt(f * (1 - f) / n + z * z / (4 * n * n)) / denom
        lo, hi = np.clip(centre - half, 0, 1), np.clip(centre + half, 0, 1)
        lo, hi = np.where(k == 0, 0.0, lo), np.where(k == n, 1.0, hi)   # exact at the ends
    return np.where(n > 0, lo, np.nan), np.where(n > 0, hi, np.nan)


# ---------------------------------------------------------------------------------------- F(p0, N)
FRACTION_COLUMNS = ("n_cells", "p0", "n_replicas", "n_zero", "n_rigid", "n_unconverged", "n_max_steps",
                    "n_t1_oscillation", "n_other", "F", "F_err", "F_low", "F_high", "F_unconverged_rigid",
                    "F_unconverged_zero")


def zero_fraction(n_cells, p0, status):
    """F(p0, N) from per-replica records: ``F = n_zero / (n_zero + n_rigid)``. Non-converged replicas
    are not in the denominator; they are counted in ``n_max_steps``, ``n_t1_oscillation`` and
    ``n_other``. ``F_err`` is the binomial standard error, ``F_low``/``F_high`` the 68 % Wilson
    interval; ``F_unconverged_rigid``/``_zero`` are F if every non-converged replica had been rigid
    or zero energy (a bound on what leaving them out can do).

    Parameters
    ----------
    n_cells, p0, status : array
        One entry per replica (``status`` from :func:`classify`).

    Returns
    -------
    dict
        Columns (:data:`FRACTION_COLUMNS`), one row per (N, p0)."""
    n_cells = np.asarray(n_cells, dtype=np.int64)
    p0 = np.asarray(p0, dtype=np.float64)
    status = np.asarray(status).astype(str)
    if not (n_cells.shape == p0.shape == status.shape):
        raise ValueError("n_cells, p0 and status must have one entry per replica")
    out = {c: [] for c in FRACTION_COLUMNS}
    keys = sorted(set(zip(n_cells.tolist(), p0.tolist())))
    for n, p in keys:
        s = status[(n_cells == n) & (p0 == p)]
        n_zero, n_rigid = int((s == "zero").sum()), int((s == "rigid").sum())
        n_max, n_osc = int((s == "max_steps").sum()), int((s == "t1_oscillation").sum())
        n_unconv = len(s) - n_zero - n_rigid
        m = n_zero + n_rigid
        for col, val in (("n_cells", n), ("p0", p), ("n_replicas", len(s)), ("n_zero", n_zero),
                         ("n_rigid", n_rigid), ("n_unconverged", n_unconv), ("n_max_steps", n_max),
                         ("n_t1_oscillation", n_osc), ("n_other", n_unconv - n_max - n_osc),
                         ("F", n_zero / m if m else math.nan),
                         ("F_unconverged_rigid", n_zero / len(s)),
                         ("F_unconverged_zero", (n_zero + n_unconv) / len(s))):
            out[col].append(val)
    out = {k: np.asarray(v) for k, v in out.items() if k not in ("F_err", "F_low", "F_high")}
    k, m = out["n_zero"], out["n_zero"] + out["n_rigid"]
    out["F_err"] = binomial_error(k, m)
    out["F_low"], out["F_high"] = wilson_interval(k, m)
    return {c: out[c] for c in FRACTION_COLUMNS}


# ---------------------------------------------------------------------------------------- p0* distribution
def _normal_cdf(x):
    from scipy.special import ndtr
    return ndtr(x)


def _check_curve(p0, F):
    x = np.asarray(p0, dtype=np.float64)
    f = np.asarray(F, dtype=np.float64)
    if x.ndim != 1 or f.shape != x.shape:
        raise ValueError(f"p0 and F must be 1-D arrays of equal length, got shapes {x.shape} and {f.shape}")
    ok = np.isfinite(f)
    x, f = x[ok], f[ok]  # a p0 without any converged replica gives no F: interpolate across it
    if len(x) < 2:
        raise ValueError(f"need F at two or more p0 values to take a derivative, got {len(x)}")
    if not np.all(np.isfinite(x)) or np.any(np.diff(x) <= 0):
        raise ValueError("p0 must be finite and strictly increasing")
    return x, f


def _moments(x, f):
    """Mass, mean and variance of the piecewise-constant density dF/dp0 of the linear interpolation."""
    dF = np.diff(f)
    mass = f[-1] - f[0]
    if mass <= 0:
        return mass, math.nan, math.nan
    mean = float(np.sum(dF * (x[1:] + x[:-1]) / 2) / mass)
    # second moment: int x^2 s dx over [a, b] = s (b^3 - a^3) / 3 with s = dF / (b - a)
    m2 = float(np.sum(dF * (x[1:] ** 2 + x[1:] * x[:-1] + x[:-1] ** 2) / 3) / mass)
    return mass, mean, m2 - mean * mean


def monotone_fit(p0, F, weights=None):
    """The non-decreasing least-squares fit of F (pool-adjacent-violators), weighted by ``weights``."""
    x, f = _check_curve(p0, F)
    w = np.ones_like(f) if weights is None else np.asarray(weights, dtype=np.float64)[np.isfinite(np.asarray(F, float))]
    from scipy.optimize import isotonic_regression
    return x, isotonic_regression(f, weights=np.maximum(w, 1e-12), increasing=True).x


def smoothing_width(p0, F, weights=None, fraction: float = SIGMA_FRACTION,
                    min_spacing: float = SIGMA_MIN_SPACING) -> float:
    """The Gaussian width sigma used to differentiate F, from the shape of F itself.

    Rule: fit a non-decreasing curve to F (:func:`monotone_fit`, so that noise cannot widen it),
    take the standard deviation ``w`` of its derivative (the width of the transition region: for an
    error-function step it is the step's sigma), and use ``sigma = fraction * w``, but at least
    ``min_spacing`` times the median p0 spacing (a sharper kernel only resolves the grid).
    ``fraction = 0.5`` widens the distribution by sqrt(1 + 0.25) = 1.12 and leaves its mean
    unchanged. Returns NaN if F does not increase anywhere.
    """
    x, g = monotone_fit(p0, F, weights)
    h = float(np.median(np.diff(x)))
    _, _, var = _moments(x, g)
    if not np.isfinite(var):
        return math.nan
    return max(float(fraction) * math.sqrt(max(var, 0.0)), float(min_spacing) * h)


def transition_density(p0, F, sigma, grid):
    """The smoothed distribution of p0*: the linear interpolation of F convolved with the derivative
    of a Gaussian of width ``sigma``, evaluated on ``grid`` and normalised to unit integral.

    F is held constant outside the data. Computed exactly: the derivative of the interpolation is
    the constant slope ``s_i`` on ``[x_i, x_{i+1}]``, so the convolution is
    ``sum_i s_i [Phi((p - x_i)/sigma) - Phi((p - x_{i+1})/sigma)]``, divided by ``F_last - F_first``.
    Negative where the data make F decrease (noise): that is kept, not clipped.
    """
    x, f = _check_curve(p0, F)
    s = float(sigma)
    if not np.isfinite(s) or s <= 0:
        raise ValueError(f"sigma must be positive and finite, got {sigma!r}")
    p = np.asarray(grid, dtype=np.float64)
    mass = f[-1] - f[0]
    if mass <= 0:
        return np.full(p.shape, np.nan)
    slope = np.diff(f) / np.diff(x)
    cdf = _normal_cdf((p[..., None] - x) / s)           # (..., n)
    return (slope * (cdf[..., :-1] - cdf[..., 1:])).sum(axis=-1) / mass


@dataclass
class TransitionEstimate:
    """The distribution of p0* for one N (see :func:`p0_star`)."""
    mean: float          # mean of the distribution: the estimate p0*(N)
    std: float           # standard deviation of the smoothed distribution (what is plotted)
    std_unsmoothed: float  # the same without the Gaussian: sqrt(std^2 - sigma^2)
    mean_err: float      # statistical error of ``mean`` (Jeffreys-posterior resampling of each F)
    sigma: float         # the smoothing width used
    p0_half: float       # where the monotone fit of F crosses 1/2
    F_first: float       # F at the smallest p0 (monotone fit)
    F_last: float        # F at the largest p0 (monotone fit)
    bracketed: bool      # F_first <= 0.05 and F_last >= 0.95: the transition lies inside the grid

    def as_dict(self):
        return asdict(self)


def p0_star(p0, F, n=None, sigma=None, resamples: int = 400, seed: int = 0) -> TransitionEstimate:
    """Mean and spread of the transition point p0* from F(p0) at one N. The mean and variance are
    computed exactly from the interpolation (see the module docstring).

    Parameters
    ----------
    p0, F : array
        F(p0) on increasing p0.
    n : array, optional
        Replicas entering F at each p0: weights the monotone fit behind the smoothing width, and
        gives ``mean_err`` (F redrawn ``resamples`` times from its Jeffreys posterior
        Beta(k + 1/2, n - k + 1/2); NaN without ``n``).
    sigma : float, optional
        Smoothing width (default :func:`smoothing_width`).
    resamples, seed : int

    Returns
    -------
    TransitionEstimate"""
    x, f = _check_curve(p0, F)
    finite = np.isfinite(np.asarray(F, dtype=np.float64))
    weights = None if n is None else np.asarray(n, dtype=np.float64)[finite]
    if sigma is None:
        sigma = smoothing_width(p0, F, None if n is None else np.asarray(n, dtype=np.float64))
    mass, mean, var = _moments(x, f)
    xm, g = monotone_fit(x, f, weights)
    half = math.nan
    if g[0] <= 0.5 <= g[-1] and g[-1] > g[0]:
        i = int(np.searchsorted(g, 0.5, side="left"))
        i = min(max(i, 1), len(g) - 1)
        if g[i] == g[i - 1]:
            half = float(xm[i])
        else:
            half = float(xm[i - 1] + (0.5 - g[i - 1]) * (xm[i] - xm[i - 1]) / (g[i] - g[i - 1]))
    mean_err = math.nan
    if weights is not None and resamples > 0 and np.isfinite(mean):
        k = np.rint(f * weights)
        rng = np.random.default_rng(seed)
        draws = rng.beta(k + 0.5, weights - k + 0.5, size=(int(resamples), len(f)))
        means = [_moments(x, d)[1] for d in draws]
        means = np.asarray([m for m in means if np.isfinite(m)])
        if len(means) > 1:
            mean_err = float(means.std(ddof=1))
    sig = float(sigma) if sigma is not None else math.nan
    std_raw = math.sqrt(var) if np.isfinite(var) and var >= 0 else math.nan
    std = math.sqrt(var + sig * sig) if np.isfinite(var) and np.isfinite(sig) and var + sig * sig >= 0 else math.nan
    return TransitionEstimate(mean=mean, std=std, std_unsmoothed=std_raw, mean_err=mean_err, sigma=sig,
                              p0_half=half, F_first=float(g[0]), F_last=float(g[-1]),
                              bracketed=bool(g[0] <= 0.05 and g[-1] >= 0.95))


def critical_perimeter(p0_star_value, mean_area):
    """Fig. 4 of the paper: ``P0*(N, <A>) = sqrt(<A>) p0*(N)`` (NumPy broadcasting).

    Parameters
    ----------
    p0_star_value, mean_area : float or array

    Returns
    -------
    numpy.ndarray"""
    a = np.asarray(mean_area, dtype=np.float64)
    if np.any(a <= 0):
        raise ValueError("mean_area must be positive")
    return np.sqrt(a) * np.asarray(p0_star_value, dtype=np.float64)


# ---------------------------------------------------------------------------------------- tables
P0STAR_COLUMNS = ("n_cells", "p0_star", "p0_star_err", "std", "std_unsmoothed", "sigma", "p0_half",
                  "pentagon_perimeter", "F_first", "F_last", "bracketed", "n_replicas", "n_unconverged")


def summarize(n_cells, p0, status, sigma=None, grid_points: int = 401, resamples: int = 400, surface: str = "sphere"):
    """The three tables of a sweep from per-replica records.

    Returns ``(fractions, p0star, density)``: F(p0, N) (:func:`zero_fraction`), one row per N with
    p0* beside :func:`~spherevm.analysis.pentagon_perimeter` (:data:`P0STAR_COLUMNS`), and the
    smoothed distributions on a common grid (columns ``n_cells``, ``p0``, ``density``). ``sigma``
    (None: :func:`smoothing_width` per N) may be a number used for every N. ``surface="plane"`` puts
    the flat unit-area pentagon (3.81194, every N) in the pentagon column.
    """
    frac = zero_fraction(n_cells, p0, status)
    sizes = np.unique(frac["n_cells"])
    lo, hi = float(frac["p0"].min()), float(frac["p0"].max())
    rows = {c: [] for c in P0STAR_COLUMNS}
    dens = {"n_cells": [], "p0": [], "density": []}
    estimates = {}
    for n in sizes:
        sel = frac["n_cells"] == n
        x, f = frac["p0"][sel], frac["F"][sel]
        m = (frac["n_zero"] + frac["n_rigid"])[sel]
        try:
            est = p0_star(x, f, m, sigma=sigma, resamples=resamples)
        except ValueError:  # fewer than two usable p0 values
            est = TransitionEstimate(*([math.nan] * 8), bracketed=False)
        estimates[int(n)] = est
        for col, val in (("n_cells", int(n)), ("p0_star", est.mean), ("p0_star_err", est.mean_err),
                         ("std", est.std), ("std_unsmoothed", est.std_unsmoothed), ("sigma", est.sigma),
                         ("p0_half", est.p0_half), ("pentagon_perimeter", surface_pentagon_perimeter(int(n), surface)),
                         ("F_first", est.F_first), ("F_last", est.F_last), ("bracketed", est.bracketed),
                         ("n_replicas", int(frac["n_replicas"][sel].sum())),
                         ("n_unconverged", int(frac["n_unconverged"][sel].sum()))):
            rows[col].append(val)
        if np.isfinite(est.sigma) and np.isfinite(est.mean):
            pad = est.sigma         # F is constant outside the data: the density decays within ~2 sigma
            grid = np.linspace(lo - pad, hi + pad, grid_points)
            dens["n_cells"].append(np.full(grid_points, int(n)))
            dens["p0"].append(grid)
            dens["density"].append(transition_density(x, f, est.sigma, grid))
    p0star = {k: np.asarray(v) for k, v in rows.items()}
    density = {k: (np.concatenate(v) if v else np.zeros(0)) for k, v in dens.items()}
    return frac, p0star, density


# ---------------------------------------------------------------------------------------- plots
def size_colors(sizes):
    """The paper's colours: darker red (small N) to lighter blue (large N)."""
    from matplotlib.colors import LinearSegmentedColormap
    cmap = LinearSegmentedColormap.from_list("red_to_light_blue",
                                             ["#7f0000", "#d7301f", "#c06c84", "#4a7fc1", "#8ec5ea"])
    sizes = list(sizes)
    if len(sizes) == 1:
        return {sizes[0]: cmap(0.0)}
    return {n: cmap(i / (len(sizes) - 1)) for i, n in enumerate(sizes)}


def _legend(ax, **options):
    """A legend of the labelled curves; none when nothing is labelled (p0* of no N is known, for
    example a sweep of one p0 value), where matplotlib would warn."""
    if ax.get_legend_handles_labels()[0]:
        ax.legend(**options)


def plot_transition(fractions, p0star, density, ax=None, inset=True, pentagons=True):
    """Fig. 2 (right) of the paper: distributions of p0* per N with F(p0) in an inset, and a
    pentagon marker at the regular-pentagon perimeter of each N (``pentagons=False``: none, as the
    paper's planar panel). Returns the figure."""
    import matplotlib.pyplot as plt
    if ax is None:
        fig, ax = plt.subplots(figsize=(6.4, 4.6))
    else:
        fig = ax.figure
    sizes = [int(n) for n in p0star["n_cells"]]
    colors = size_colors(sizes)
    ymax = 0.0
    for n in sizes:
        sel = density["n_cells"] == n
        if sel.any():
            ax.plot(density["p0"][sel], density["density"][sel], color=colors[n], lw=1.8, label=f"N = {n}")
            ymax = max(ymax, float(np.nanmax(density["density"][sel])))
    for n in sizes if pentagons else ():
        ax.plot([pentagon_perimeter(n)], [-0.04 * max(ymax, 1.0)], marker="p", ms=9, color=colors[n],
                mec="k", mew=0.5, ls="none", clip_on=False)
    ax.set_xlabel(r"$p_0^*$")
    ax.set_ylabel(r"$P(p_0^*) = \partial F / \partial p_0$")
    ax.axhline(0, color="0.6", lw=0.6, zorder=0)
    _legend(ax, fontsize=8, loc="upper right", frameon=False)
    if inset:
        ax.set_ylim(-0.06 * max(ymax, 1.0), 1.8 * max(ymax, 1e-9))   # room for the inset above the curves
        ins = ax.inset_axes([0.08, 0.6, 0.34, 0.36])
        for n in sizes:
            sel = fractions["n_cells"] == n
            x, f = fractions["p0"][sel], fractions["F"][sel]
            lo, hi = fractions["F_low"][sel], fractions["F_high"][sel]
            ins.errorbar(x, f, yerr=[np.clip(f - lo, 0, None), np.clip(hi - f, 0, None)], color=colors[n],
                         marker="o", ms=2.5, lw=1, capsize=0)
        ins.set_xlabel(r"$p_0$", fontsize=8, labelpad=1)
        ins.set_ylabel(r"$F(p_0)$", fontsize=8, labelpad=1)
        ins.set_yticks([0, 0.5, 1])
        ins.tick_params(labelsize=7)
        ins.set_ylim(-0.03, 1.03)
    return fig


def plot_fraction(fractions, ax=None):
    """F(p0, N) with 68 % Wilson error bars, one curve per N. Returns the figure."""
    import matplotlib.pyplot as plt
    if ax is None:
        fig, ax = plt.subplots(figsize=(6.4, 4.6))
    else:
        fig = ax.figure
    sizes = sorted(set(int(n) for n in fractions["n_cells"]))
    colors = size_colors(sizes)
    for n in sizes:
        sel = fractions["n_cells"] == n
        x, f = fractions["p0"][sel], fractions["F"][sel]
        lo, hi = fractions["F_low"][sel], fractions["F_high"][sel]
        ax.errorbar(x, f, yerr=[np.clip(f - lo, 0, None), np.clip(hi - f, 0, None)], color=colors[n], marker="o",
                    ms=3, lw=1.2, capsize=2, label=f"N = {n}")
    ax.set_xlabel(r"$p_0$")
    ax.set_ylabel(r"$F(p_0, N)$: fraction of zero-energy states")
    ax.set_ylim(-0.03, 1.03)
    _legend(ax, fontsize=8, frameon=False)
    return fig


def plot_p0_star(p0star, ax=None, surface: str = "sphere"):
    """p0*(N) (mean, error bar: spread of the distribution; thick bar: error of the mean) against
    the regular-pentagon perimeter of unit area on the sphere of N cells. Returns the figure."""
    import matplotlib.pyplot as plt
    if ax is None:
        fig, ax = plt.subplots(figsize=(6.4, 4.6))
    else:
        fig = ax.figure
    n = np.asarray(p0star["n_cells"], dtype=np.float64)
    nn = np.geomspace(max(n.min() / 1.3, 8), n.max() * 1.3, 200)
    ax.plot(nn, surface_pentagon_perimeter(nn, surface), color="k", lw=1, ls="--",
            label="regular pentagon, unit area" + (" (flat)" if surface == "plane" else ""))
    ax.errorbar(n, p0star["p0_star"], yerr=p0star["std"], fmt="none", ecolor="0.55", lw=1, capsize=3)
    ax.errorbar(n, p0star["p0_star"], yerr=p0star["p0_star_err"], fmt="o", color="C3", lw=2.5, ms=5,
                label=r"$p_0^*(N)$: mean (bars: spread, error of mean)")
    ax.set_xscale("log")
    from matplotlib.ticker import NullFormatter, ScalarFormatter
    ax.set_xticks(n)
    ax.xaxis.set_major_formatter(ScalarFormatter())
    ax.xaxis.set_minor_formatter(NullFormatter())
    ax.set_xlabel("N (cells)")
    ax.set_ylabel(r"$p_0^*$")
    _legend(ax, fontsize=8, frameon=False, loc="lower right")
    return fig


def plot_critical_perimeter(p0star, mean_area=None, ax=None, dashed=1024):
    """Fig. 4 of the paper: ``P0*(<A>) = sqrt(<A>) p0*(N)`` for each N; the N = ``dashed`` curve (if
    present, else the largest N) is drawn as a dashed black line. Returns the figure."""
    import matplotlib.pyplot as plt
    if ax is None:
        fig, ax = plt.subplots(figsize=(6.4, 4.6))
    else:
        fig = ax.figure
    a = np.linspace(0.5, 1.5, 101) if mean_area is None else np.asarray(mean_area, dtype=np.float64)
    sizes = [int(n) for n in p0star["n_cells"]]
    special = dashed if dashed in sizes else max(sizes)
    colors = size_colors([n for n in sizes if n != special] or sizes)
    for n, p in zip(sizes, p0star["p0_star"]):
        if not np.isfinite(p):
            continue
        if n == special:
            ax.plot(a, critical_perimeter(p, a), "k--", lw=1.6, label=f"N = {n}")
        else:
            ax.plot(a, critical_perimeter(p, a), color=colors[n], lw=1.8, label=f"N = {n}")
    ax.set_xlabel(r"$\langle A \rangle$")
    ax.set_ylabel(r"$P_0^*(N, \langle A \rangle) = \sqrt{\langle A \rangle}\, p_0^*(N)$")
    _legend(ax, fontsize=8, frameon=False)
    return fig
