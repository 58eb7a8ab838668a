"""Sphere geometry: geodesic lengths, spherical areas and their gradients (see docs/numerics.md).

Analytic references: regular spherical polygons, the two regular tilings, and 50-digit mpmath
evaluations on the exact float64 inputs. Property tests (hypothesis) for symmetry, the triangle
inequality, additivity of areas and gradients against central finite differences. Tilings: the cell
areas sum to 4 pi R^2 and V - E + F = 2.
"""
import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st
from scipy.spatial import ConvexHull, SphericalVoronoi

import spherevm as svm
from spherevm import topology
from spherevm.analysis import pentagon_perimeter, regular_polygon_perimeter
from spherevm.geometry import sphere as geo

mp = pytest.importorskip("mpmath")
mp.mp.dps = 50

EPS = np.finfo(np.float64).eps
FOUR_PI = 4.0 * np.pi
PROPS = settings()   # examples and randomness from the profile in conftest.py


# ----------------------------------------------------------------------------- helpers
def unit(x):
    return x / np.linalg.norm(x, axis=-1)[..., None]


def random_pairs(rng, theta, n):
    """n pairs of float64 unit vectors at nominal angle theta, random orientations."""
    a = unit(rng.normal(size=(n, 3)))
    t = rng.normal(size=(n, 3))
    t = unit(t - (t * a).sum(1)[:, None] * a)
    return a, unit(np.cos(theta) * a + np.sin(theta) * t)


def mpvec(x):
    v = [mp.mpf(float(s)) for s in x]  # exact
    n = mp.sqrt(sum(s * s for s in v))
    return [s / n for s in v], n


def ref_angle(a, b):
    """Angle between the directions of two float64 vectors, at 50 digits."""
    (A, _), (B, _) = mpvec(a), mpvec(b)
    cr = [A[1] * B[2] - A[2] * B[1], A[2] * B[0] - A[0] * B[2], A[0] * B[1] - A[1] * B[0]]
    return mp.atan2(mp.sqrt(sum(s * s for s in cr)), sum(x * y for x, y in zip(A, B)))


def exact_polygon_area(verts):
    """50-digit signed area of the unit-sphere polygon through the (normalised) float64 vertices."""
    vs = [mpvec(v)[0] for v in verts]
    dot = lambda x, y: sum(p * r for p, r in zip(x, y))  # noqa: E731
    a, total = vs[0], mp.mpf(0)
    for b, c in zip(vs, vs[1:] + vs[:1]):
        cross = [b[1] * c[2] - b[2] * c[1], b[2] * c[0] - b[0] * c[2], b[0] * c[1] - b[1] * c[0]]
        total += 2 * mp.atan2(dot(a, cross), 1 + dot(a, b) + dot(b, c) + dot(c, a))
    return total


def exact_regular_polygon(n, rho):
    """Area and perimeter of the regular spherical n-gon of circumradius rho (unit sphere), 50 digits."""
    rho = mp.mpf(rho)
    alpha = 2 * mp.atan2(1, mp.cos(rho) * mp.tan(mp.pi / n))
    return n * alpha - (n - 2) * mp.pi, 2 * n * mp.asin(mp.sin(rho) * mp.sin(mp.pi / n))


def fd_surface_gradient(f, x, h=1e-6):
    """Central differences of f(normalize(y)) at the unit vector x: the tangent gradient of f."""
    g = np.zeros(3)
    for k in range(3):
        e = np.zeros(3)
        e[k] = h
        g[k] = (f(unit(x + e)) - f(unit(x - e))) / (2 * h)
    return g


def tiling_area_sums(state):
    """Per replica: (sum of cell areas) / (4 pi R^2) - 1."""
    g = state.constraint.cell_geometry(state)
    total = np.bincount(state.cell_replica_np(), weights=state.device.to_numpy(g.area), minlength=state.n_replicas)
    return total / (FOUR_PI * state.radius_np() ** 2) - 1.0


def euler_characteristics(state):
    """V - E + F per replica, E counted from the unique undirected edges."""
    e = topology.edges(state.device.to_numpy(state.vertex_neighbors))
    rep = state.vertex_replica_np()
    n_e = np.bincount(rep[e[:, 0]], minlength=state.n_replicas)
    return state.vertices_per_replica - n_e + state.cells_per_replica


def unit_cells(state):
    """Per cell, the unit vertex directions (n_i, 3) in counter-clockwise order."""
    pos = state.device.to_numpy(state.positions)
    u = unit(pos)
    cv, sides = state.device.to_numpy(state.cell_vertices), state.device.to_numpy(state.cell_sides)
    return [u[cv[c, :sides[c]]] for c in range(len(sides))]


def solid_angle_error_bound(a, b, c):
    """First-order rounding bound of solid_angle: Omega = 2 atan2(N, D) with |dN|, |dD| ~ a few eps,
    so |dOmega| <~ eps (20 / |(N, D)| + 2 pi); large only when N and D both vanish (an antipodal pair)."""
    num = np.dot(a, np.cross(b, c))
    den = 1 + np.dot(a, b) + np.dot(b, c) + np.dot(c, a)
    return EPS * (20 / np.hypot(num, den) + 2 * np.pi)


