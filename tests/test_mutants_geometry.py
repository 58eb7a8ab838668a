"""Tests that kill mutants of spherevm/geometry/sphere.py that survived the existing tests.

Found with ``python3 benchmarks/mutate.py spherevm/geometry/sphere.py ...`` (docs/testing.md,
"Mutation testing"): known answers on the octant triangle and a generic triangle, every route
against the default one, the radius defaults and scalings.
"""
import math

import numpy as np
import pytest

from spherevm.geometry import sphere as geo

EX, EY, EZ = np.eye(3)


def _unit(v):
    v = np.asarray(v, dtype=np.float64)
    return v / np.linalg.norm(v)


# a generic, counter-clockwise (seen from outside) triangle of moderate size
A = _unit([1.0, 0.2, 0.3])
B = _unit([0.3, 1.0, 0.1])
C = _unit([0.2, 0.4, 1.0])


def _solid_angle_reference(a, b, c):
    # Girard with angles from tangent vectors, independent of the module's formulas
    def angle(p, q, r):
        tq = q - np.dot(q, p) * p
        tr = r - np.dot(r, p) * p
        return math.acos(np.dot(tq, tr) / (np.linalg.norm(tq) * np.linalg.norm(tr)))
    return angle(a, b, c) + angle(b, c, a) + angle(c, a, b) - math.pi


def test_octant_triangle_known_answers():
    assert geo.solid_angle(EX, EY, EZ) == pytest.approx(math.pi / 2, rel=1e-15)
    assert geo.solid_angle(EX, EZ, EY) == pytest.approx(-math.pi / 2, rel=1e-15)
    for f in (geo.solid_angle_girard, geo.solid_angle_lhuilier, geo.solid_angle_difference):
        assert f(EX, EY, EZ) == pytest.approx(math.pi / 2, rel=1e-12), f.__name__
        assert f(EX, EZ, EY) == pytest.approx(-math.pi / 2, rel=1e-12), f.__name__
    for ang in geo.triangle_angles(EX, EY, EZ):
        assert ang == pytest.approx(math.pi / 2, rel=1e-12)
    for route in geo.LENGTH_ROUTES:
        if route != "asin":
            assert geo.geodesic_length(EX, EY, route=route) == pytest.approx(math.pi / 2, rel=1e-15), route
    assert geo.geodesic_length(EX, EY, route="asin") == pytest.approx(math.pi / 2, rel=1e-7)
    assert geo.geodesic_length_difference(EX, EY) == pytest.approx(math.pi / 2, rel=1e-15)
    assert geo.triangle_area(EX, EY, EZ) == pytest.approx(math.pi / 2, rel=1e-15)
    assert geo.triangle_area(EX, EY, EZ, radius=3.0) == pytest.approx(9 * math.pi / 2, rel=1e-15)


def test_generic_triangle_every_route_agrees():
    ref = _solid_angle_reference(A, B, C)
    assert ref > 0.1
    for f in (geo.solid_angle, geo.solid_angle_girard, geo.solid_angle_lhuilier, geo.solid_angle_difference):
        assert f(A, B, C) == pytest.approx(ref, rel=1e-12), f.__name__
        assert f(A, C, B) == pytest.approx(-ref, rel=1e-12), f.__name__
    # interior angles, each against the tangent-vector angle
    al, be, ga = geo.triangle_angles(A, B, C)
    assert al + be + ga - math.pi == pytest.approx(ref, rel=1e-12)
    t_b, t_c = B - np.dot(B, A) * A, C - np.dot(C, A) * A
    assert al == pytest.approx(math.acos(np.dot(t_b, t_c) / np.linalg.norm(t_b) / np.linalg.norm(t_c)), rel=1e-12)
    t_c, t_a = C - np.dot(C, B) * B, A - np.dot(A, B) * B
    assert be == pytest.approx(math.acos(np.dot(t_c, t_a) / np.linalg.norm(t_c) / np.linalg.norm(t_a)), rel=1e-12)
    # lengths: every route, both orders
    theta = math.acos(np.dot(A, B))
    for route in geo.LENGTH_ROUTES:
        assert geo.geodesic_length(A, B, route=route) == pytest.approx(theta, rel=1e-12), route
        assert geo.geodesic_length(B, A, route=route) == pytest.approx(theta, rel=1e-12), route
    assert geo.geodesic_length_difference(A, B) == pytest.approx(theta, rel=1e-12)
    assert geo.geodesic_length_difference(B, A) == pytest.approx(theta, rel=1e-12)


