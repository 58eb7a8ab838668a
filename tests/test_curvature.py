"""The pentagon bound at any Gaussian curvature, K at points of each surface, and binned means
(docs/results.md, "Curvature gradients")."""
import numpy as np
import pytest
from scipy import integrate, optimize

import spherevm.geometry as geo
from spherevm.analysis import (binned_mean, gaussian_curvature, pentagon_perimeter, pentagon_perimeter_at_curvature,
                               polygon_perimeter_at_curvature, torus_curvature_range)
from spherevm.constraints import GaussianBump, PeriodicPlane, Sphere, Torus
from spherevm.shapes import planar_pentagon_perimeter


# ----------------------------------------------------------------------------- regular polygon at K
def constructed_perimeter(n, curvature, area=1.0):
    """The regular n-gon built in the embedding (unit sphere or hyperboloid, lengths scaled by
    1/sqrt|K|): vertices on a geodesic circle of radius rho, edges where the plane through the origin
    and two vertices cuts the surface; the area by quadrature in geodesic polar coordinates, rho by
    root finding. Uses neither Gauss-Bonnet nor the right-triangle rule."""
    s = 1.0 if curvature > 0 else -1.0
    cs, sn, atn = (np.cos, np.sin, np.arctan) if s > 0 else (np.cosh, np.sinh, np.arctanh)

    def point(rho, theta):
        return np.array([sn(rho) * np.cos(theta), sn(rho) * np.sin(theta), cs(rho)])

    def area_of(rho):
        normal = np.cross(point(rho, 0.0), point(rho, 2 * np.pi / n))

        def cap(theta):     # the area from the centre out to the edge along direction theta
            r_edge = atn(-normal[2] / (normal[0] * np.cos(theta) + normal[1] * np.sin(theta)))
            return s * (1 - cs(r_edge))
        return n * integrate.quad(cap, 0.0, 2 * np.pi / n, epsabs=1e-14, epsrel=1e-13)[0]

    target = abs(curvature) * area
    hi = np.pi / 2 if s > 0 else 1.0
    while s < 0 and area_of(hi) < target:
        hi *= 2
    rho = optimize.brentq(lambda r: area_of(r) - target, 1e-9, hi - 1e-12 * (s > 0), xtol=1e-15)
    a, b = point(rho, 0.0), point(rho, 2 * np.pi / n)
    side = np.arccos(a @ b) if s > 0 else np.arccosh(a[2] * b[2] - a[0] * b[0] - a[1] * b[1])
    return n * side / np.sqrt(abs(curvature))


@pytest.mark.parametrize("n", [5, 6])
@pytest.mark.parametrize("k_area", [-6.0, -2.5, -1.0, -0.1, 0.05, 1.0, 3.0])
def test_matches_the_polygon_built_numerically(n, k_area):
    area = 1.7
    assert polygon_perimeter_at_curvature(n, k_area / area, area) == pytest.approx(
        constructed_perimeter(n, k_area / area, area), rel=1e-10)


def test_sphere_of_n_cells_matches_the_napier_polygon():
    """K = 1/R^2 with R = sqrt(N / 4 pi): the pentagon of unit area from geometry.regular_polygon."""
    for n_cells in (16, 32, 256, 1024):
        radius = np.sqrt(n_cells / (4 * np.pi))
        rho = optimize.brentq(lambda r: geo.regular_polygon(5, r, radius)[3] - 1.0, 1e-6, 1.5, xtol=1e-16)
        expected = geo.regular_polygon(5, rho, radius)[2]
        assert pentagon_perimeter_at_curvature(1 / radius ** 2) == pytest.approx(expected, rel=1e-12)
        assert pentagon_perimeter(n_cells) == pytest.approx(expected, rel=1e-12)