def mod_4pi(x):
    """x wrapped to (-2 pi, 2 pi]: signed areas are defined modulo 4 pi (+-2 pi is one hemisphere)."""
    return -((-x + 2 * np.pi) % FOUR_PI - 2 * np.pi)


def fan_error_bound(verts, apex=None):
    """First-order rounding bound of a fan about ``apex`` (default: the normalised centroid, as in
    polygon_area): sum over the fan of eps (20 / |(N, D)| + 2 pi)."""
    apex = unit(verts.sum(axis=0)) if apex is None else apex
    b, c = verts, np.roll(verts, -1, axis=0)
    num = (apex * np.cross(b, c)).sum(1)
    den = 1 + b @ apex + (b * c).sum(1) + c @ apex
    return float((EPS * (20 / np.hypot(num, den) + 2 * np.pi)).sum())


def voronoi_tiling(points, radius):
    """Spherical Voronoi tiling of the given unit points (scipy), as a State, plus scipy's cell areas."""
    sv = SphericalVoronoi(points)
    sv.sort_vertices_of_regions()
    cells = [r if geo.polygon_area(sv.vertices[r]) > 0 else r[::-1] for r in sv.regions]
    return svm.init.from_polygons(sv.vertices, cells, radius), sv.calculate_areas()


# hypothesis strategies
coord = st.floats(-1.0, 1.0, allow_nan=False, allow_infinity=False)


@st.composite
def unit_vectors(draw):
    v = np.array([draw(coord), draw(coord), draw(coord)])
    assume(np.linalg.norm(v) > 0.1)
    return unit(v)


@st.composite
def cap_triangles(draw, max_radius=1.2, min_area=1e-3):
    """Counter-clockwise or clockwise triangles inside a cap about a random centre, not degenerate."""
    c = draw(unit_vectors())
    pts = []
    for _ in range(3):
        t = draw(unit_vectors())
        t = t - t.dot(c) * c
        assume(np.linalg.norm(t) > 0.1)
        r = draw(st.floats(0.05, max_radius))
        pts.append(unit(np.cos(r) * c + np.sin(r) * unit(t)))
    assume(abs(float(geo.solid_angle(*pts))) > min_area)
    return pts


# ----------------------------------------------------------------------------- regular polygons
RHOS = [1e-3, 0.01, 0.1, 0.5, 1.0, 1.5, np.pi / 2 - 1e-4, np.pi / 2 + 0.03, 2.0, 2.5, 3.0, np.pi - 1e-3]


@pytest.mark.parametrize("n", range(3, 9))
@pytest.mark.parametrize("rho", RHOS)
def test_regular_polygon_area_and_perimeter(n, rho):
    verts, side, perimeter, area = geo.regular_polygon(n, rho)
    exact_area, exact_perimeter = exact_regular_polygon(n, rho)
    num = float(geo.polygon_area(verts))
    if rho < np.pi / 2:
        assert abs(num - float(exact_area)) <= 2e-15 * float(exact_area)
    else:
        # the normalised vertex centroid is then -z, outside the polygon: the fan returns the signed
        # area of the complement, A - 4 pi (equal to A modulo 4 pi), accurately
        complement = float(exact_area - 4 * mp.pi)
        assert abs(num - complement) <= 2e-15 * abs(complement)
    # regular_polygon's own float formula n alpha - (n - 2) pi is exact up to its cancellation
    assert abs(area - float(exact_area)) <= 2 * n * np.spacing(np.pi)
    # the float64 vertices are themselves rounded (~1 ulp absolute each): a few ulp absolute per side
    lengths = geo.geodesic_length(verts, np.roll(verts, -1, axis=0))
    assert np.all(np.abs(lengths - side) <= 4 * EPS * (1 + side))
    assert abs(float(geo.polygon_perimeter(verts)) - float(exact_perimeter)) <= 4 * EPS * (n + float(exact_perimeter))
    assert abs(perimeter - float(exact_perimeter)) <= 4 * EPS * float(exact_perimeter)


@pytest.mark.parametrize("n", range(3, 9))
def test_regular_polygon_limits(n):
    # on the equator: a hemisphere, sides 2 pi / n
    _, side, perimeter, area = geo.regular_polygon(n, np.pi / 2)
    assert area == pytest.approx(2 * np.pi, rel=1e-15)
    assert side == pytest.approx(2 * np.pi / n, rel=1e-15)
    # the polygon at pi - rho is the complement of the one at rho (mirrored through the equator)
    for rho in (0.3, 1.0, 1.4):
        a1 = geo.regular_polygon(n, rho)[3]
        a2 = geo.regular_polygon(n, np.pi - rho)[3]
        assert a1 + a2 == pytest.approx(FOUR_PI, rel=1e-15)
    # radius scaling and the flat limit (regular n-gon area n/2 rho^2 sin(2 pi/n))
    verts, side, perimeter, area = geo.regular_polygon(n, 0.2, radius=3.0)
    assert float(geo.polygon_area(verts / 3.0, radius=3.0)) == pytest.approx(area, rel=1e-14)
    assert float(geo.polygon_perimeter(verts / 3.0, radius=3.0)) == pytest.approx(perimeter, rel=1e-15)
    flat = 0.5 * n * 1e-4 ** 2 * np.sin(2 * np.pi / n)
    assert float(geo.polygon_area(geo.regular_polygon(n, 1e-4)[0])) == pytest.approx(flat, rel=1e-7)