def test_obtuse_arcs_and_routes():
    a, b = EX, _unit([-1.0, 0.5, 0.0])          # an arc longer than pi/2
    theta = math.acos(np.dot(a, b))
    assert theta > math.pi / 2
    for route in ("default", "acos", "atan2"):
        assert geo.geodesic_length(a, b, route=route) == pytest.approx(theta, rel=1e-12)
    assert geo.geodesic_length_difference(a, b) == pytest.approx(theta, rel=1e-12)
    assert geo.geodesic_length(a, b, route="asin") == pytest.approx(math.pi - theta, rel=1e-12)   # documented failure


def _fd_gradient(f, x, h=1e-6):
    g = np.zeros(3)
    for i in range(3):
        e = np.zeros(3)
        e[i] = h
        g[i] = (f(x + e) - f(x - e)) / (2 * h)
    return g - np.dot(g, x) * x          # tangent part


@pytest.mark.parametrize("b", [B, _unit([-1.0, 0.5, 0.2]), _unit([-1.0, 1e-3, 2e-3])])
def test_length_gradient_routes_match_finite_differences(b):
    a = A if b is B else EX
    ref = _fd_gradient(lambda x: math.atan2(np.linalg.norm(np.cross(x, b)), np.dot(x, b)), a)
    for f in (geo.geodesic_length_gradient, geo.geodesic_length_gradient_robust, geo.geodesic_length_gradient_acos):
        g = f(a, b)
        assert np.allclose(g, ref, atol=1e-7), f.__name__
        assert abs(np.dot(g, a)) < 1e-12
    # coincident points: the zero subgradient from the default and the robust form
    assert np.array_equal(geo.geodesic_length_gradient(A, A), np.zeros(3))
    assert np.array_equal(geo.geodesic_length_gradient_robust(A, A), np.zeros(3))


def test_solid_angle_gradients_match_finite_differences():
    ref = _fd_gradient(lambda x: _solid_angle_reference(A, x, C), B)
    for f in (geo.solid_angle_gradient, geo.solid_angle_gradient_difference):
        g = geo.tangent_project(B, f(A, B, C))
        assert np.allclose(g, ref, atol=1e-7), f.__name__
    # the unprojected gradients agree with each other everywhere, not only in the tangent plane
    assert np.allclose(geo.solid_angle_gradient(A, B, C), geo.solid_angle_gradient_difference(A, B, C), atol=1e-14)


def test_edge_area_gradient_known_answer():
    # b x d / (1 + b.d) = tan(theta / 2) n: for the octant edge x -> y, tan(pi/4) z
    assert np.allclose(geo.edge_area_gradient(EX, EY), EZ, atol=1e-15)
    assert np.allclose(geo.edge_area_gradient(EY, EX), -EZ, atol=1e-15)
    theta = math.acos(np.dot(A, B))
    g = geo.edge_area_gradient(A, B)
    assert np.linalg.norm(g) == pytest.approx(math.tan(theta / 2), rel=1e-12)
    assert np.allclose(g / np.linalg.norm(g), _unit(np.cross(A, B)), atol=1e-14)


def test_polygon_functions_radius_default_and_scaling():
    verts = np.stack([EX, EY, EZ])
    assert geo.polygon_area(verts) == pytest.approx(math.pi / 2, rel=1e-14)
    assert geo.polygon_area(verts, radius=2.0) == pytest.approx(2 * math.pi, rel=1e-14)
    assert geo.polygon_perimeter(verts) == pytest.approx(3 * math.pi / 2, rel=1e-14)
    assert geo.polygon_perimeter(verts, radius=2.0) == pytest.approx(3 * math.pi, rel=1e-14)
    quad = np.stack([_unit([1, 0, 1]), _unit([0, 1, 1]), _unit([-1, 0, 1]), _unit([0, -1, 1])])
    g1, g2 = geo.polygon_area_gradient(quad), geo.polygon_area_gradient(quad, radius=2.0)
    assert np.allclose(g2, 4 * g1, rtol=1e-14, atol=0)
    p1, p2 = geo.polygon_perimeter_gradient(quad), geo.polygon_perimeter_gradient(quad, radius=2.0)
    assert np.allclose(p2, 2 * p1, rtol=1e-14, atol=0)
    # finite differences of area and perimeter at one vertex
    for k in range(4):
        def area(x, k=k):
            q = quad.copy()
            q[k] = x
            return geo.polygon_area(q)

        def perim(x, k=k):
            q = quad.copy()
            q[k] = x
            return geo.polygon_perimeter(q)
        assert np.allclose(g1[k], _fd_gradient(area, quad[k]), atol=1e-8)
        assert np.allclose(p1[k], _fd_gradient(perim, quad[k]), atol=1e-8)