def test_flat_values_and_continuity_through_zero():
    flat = planar_pentagon_perimeter()
    assert abs(pentagon_perimeter_at_curvature(0.0) - flat) <= 1e-12
    assert abs(polygon_perimeter_at_curvature(6, 0.0) - np.sqrt(8 * np.sqrt(3))) <= 1e-12
    for k in (1e-300, 1e-12, -1e-12, -1e-300):
        assert abs(pentagon_perimeter_at_curvature(k) - flat) <= 1e-12
    # area scaling: P(K, A) = sqrt(A) P(K A, 1)
    doubled = 2 * pentagon_perimeter_at_curvature(1.2)
    assert pentagon_perimeter_at_curvature(0.3, 4.0) == pytest.approx(doubled, rel=1e-14)


@pytest.mark.parametrize("n", [5, 6])
def test_smooth_through_zero(n):
    """No kink or jump at K = 0 or where the series hands over: a degree-10 polynomial fits
    [-0.1, 0.1] to 1e-13, and the slope at 0 is the series' first term,
    dP/dK = -P0 A / (2n) (cot(pi/n)/4 + 5 tan(pi/n)/12)."""
    k = np.linspace(-0.1, 0.1, 401)
    p = polygon_perimeter_at_curvature(n, k)
    fit = np.polynomial.chebyshev.Chebyshev.fit(k, p, 10)
    assert np.abs(fit(k) - p).max() <= 1e-13
    beta = np.pi / n
    p0 = np.sqrt(4 * n * np.tan(beta))
    slope = -p0 / (2 * n) * (1 / np.tan(beta) / 4 + 5 * np.tan(beta) / 12)
    assert fit.deriv()(0.0) == pytest.approx(slope, rel=1e-9)


def test_increasing_with_minus_k_and_vectorised():
    k = np.linspace(-9.0, 6.0, 3000)          # K A from near the ideal pentagon (-3 pi) to near 2 pi
    p = pentagon_perimeter_at_curvature(k)
    assert p.shape == k.shape and np.all(np.diff(p) < 0)
    assert pentagon_perimeter_at_curvature(k.reshape(3, -1)).shape == (3, 1000)
    hexagon = polygon_perimeter_at_curvature(6, k[k > -4 * np.pi])
    assert np.all(np.diff(hexagon) < 0)
    assert np.all(hexagon < pentagon_perimeter_at_curvature(k[k > -4 * np.pi]))


def test_out_of_range_is_refused():
    with pytest.raises(ValueError, match=r"curvature \* area must lie in \(-9.42478, 6.28319\)"):
        pentagon_perimeter_at_curvature(-3 * np.pi)
    with pytest.raises(ValueError, match="curvature \\* area"):
        pentagon_perimeter_at_curvature([0.0, 7.0])
    with pytest.raises(ValueError, match="area must be positive"):
        pentagon_perimeter_at_curvature(0.0, area=0.0)
    with pytest.raises(ValueError, match="n_sides must be >= 3"):
        polygon_perimeter_at_curvature(2, 0.0)


# ----------------------------------------------------------------------------- K on each surface
def fd_curvature(surface, u, v, h=1e-4):
    """K = det(II) / det(I) of a parametrised surface, derivatives by central differences."""
    du = (surface(u + h, v) - surface(u - h, v)) / (2 * h)
    dv = (surface(u, v + h) - surface(u, v - h)) / (2 * h)
    duu = (surface(u + h, v) - 2 * surface(u, v) + surface(u - h, v)) / h ** 2
    dvv = (surface(u, v + h) - 2 * surface(u, v) + surface(u, v - h)) / h ** 2
    duv = (surface(u + h, v + h) - surface(u + h, v - h) - surface(u - h, v + h) + surface(u - h, v - h)) / (4 * h * h)
    nrm = np.cross(du, dv)
    nrm /= np.linalg.norm(nrm)
    first = (du @ du) * (dv @ dv) - (du @ dv) ** 2
    return ((duu @ nrm) * (dvv @ nrm) - (duv @ nrm) ** 2) / first