# ----------------------------------------------------------------------------- regular tilings
def test_dodecahedron():
    s = svm.init.regular_tiling("dodecahedron")
    R = float(s.radius_np()[0])
    assert R == pytest.approx(np.sqrt(12 / FOUR_PI))
    e = topology.edges(s.vertex_neighbors)
    assert (s.n_vertices, len(e), s.n_cells) == (20, 30, 12)
    assert euler_characteristics(s).tolist() == [2]
    lengths = s.constraint.edge_lengths(s, e[:, 0], e[:, 1])
    # central angle between adjacent vertices of the regular dodecahedron: acos(sqrt(5)/3)
    assert np.abs(lengths / R - np.arccos(np.sqrt(5) / 3)).max() <= 1e-14
    area, perimeter = svm.analysis.cell_shapes(s)
    assert np.abs(area - FOUR_PI * R ** 2 / 12).max() <= 1e-14
    assert np.abs(perimeter - pentagon_perimeter(12)).max() <= 1e-14 * perimeter.max()
    assert np.abs(perimeter - 5 * lengths.mean()).max() <= 1e-14 * perimeter.max()
    assert abs(tiling_area_sums(s)[0]) <= 1e-10


def test_truncated_icosahedron():
    R = 2.7
    s = svm.init.regular_tiling("truncated_icosahedron", radius=R)
    e = topology.edges(s.vertex_neighbors)
    assert (s.n_vertices, len(e), s.n_cells) == (60, 90, 32)
    assert euler_characteristics(s).tolist() == [2]
    lengths = s.constraint.edge_lengths(s, e[:, 0], e[:, 1])
    # edge of the unit-circumradius truncated icosahedron: chord 4 / sqrt(58 + 18 sqrt 5)
    edge = 2 * np.arcsin(2 / np.sqrt(58 + 18 * np.sqrt(5)))
    assert np.abs(lengths / R - edge).max() <= 1e-14
    area, perimeter = svm.analysis.cell_shapes(s)
    sides = s.cell_sides
    assert (sides == 5).sum() == 12 and (sides == 6).sum() == 20
    for k in (5, 6):
        # the regular k-gon with this side: sin(s/2) = sin(rho) sin(pi/k)
        rho = np.arcsin(np.sin(edge / 2) / np.sin(np.pi / k))
        _, side, per, a = geo.regular_polygon(k, rho, radius=R)
        assert side == pytest.approx(edge * R, rel=1e-14)
        assert np.abs(area[sides == k] - a).max() <= 1e-13 * a
        assert np.abs(perimeter[sides == k] - per).max() <= 1e-14 * per
    assert 12 * geo.regular_polygon(5, np.arcsin(np.sin(edge / 2) / np.sin(np.pi / 5)))[3] \
        + 20 * geo.regular_polygon(6, np.arcsin(np.sin(edge / 2) / np.sin(np.pi / 6)))[3] \
        == pytest.approx(FOUR_PI, rel=1e-14)
    assert abs(tiling_area_sums(s)[0]) <= 1e-10


def test_regular_pentagon_perimeter_matches_geometry():
    """analysis.regular_polygon_perimeter (acos route) against geometry.regular_polygon (Napier)."""
    for rho in (0.1, 0.5, 1.0, 1.3):
        _, _, per, a = geo.regular_polygon(5, rho, radius=1.7)
        assert regular_polygon_perimeter(5, a, 1.7) == pytest.approx(per, rel=1e-13)


# ----------------------------------------------------------------------------- lengths: accuracy
ANGLES = [1e-9, 1e-8, 1e-7, 1e-6, 1e-4, 1e-2, 0.5, 1.0, np.pi / 2, 2.0, 3.0, np.pi - 1e-3, np.pi - 1e-6,
          np.pi - 1e-9]


@pytest.mark.parametrize("theta", ANGLES)
def test_default_length_accuracy(theta):
    """Default and difference routes against 50 digits, from 1e-9 R to nearly pi R."""
    rng = np.random.default_rng(int(1e6 * theta) + 7)
    a, b = random_pairs(rng, theta, 40)
    R = 3.3
    for x, y in zip(a, b):
        ref = ref_angle(x, y)
        d = R * float(geo.geodesic_length(x, y))
        # the half-angle form assumes |x| = |y| = 1; float64 unit vectors are off by ~1e-16 and that
        # enters the chord |x - y| in quadrature: relative error (|x| - |y|)^2 / (2 theta^2)
        dn = float(mpvec(x)[1] - mpvec(y)[1])
        bound = 4 * EPS + 0.5 * (dn / float(ref)) ** 2
        assert abs(d - R * float(ref)) <= bound * R * float(ref)
        assert abs(d - R * float(ref)) <= 1e-13 * R * float(ref)  # ~1e-14 at 1e-9 R, a few ulp above 1e-8 R
        if theta >= 1e-8:
            assert abs(d - R * float(ref)) <= 2e-15 * R * float(ref)
        # the difference form does not assume unit norms: a few ulp everywhere
        dd = float(geo.geodesic_length_difference(x, y))
        assert abs(dd - float(ref)) <= 4 * EPS * float(ref)