def test_regular_polygon_known_answers():
    # the octant triangle: 3 sides, circumradius acos(1 / sqrt 3), side pi/2, area pi/2
    verts, side, perim, area = geo.regular_polygon(3, math.acos(1 / math.sqrt(3)))
    assert side == pytest.approx(math.pi / 2, rel=1e-14)
    assert perim == pytest.approx(3 * math.pi / 2, rel=1e-14)
    assert area == pytest.approx(math.pi / 2, rel=1e-14)
    assert np.allclose(np.linalg.norm(verts, axis=1), 1.0)
    assert geo.polygon_area(verts) == pytest.approx(area, rel=1e-13)
    verts, side2, perim2, area2 = geo.regular_polygon(3, math.acos(1 / math.sqrt(3)), radius=2.0)
    assert np.allclose(np.linalg.norm(verts, axis=1), 2.0)
    assert side2 == pytest.approx(2 * side) and perim2 == pytest.approx(2 * perim) and area2 == pytest.approx(4 * area)
    # a hemisphere-sized square: circumradius pi/2 gives the equator, area 2 pi
    verts, side, perim, area = geo.regular_polygon(4, math.pi / 2)
    assert area == pytest.approx(2 * math.pi, rel=1e-14) and perim == pytest.approx(2 * math.pi, rel=1e-14)
    assert verts[1] == pytest.approx([0.0, 1.0, 0.0], abs=1e-15)     # counter-clockwise from +x


def test_normalize_and_tangent_project():
    v = np.array([[3.0, 0.0, 4.0], [0.0, -2.0, 0.0]])
    assert np.allclose(geo.normalize(v), [[0.6, 0.0, 0.8], [0.0, -1.0, 0.0]], atol=1e-16)
    t = geo.tangent_project(EZ, np.array([1.0, 2.0, 3.0]))
    assert np.array_equal(t, [1.0, 2.0, 0.0])


def test_clipped_routes_at_coincident_and_antipodal_points():
    # unit vectors whose float64 |a|^2 rounds above 1: acos and asin must clip, not return NaN
    rng = np.random.default_rng(0)
    v = geo.normalize(rng.normal(size=(1000, 3)))
    v = v[geo._dot(v, v) > 1]
    assert len(v) > 10
    assert np.array_equal(geo.geodesic_length(v, v, route="acos"), np.zeros(len(v)))
    assert np.allclose(geo.geodesic_length(v, -v, route="acos"), np.pi, rtol=0, atol=1e-7)
    assert np.all(np.isfinite(geo.geodesic_length(v, v, route="asin")))
    w = geo.normalize(v + 1e-3)
    assert np.all(geo.geodesic_length(v, w, route="asin") <= np.pi / 2)


def test_angles_of_triangles_on_one_great_circle_are_finite():
    # the law-of-cosines ratio rounds beyond -1 for about half of these: clipped, the angle is pi
    rng = np.random.default_rng(0)
    t = np.sort(rng.uniform(0.0, 2.5, size=(50, 3)), axis=1)
    circle = lambda x: np.stack([np.cos(x), np.sin(x), np.zeros_like(x)], axis=-1)
    a, middle, b = circle(t[:, 0]), circle(t[:, 1]), circle(t[:, 2])
    at_a, at_b, at_middle = geo.triangle_angles(a, b, middle)
    # acos near -1 turns a ratio error d into an angle error sqrt(2 d): 1e-5 allows d up to 5e-11
    assert np.all(np.isfinite(at_middle)) and np.allclose(at_middle, np.pi, atol=1e-5)
    assert np.all(np.isfinite(at_a)) and np.all(np.isfinite(at_b))
    assert np.all(np.isfinite(geo.solid_angle_girard(a, b, middle)))