def test_torus_curvature_against_its_parametrisation():
    torus = Torus(3.0, 1.2)

    def surface(u, v):
        rho = 3.0 + 1.2 * np.cos(v)
        return np.array([rho * np.cos(u), rho * np.sin(u), 1.2 * np.sin(v)])
    for u, v in [(0.3, 0.0), (1.0, 1.0), (2.0, np.pi / 2), (4.0, 2.5), (5.0, np.pi)]:
        assert gaussian_curvature(torus, surface(u, v)) == pytest.approx(fd_curvature(surface, u, v), abs=1e-6)
    k_min, k_max = torus_curvature_range(3.0 / 1.2, 4 * np.pi ** 2 * 3.0 * 1.2)
    assert k_min == pytest.approx(gaussian_curvature(torus, surface(0.0, np.pi)), rel=1e-14)
    assert k_max == pytest.approx(gaussian_curvature(torus, surface(0.0, 0.0)), rel=1e-14)


def test_bump_curvature_against_its_height_field():
    bump = GaussianBump(height=2.0, width=1.5, box=40.0)

    def surface(u, v):
        return np.array([u, v, 2.0 * np.exp(-(u * u + v * v) / (2 * 1.5 ** 2))])
    for u, v in [(0.0, 0.0), (0.7, -0.4), (1.5, 0.0), (2.0, 1.0), (-3.0, 2.0)]:
        assert gaussian_curvature(bump, surface(u, v)) == pytest.approx(fd_curvature(surface, u, v), abs=1e-6)
    assert gaussian_curvature(bump, [0.0, 0.0, 2.0]) == pytest.approx(2.0 ** 2 / 1.5 ** 4, rel=1e-14)
    # the next image of the bump: the same curvature one box over
    assert gaussian_curvature(bump, [40.7, -0.4, 0.0]) == pytest.approx(gaussian_curvature(bump, [0.7, -0.4, 0.0]))

    def ring(rho):           # total curvature of a bump that flattens out is zero (Gauss-Bonnet)
        slope = -2.0 * rho / 1.5 ** 2 * np.exp(-rho ** 2 / (2 * 1.5 ** 2))
        return gaussian_curvature(bump, [rho, 0.0, 0.0]) * np.sqrt(1 + slope ** 2) * 2 * np.pi * rho
    assert abs(integrate.quad(ring, 0.0, 15.0, epsabs=1e-13, limit=200)[0]) <= 1e-9


def test_sphere_and_plane_curvature():
    x = np.random.default_rng(0).normal(size=(7, 3))
    assert np.array_equal(gaussian_curvature(Sphere(), x, radius=2.0), np.full(7, 0.25))
    assert np.array_equal(gaussian_curvature(PeriodicPlane(), x), np.zeros(7))
    with pytest.raises(ValueError, match="radius must be given and positive on a sphere"):
        gaussian_curvature(Sphere(), x)
    with pytest.raises(ValueError, match=r"x must have shape \(\.\.\., 3\)"):
        gaussian_curvature(PeriodicPlane(), x[:, :2])
    with pytest.raises(ValueError, match="aspect must be above 1"):
        torus_curvature_range(1.0, 256)
    with pytest.raises(ValueError, match="constraint must be a Sphere, PeriodicPlane, Torus or GaussianBump, got str"):
        gaussian_curvature("sphere", x)


# ----------------------------------------------------------------------------- binned means
def test_binned_mean_by_quantile_and_edges():
    x = np.array([0.0, 1.0, 2.0, 3.0, 4.0, 5.0, np.nan, 2.0])
    y = np.array([1.0, 3.0, 5.0, 10.0, 20.0, 30.0, 1.0, np.nan])
    b = binned_mean(x, y, bins=2)                 # NaN pairs out; halves at the median 2.5
    assert np.allclose(b.edges, [0, 2.5, 5]) and list(b.count) == [3, 3]
    assert np.allclose(b.x, [1, 4]) and np.allclose(b.mean, [3, 20])
    assert np.allclose(b.sem, [2 / np.sqrt(3), 10 / np.sqrt(3)])
    b = binned_mean(x, y, bins=[1.0, 3.0, 5.0])   # 0 is outside; 5 is in the last bin
    assert list(b.count) == [2, 3] and np.allclose(b.mean, [4, 20])
    b = binned_mean(x, y, bins=5, spacing="linear")
    assert np.allclose(b.edges, [0, 1, 2, 3, 4, 5]) and list(b.count) == [1, 1, 1, 1, 2]
    assert np.isnan(b.sem[0]) and b.sem[4] == pytest.approx(5.0)