def _rel_errors(route, a, b):
    ref = np.array([float(ref_angle(x, y)) for x, y in zip(a, b)])
    return np.abs(geo.geodesic_length(a, b, route) - ref) / ref


def test_acos_route_fails_for_short_arcs():
    """Why the default is not acos: at 1e-9 acos has no correct digit; at 1e-4 it has lost half of them."""
    rng = np.random.default_rng(1)
    a, b = random_pairs(rng, 1e-9, 40)
    e_acos, e_def = _rel_errors("acos", a, b), _rel_errors("default", a, b)
    assert np.median(e_acos) >= 0.5           # a.b rounds to 1 or 1 - ulp: acos gives 0 or 1.5e-8
    assert e_acos.max() >= 1e10 * e_def.max()
    a, b = random_pairs(rng, 1e-4, 40)
    e_acos, e_def = _rel_errors("acos", a, b), _rel_errors("default", a, b)
    assert np.median(e_acos) >= 1e-11        # eps / theta^2 ~ 2e-8 at most
    assert e_def.max() <= 2 * EPS


def test_atan2_route_cancels_for_short_arcs():
    """atan2(|a x b|, a.b): |a x b| is a difference of O(1) products, relative error ~eps/theta."""
    rng = np.random.default_rng(2)
    a, b = random_pairs(rng, 1e-9, 40)
    e = _rel_errors("atan2", a, b)
    assert np.median(e) >= 1e-10
    assert np.allclose(_rel_errors("asin", a, b), e, rtol=1e-6)  # same cancelled numerator
    a, b = random_pairs(rng, np.pi - 1e-9, 40)  # but fine near the antipode
    assert _rel_errors("atan2", a, b).max() <= 2 * EPS


def test_asin_route_fails_beyond_a_right_angle():
    rng = np.random.default_rng(3)
    for theta in (2.0, 3.0, np.pi - 1e-6):
        a, b = random_pairs(rng, theta, 20)
        ref = np.array([float(ref_angle(x, y)) for x, y in zip(a, b)])
        d = geo.geodesic_length(a, b, "asin")
        assert np.allclose(d, np.pi - ref, rtol=0, atol=1e-14)  # it returns pi - theta
        assert np.all(np.abs(d - ref) / ref >= 0.3)
    # and it is ill conditioned at pi/2: sqrt(eps) absolute error
    a, b = random_pairs(rng, np.pi / 2, 200)
    assert _rel_errors("asin", a, b).max() >= 1e-10
    assert _rel_errors("default", a, b).max() <= 2 * EPS


def test_length_routes_reject_unknown_route():
    with pytest.raises(ValueError):
        geo.geodesic_length(np.array([1.0, 0, 0]), np.array([0, 1.0, 0]), "haversine")


# ----------------------------------------------------------------------------- lengths: properties
@PROPS
@given(unit_vectors(), unit_vectors())
def test_length_symmetry_and_range(a, b):
    for route in geo.LENGTH_ROUTES:
        d_ab, d_ba = geo.geodesic_length(a, b, route), geo.geodesic_length(b, a, route)
        assert d_ab == d_ba  # bitwise: every route is built from symmetric operations
        assert 0.0 <= d_ab <= np.pi
    assert geo.geodesic_length(a, a) == 0.0
    assert geo.geodesic_length(a, -a) == pytest.approx(np.pi, abs=4 * EPS)
    assert float(geo.geodesic_length_difference(a, b)) == pytest.approx(float(geo.geodesic_length(a, b)),
                                                                         rel=4 * EPS, abs=4 * EPS)


@PROPS
@given(unit_vectors(), unit_vectors(), unit_vectors())
def test_triangle_inequality(a, b, c):
    ab, bc, ac = (float(geo.geodesic_length(x, y)) for x, y in ((a, b), (b, c), (a, c)))
    assert ac <= ab + bc + 8 * EPS
    # equality for a point on the geodesic between a and c
    assume(ac < np.pi - 1e-3)
    m = unit(a + c)
    assert float(geo.geodesic_length(a, m) + geo.geodesic_length(m, c)) == pytest.approx(ac, rel=1e-14, abs=1e-15)


@PROPS
@given(unit_vectors(), unit_vectors(), st.floats(-9, np.log10(np.pi - 1e-3)))
def test_length_across_scales_matches_reference(a, t, log_theta):
    """Random orientation and a random angle from 1e-9 to pi - 1e-3: default route to 1e-13."""
    t = t - t.dot(a) * a
    assume(np.linalg.norm(t) > 0.1)
    theta = 10.0 ** log_theta
    b = unit(np.cos(theta) * a + np.sin(theta) * unit(t))
    ref = float(ref_angle(a, b))
    assert abs(float(geo.geodesic_length(a, b)) - ref) <= 1e-13 * ref
    assert abs(float(geo.geodesic_length_difference(a, b)) - ref) <= 4 * EPS * ref