def test_binned_mean_with_groups_takes_one_sample_per_group():
    x = np.array([0.0, 0.0, 0.0, 0.0, 0.0, 1.0, 1.0])
    y = np.array([1.0, 3.0, 10.0, 10.0, 10.0, 7.0, 9.0])
    groups = np.array([5, 5, 8, 8, 8, 5, 8])          # pooled, bin 0 would have mean 6.8
    b = binned_mean(x, y, bins=[-0.5, 0.5, 1.5], groups=groups)
    assert list(b.count) == [2, 2]
    assert np.allclose(b.mean, [6.0, 8.0])      # group means 2 and 10, then 7 and 9
    assert np.allclose(b.sem, [4.0, 1.0])
    assert list(binned_mean(np.zeros(4), np.arange(4.0)).count) == [4]   # one value of x: one bin


def test_binned_mean_refuses_bad_input():
    with pytest.raises(ValueError, match="x and y must be 1-d of one length"):
        binned_mean(np.zeros(3), np.zeros(4))
    with pytest.raises(ValueError, match="spacing must be 'quantile' or 'linear'"):
        binned_mean(np.zeros(3), np.zeros(3), spacing="log")
    with pytest.raises(ValueError, match="bins as edges must be at least two increasing values"):
        binned_mean(np.zeros(3), np.zeros(3), bins=[1.0, 0.0])
    with pytest.raises(ValueError, match="groups must have the shape of x"):
        binned_mean(np.zeros(3), np.zeros(3), groups=[0, 1])


def test_the_example_writes_the_ranges(tmp_path):
    """examples/pentagon_bound.py: the CSV's rows are the analytic ranges, and the figure is written."""
    import csv
    import pathlib
    import runpy
    pytest.importorskip("matplotlib")
    example = runpy.run_path(str(pathlib.Path(__file__).resolve().parent.parent / "examples" / "pentagon_bound.py"))
    example["main"](["--out", str(tmp_path), "--cells", "256"])
    rows = {r["surface"]: r for r in csv.DictReader(open(tmp_path / "pentagon_bound.csv"))}
    k_min, k_max = torus_curvature_range(2.0, 256)
    assert float(rows["torus R/r = 2"]["K_min <A>"]) == pytest.approx(k_min, abs=1e-5)
    assert float(rows["torus R/r = 2"]["p_penta(K_max)"]) == pytest.approx(pentagon_perimeter_at_curvature(k_max),
                                                                           abs=1e-5)
    assert float(rows["sphere"]["p_penta(K_min)"]) == pytest.approx(pentagon_perimeter(256), abs=1e-5)
    # bump h/w = 1, w = 16 / 6.5: K on top is 1 / w^2, times <A>: the surface's area over the square / 256
    w = 16 / 6.5

    def stretch(y, x):
        g2 = (x * x + y * y) / w ** 2 * np.exp(-(x * x + y * y) / w ** 2)     # |grad z|^2 with h = w
        return np.sqrt(1 + g2)
    mean_area = integrate.dblquad(stretch, -8, 8, -8, 8, epsabs=1e-9)[0] / 256
    assert float(rows["bump h/w = 1"]["K_max <A>"]) == pytest.approx(mean_area / w ** 2, abs=1e-5)
    assert (tmp_path / "pentagon_bound.png").stat().st_size > 10_000