# ----------------------------------------------------------------------------- length gradients
@PROPS
@given(unit_vectors(), unit_vectors())
def test_length_gradient_matches_finite_differences(a, b):
    theta = float(geo.geodesic_length(a, b))
    assume(0.05 < theta < np.pi - 0.05)
    fd = fd_surface_gradient(lambda x: float(geo.geodesic_length(x, b)), a)
    for grad in (geo.geodesic_length_gradient, geo.geodesic_length_gradient_robust,
                 geo.geodesic_length_gradient_acos):
        g = grad(a, b)
        assert np.abs(g - fd).max() <= 1e-7
        if grad is geo.geodesic_length_gradient_robust:
            assert abs(g.dot(a)) <= 8 * EPS  # tangent at a (to the rounding of |a| = 1)
        else:  # acos: b - (a.b) a cancels at both ends; default: b - a ~ -2a near the antipode
            assert abs(g.dot(a)) <= 8 * EPS / np.sin(theta)
        if grad is not geo.geodesic_length_gradient_acos:  # acos is off unit length by ~eps/theta^2
            assert np.linalg.norm(g) == pytest.approx(1.0, abs=8 * EPS / np.sin(theta))


@pytest.mark.parametrize("theta", [1e-12, 1e-9, 1e-6, 1e-2, 1.0, 3.0, np.pi - 1e-6, np.pi - 1e-9])
def test_length_gradient_accuracy(theta):
    """-t/|t| from b - a stays accurate for short arcs where the acos derivative is NaN or wrong."""
    rng = np.random.default_rng(11)
    a, b = random_pairs(rng, theta, 30)
    ref = []
    for x, y in zip(a, b):
        (A, _), (B, _) = mpvec(x), mpvec(y)
        ab = sum(p * q for p, q in zip(A, B))
        t = [q - ab * p for p, q in zip(A, B)]
        n = mp.sqrt(sum(s * s for s in t))
        ref.append([float(-s / n) for s in t])
    ref = np.array(ref)
    err = lambda g: np.linalg.norm(g - ref, axis=1)  # noqa: E731
    assert err(geo.geodesic_length_gradient_robust(a, b)).max() <= 4 * EPS
    if theta <= np.pi / 2:
        assert err(geo.geodesic_length_gradient(a, b)).max() <= 4 * EPS
    else:  # b - a ~ -2a cancels against its radial part: error ~ eps / (pi - theta)
        assert err(geo.geodesic_length_gradient(a, b)).max() <= 10 * EPS / (np.pi - theta)
    with np.errstate(invalid="ignore", divide="ignore"):
        e_acos = err(geo.geodesic_length_gradient_acos(a, b))
    if theta <= 1e-9 or theta >= np.pi - 1e-9:
        assert not np.all(e_acos <= 1e-3)  # NaN (a.b rounds to +-1) or a wrong direction
    if theta == 1e-6:
        assert np.median(e_acos) >= 1e-7  # eps / theta^2 in principle, ~1e-5 here


def test_zero_length_edge_subgradient():
    """Coincident points: the length is a cone, any unit tangent (or less) is a subgradient; we return 0."""
    rng = np.random.default_rng(4)
    a = unit(rng.normal(size=(20, 3)))
    # probes x = exp_a(h u) for unit tangents u in 16 directions around each a, h = 1e-3
    t1 = unit(np.cross(a, rng.normal(size=a.shape)))
    t2 = np.cross(a, t1)
    phis = np.linspace(0, 2 * np.pi, 16, endpoint=False)
    u = np.cos(phis)[:, None, None] * t1 + np.sin(phis)[:, None, None] * t2      # (16, 20, 3)
    h = 1e-3
    x = np.cos(h) * a + np.sin(h) * u
    d = geo.geodesic_length(x, np.broadcast_to(a, x.shape))
    assert np.allclose(d, h, rtol=1e-9)                 # the cone: d(exp_a(h u), a) = h
    for grad in (geo.geodesic_length_gradient, geo.geodesic_length_gradient_robust):
        g = grad(a, a.copy())
        # the subgradient inequality d(x, a) >= d(a, a) + g.(x - a), at every probe
        assert np.all(d >= 0.0 + (g * (x - a)).sum(axis=-1))
        assert np.all(g == 0.0)
    # the inequality has teeth: a tangent of length 0.99 is a subgradient, one of length 1.01 is not
    g_in, g_out = 0.99 * t1, 1.01 * t1
    assert np.all(d >= (g_in * (x - a)).sum(axis=-1))
    assert not np.all(d >= (g_out * (x - a)).sum(axis=-1))
    with np.errstate(invalid="ignore", divide="ignore"):
        g_acos = geo.geodesic_length_gradient_acos(a, a.copy())
    # a.a rounds to 1 (0/0: NaN) or to 1 - ulp (a tiny vector in an arbitrary direction)
    assert np.isnan(g_acos).any()
    # a polygon with a collapsed edge has a finite perimeter gradient (from its two other edges)
    verts = geo.regular_polygon(5, 0.4)[0]
    verts = np.insert(verts, 2, verts[2], axis=0)
    g = geo.polygon_perimeter_gradient(verts)
    assert np.all(np.isfinite(g))
    expected = geo.geodesic_length_gradient(verts[2], verts[1])
    assert np.allclose(g[2], expected, atol=1e-15)


# ----------------------------------------------------------------------------- triangle areas
@PROPS
@given(unit_vectors(), unit_vectors(), unit_vectors())
def test_solid_angle_symmetries(a, b, c):
    om = float(geo.solid_angle(a, b, c))
    assert -2 * np.pi <= om <= 2 * np.pi
    # undefined only when N = D = 0 (two antipodal vertices: a lune of any width)
    tol = 2 * solid_angle_error_bound(a, b, c)
    assume(np.isfinite(tol))
    assert abs(mod_4pi(float(geo.solid_angle(a, c, b)) + om)) <= tol   # antisymmetric under swap
    assert abs(mod_4pi(float(geo.solid_angle(b, a, c)) + om)) <= tol
    assert abs(mod_4pi(float(geo.solid_angle(b, c, a)) - om)) <= tol   # cyclic
    assert abs(mod_4pi(float(geo.solid_angle(-a, -c, -b)) - om)) <= tol  # point reflection
    assert abs(mod_4pi(float(geo.solid_angle_difference(a, b, c)) - om)) <= tol
    assert float(geo.triangle_area(a, b, c, radius=2.5)) == pytest.approx(6.25 * om, rel=4 * EPS, abs=4 * EPS)


@PROPS
@given(unit_vectors(), unit_vectors(), unit_vectors(), st.floats(0.01, 0.99))
def test_solid_angle_additivity(a, b, c, s):
    """Splitting a triangle at a point of one side, and fanning it about a fourth point."""
    # no (nearly) antipodal pair: the triangle would not be defined
    assume(max(float(geo.geodesic_length(x, y)) for x, y in ((a, b), (b, c), (c, a))) < np.pi - 1e-2)
    om = float(geo.solid_angle(a, b, c))
    m = unit((1 - s) * b + s * c)  # on the geodesic bc
    split = float(geo.solid_angle(a, b, m) + geo.solid_angle(a, m, c))
    # each side to its rounding bound (large when a pair is nearly antipodal: N and D both small)
    tol = sum(solid_angle_error_bound(*t) for t in ((a, b, c), (a, b, m), (a, m, c)))
    assert abs(split - om) <= max(tol, 1e-13)
    # any apex p: the fan sum equals the area modulo 4 pi (exactly, unless p crosses an edge's antipode)
    p = unit(a + b + c + 0.3 * np.array([s, 1 - s, 0.5]))
    fan = float(geo.solid_angle(p, a, b) + geo.solid_angle(p, b, c) + geo.solid_angle(p, c, a))
    tol = sum(solid_angle_error_bound(*t) for t in ((a, b, c), (p, a, b), (p, b, c), (p, c, a)))
    assert abs(mod_4pi(fan - om)) <= max(tol, 1e-13)


@PROPS
@given(cap_triangles(max_radius=1.0, min_area=1e-2))
def test_triangle_area_routes_agree(tri):
    """Girard and L'Huilier agree with the default on well-shaped, not-too-small triangles."""
    a, b, c = tri
    om = float(geo.solid_angle(a, b, c))
    assert float(geo.solid_angle_difference(a, b, c)) == pytest.approx(om, rel=1e-13)
    assert float(geo.solid_angle_lhuilier(a, b, c)) == pytest.approx(om, rel=1e-7)
    assert float(geo.solid_angle_girard(a, b, c)) == pytest.approx(om, rel=1e-7)
    al, be, ga = geo.triangle_angles(a, b, c)
    assert 0 < al < np.pi and 0 < be < np.pi and 0 < ga < np.pi


def test_triangle_area_routes_on_tiny_triangles():
    """Tiny triangles: the default keeps absolute (not relative) accuracy, Girard keeps neither."""
    verts = geo.regular_polygon(3, 1e-6)[0]
    rng = np.random.default_rng(5)
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    a, b, c = verts @ q.T
    (A, _), (B, _), (C, _) = mpvec(a), mpvec(b), mpvec(c)
    dot = lambda x, y: sum(p * r for p, r in zip(x, y))  # noqa: E731
    cross = [B[1] * C[2] - B[2] * C[1], B[2] * C[0] - B[0] * C[2], B[0] * C[1] - B[1] * C[0]]
    ref = float(2 * mp.atan2(dot(A, cross), 1 + dot(A, B) + dot(B, C) + dot(C, A)))
    assert ref == pytest.approx(float(exact_regular_polygon(3, 1e-6)[0]), rel=1e-9)
    assert abs(float(geo.solid_angle_difference(a, b, c)) - ref) <= 4 * EPS * ref
    assert abs(float(geo.solid_angle_lhuilier(a, b, c)) - ref) <= 16 * EPS * ref
    assert abs(float(geo.solid_angle(a, b, c)) - ref) <= 8 * EPS  # absolute
    assert abs(float(geo.solid_angle_girard(a, b, c)) - ref) >= 1.0 * ref  # no correct digit


# ----------------------------------------------------------------------------- area gradients
@PROPS
@given(cap_triangles())
def test_solid_angle_gradient_matches_finite_differences(tri):
    a, b, c = tri
    fd = fd_surface_gradient(lambda x: float(geo.solid_angle(a, x, c)), b)
    scale = max(np.linalg.norm(fd), 1e-3)
    for grad in (geo.solid_angle_gradient, geo.solid_angle_gradient_difference):
        g = geo.tangent_project(b, grad(a, b, c))
        assert np.abs(g - fd).max() <= 1e-6 * scale
    # the other two slots through cyclic symmetry
    fd_a = fd_surface_gradient(lambda x: float(geo.solid_angle(x, b, c)), a)
    g_a = geo.tangent_project(a, geo.solid_angle_gradient(c, a, b))
    assert np.abs(g_a - fd_a).max() <= 1e-6 * max(np.linalg.norm(fd_a), 1e-3)


@st.composite
def perturbed_polygons(draw):
    n = draw(st.integers(3, 9))
    rho = draw(st.floats(0.05, 1.3))
    verts = geo.regular_polygon(n, rho)[0]
    seed = draw(st.integers(0, 2 ** 32 - 1))
    rng = np.random.default_rng(seed)
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    verts = unit(verts + 0.15 * rho * rng.normal(size=verts.shape)) @ q.T
    area = float(geo.polygon_area(verts))
    assume(area > 1e-3 * rho ** 2)
    return verts


@PROPS
@given(perturbed_polygons())
def test_polygon_gradients_match_finite_differences(verts):
    """Finite differences move the fan apex (polygon_area recomputes it); the analytic gradient holds
    it fixed. They agree because the area does not depend on the apex."""
    g_area = geo.polygon_area_gradient(verts, radius=1.3)
    g_per = geo.polygon_perimeter_gradient(verts, radius=1.3)
    for i in range(len(verts)):
        def area(x, i=i):
            v = verts.copy()
            v[i] = x
            return float(geo.polygon_area(v, radius=1.3))

        def perimeter(x, i=i):
            v = verts.copy()
            v[i] = x
            return float(geo.polygon_perimeter(v, radius=1.3))

        fa, fp = fd_surface_gradient(area, verts[i]), fd_surface_gradient(perimeter, verts[i])
        assert np.abs(g_area[i] - fa).max() <= 1e-6 * max(np.linalg.norm(fa), 1e-2)
        assert np.abs(g_per[i] - fp).max() <= 1e-6 * max(np.linalg.norm(fp), 1e-2)


@PROPS
@given(perturbed_polygons())
def test_edge_area_gradient_is_the_polygon_area_gradient(verts):
    """The apex-free edge form equals the fan gradient: w(v, prev) - w(v, next), tangent at v."""
    prv, nxt = np.roll(verts, 1, axis=0), np.roll(verts, -1, axis=0)
    edge = geo.edge_area_gradient(verts, prv) - geo.edge_area_gradient(verts, nxt)
    fan = geo.polygon_area_gradient(verts)
    assert np.abs(edge - fan).max() <= 1e-12 * np.abs(fan).max()
    assert np.abs((edge * verts).sum(axis=1)).max() <= 1e-15 * np.abs(edge).max() + 1e-16


def test_edge_area_gradient_of_a_short_edge():
    """tan(theta/2) along the arc normal, to a few ulp for an edge of 1e-9."""
    b = np.array([0.0, 0.0, 1.0])
    d = np.array([np.sin(1e-9), 0.0, np.cos(1e-9)])
    w = geo.edge_area_gradient(b, d)
    assert w[1] == pytest.approx(np.tan(0.5e-9), rel=4 * EPS)          # z x x = +y
    assert abs(w[0]) + abs(w[2]) == 0.0


@PROPS
@given(perturbed_polygons(), st.floats(0.0, 0.5), st.floats(0.0, 2 * np.pi))
def test_polygon_area_independent_of_apex(verts, r, phi):
    area = float(geo.polygon_area(verts))
    c = unit(verts.sum(axis=0))
    e1 = unit(np.cross(c, [0.3, 0.5, 0.7]))
    e2 = np.cross(c, e1)
    apex = unit(c + r * (np.cos(phi) * e1 + np.sin(phi) * e2))
    fan = float(geo.solid_angle(apex[None, :], verts, np.roll(verts, -1, axis=0)).sum())
    assert fan == pytest.approx(area, abs=1e-13)


# ----------------------------------------------------------------------------- tilings
@pytest.mark.parametrize("n_cells", [100, 1000])
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_random_tiling_area_sum_and_euler(n_cells, seed):
    s = svm.init.random_tiling(n_cells, replicas=3, seed=seed)
    assert np.all(np.abs(tiling_area_sums(s)) <= 1e-10)
    assert euler_characteristics(s).tolist() == [2, 2, 2]
    # every cell: positive area, and the constraint agrees with the geometry functions
    g = s.constraint.cell_geometry(s)
    radius_c = s.radius_np()[s.cell_replica_np()]
    cells = unit_cells(s)
    area = np.array([float(geo.polygon_area(v)) for v in cells]) * radius_c ** 2
    per = np.array([float(geo.polygon_perimeter(v)) for v in cells]) * radius_c
    assert np.all(g.area > 0)
    # polygon_area (centroid fan, absolute accuracy) within its own rounding bound
    bound = np.array([fan_error_bound(v) for v in cells]) * radius_c ** 2
    assert np.all(np.abs(g.area - area) <= bound + 4 * EPS * area)
    assert np.allclose(g.perimeter, per, rtol=1e-14, atol=0)
    # the constraint's fan (about a vertex, difference numerator) has relative accuracy: the
    # smallest cells against 50-digit areas of the very unit vectors it used
    for c in np.argsort(area)[:5]:
        verts = g.unit[s.cell_vertices[c, :s.cell_sides[c]]]
        assert abs(g.area[c] - float(exact_polygon_area(verts)) * radius_c[c] ** 2) <= 4 * EPS * g.area[c]


def test_random_tiling_ensemble_radius():
    s = svm.init.random_tiling(300, replicas=5, seed=9, radius=4.2)
    assert np.all(np.abs(tiling_area_sums(s)) <= 1e-10)
    assert np.all(euler_characteristics(s) == 2)


def test_constraint_corner_gradients_match_geometry():
    """The constraint's per-corner gradients equal polygon_area_gradient / polygon_perimeter_gradient."""
    s = svm.init.random_tiling(60, seed=3, radius=2.2)
    dA, dP = s.constraint.corner_gradients(s, s.constraint.cell_geometry(s))
    cv, sides = s.cell_vertices, s.cell_sides
    cells = unit_cells(s)
    R = 2.2
    for c in range(s.n_cells):
        ga = geo.polygon_area_gradient(cells[c], radius=R) / R  # with respect to positions x = R u
        gp = geo.polygon_perimeter_gradient(cells[c], radius=R) / R
        for j, v in enumerate(cv[c, :sides[c]]):
            k = int(np.flatnonzero(s.vertex_cells[v] == c)[0])
            assert np.allclose(dA[v, k], ga[j], rtol=0, atol=1e-13)
            assert np.allclose(dP[v, k], gp[j], rtol=0, atol=1e-13)


@PROPS
@given(st.integers(4, 12), st.integers(0, 2 ** 32 - 1))
def test_small_voronoi_tilings_cover_the_sphere(n_cells, seed):
    """Small random tilings (spherical Voronoi, built independently of init.random_tiling)."""
    rng = np.random.default_rng(seed)
    pts = unit(rng.normal(size=(n_cells, 3)))
    R = float(rng.uniform(0.5, 5.0))
    s, scipy_areas = voronoi_tiling(pts, R)
    assert euler_characteristics(s).tolist() == [2]
    area = s.constraint.cell_geometry(s).area
    # each fan triangle is backward stable: error ~ eps (|dN| + |dD|) / |(N, D)|, which grows when a
    # cell has two nearly antipodal vertices (then N and D both vanish); that happens only when all
    # points lie in one hemisphere (the origin outside their hull), the draws random_tiling rejects;
    # the constraint fans each cell about its first vertex
    bound = np.array([fan_error_bound(v, apex=v[0]) for v in unit_cells(s)])
    assert np.all(np.abs(area - R ** 2 * scipy_areas) <= R ** 2 * (bound + 1e-14))
    err = abs(tiling_area_sums(s)[0])
    assert err <= bound.sum() / FOUR_PI
    if np.all(ConvexHull(pts).equations[:, 3] < 0):
        assert err <= 1e-10


@pytest.mark.parametrize("n_cells", [4, 5, 6, 12])
@pytest.mark.parametrize("vertices", ["centroid", "circumcenter"])
def test_small_random_tilings_area_sum(n_cells, vertices):
    """Small N: random_tiling redraws point sets within one hemisphere and folded tilings."""
    for seed in (0, 1, 2):
        s = svm.init.random_tiling(n_cells, replicas=6, seed=seed, vertices=vertices)
        assert np.all(np.abs(tiling_area_sums(s)) <= 1e-10)
        assert np.all(euler_characteristics(s) == 2)
        assert np.all(s.constraint.cell_geometry(s).area > 0)


@pytest.mark.parametrize("name", svm.init.REGULAR_TILINGS)
@pytest.mark.parametrize("radius", [None, 0.3, 17.0])
def test_regular_tiling_area_sum(name, radius):
    s = svm.init.regular_tiling(name, radius=radius)
    assert abs(tiling_area_sums(s)[0]) <= 1e-10
    assert euler_characteristics(s).tolist() == [2]
