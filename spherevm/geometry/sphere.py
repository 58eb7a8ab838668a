"""Geodesic lengths, spherical triangle and polygon areas, and their gradients.

All functions take unit vectors (last axis of length 3) and broadcast over leading axes; they work
on NumPy and CuPy arrays alike. Multiply lengths by R and areas by R^2 for a sphere of radius R.

The default routes are the well-conditioned ones (see docs/numerics.md):

* length ``theta = 2 atan2(|a - b|, |a + b|)``: the half-angle form, accurate to a few ulp from
  1e-9 R (where ``acos`` has lost half its digits) up to nearly antipodal points (where ``asin``
  fails);
* signed solid angle of a triangle ``Omega = 2 atan2(a.(b x c), 1 + a.b + b.c + c.a)``
  (Van Oosterom and Strackee), positive for counter-clockwise triangles seen from outside.
"""
from __future__ import annotations

import numpy as np

from ..device import array_module

LENGTH_ROUTES = ("default", "acos", "asin", "atan2")


def _dot(a, b):
    # explicit components: several times faster than a reduction over a length-3 axis
    return a[..., 0] * b[..., 0] + a[..., 1] * b[..., 1] + a[..., 2] * b[..., 2]


def _cross(a, b):
    xp = array_module(a, b)
    a0, a1, a2 = a[..., 0], a[..., 1], a[..., 2]
    b0, b1, b2 = b[..., 0], b[..., 1], b[..., 2]
    return xp.stack([a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0], axis=-1)


def _norm(a):
    xp = array_module(a)
    return xp.sqrt(_dot(a, a))


def normalize(x):
    """Unit vectors along ``x``."""
    return x / _norm(x)[..., None]


def geodesic_length(a, b, route: str = "default"):
    """Angle between unit vectors ``a`` and ``b`` (geodesic length on the unit sphere).

    ``route`` picks the formula: ``"default"`` (half-angle atan2, well conditioned everywhere),
    or the paper's three: ``"acos"`` (acos a.b: loses accuracy for short arcs), ``"asin"``
    (asin |a x b|: wrong beyond pi/2 and ill conditioned near it) and ``"atan2"``
    (atan2(|a x b|, a.b): well conditioned except that |a x b| cancels for very short arcs).
    """
    xp = array_module(a, b)
    if route == "default":
        return 2.0 * xp.arctan2(_norm(a - b), _norm(a + b))
    if route == "acos":
        return xp.arccos(xp.clip(_dot(a, b), -1.0, 1.0))
    if route == "asin":
        return xp.arcsin(xp.clip(_norm(_cross(a, b)), -1.0, 1.0))
    if route == "atan2":
        return xp.arctan2(_norm(_cross(a, b)), _dot(a, b))
    raise ValueError(f"route must be one of {LENGTH_ROUTES}, got {route!r}")


def geodesic_length_gradient(a, b):
    """Gradient of ``geodesic_length(a, b)`` with respect to ``a``, in the tangent plane at ``a``.

    It is ``-t/|t|`` with ``t = (b - a) - ((b - a).a) a``, the unit tangent at ``a`` pointing
    toward ``b``: built from ``b - a``, so it stays accurate for very short arcs. For coincident
    points (a zero-length edge) it returns 0, the minimal-norm subgradient.
    """
    xp = array_module(a, b)
    d = b - a
    t = d - _dot(d, a)[..., None] * a
    n = _norm(t)
    return -t / xp.where(n > 0, n, 1.0)[..., None]


def solid_angle(a, b, c):
    """Signed solid angle (area on the unit sphere) of the geodesic triangle (a, b, c)."""
    xp = array_module(a, b, c)
    num = _dot(a, _cross(b, c))
    den = 1.0 + _dot(a, b) + _dot(b, c) + _dot(c, a)
    return 2.0 * xp.arctan2(num, den)


def solid_angle_gradient(a, b, c):
    """Gradient of ``solid_angle(a, b, c)`` with respect to the middle vertex ``b``.

    ``2 (D (c x a) - N (a + c)) / (N^2 + D^2)``, not yet projected on the tangent plane at ``b``
    (apply ``(I - b b^T)`` for the surface gradient). Cyclic symmetry gives the other two slots:
    ``solid_angle(a, b, c) == solid_angle(b, c, a)``.
    """
    num = _dot(a, _cross(b, c))
    den = 1.0 + _dot(a, b) + _dot(b, c) + _dot(c, a)
    g = den[..., None] * _cross(c, a) - num[..., None] * (a + c)
    return 2.0 * g / (num * num + den * den)[..., None]


def edge_area_gradient(b, d):
    """``(b x d)/(1 + b.d) = tan(theta/2) n``: the area a polygon gains per unit tangent step of its
    vertex ``b``, through its edge to ``d``, is ``-edge_area_gradient(b, d)`` for a boundary
    running ``b -> d`` (counter-clockwise) and ``+edge_area_gradient(b, d)`` for ``d -> b``.

    Moving the end b of an arc of angle theta by a tangent step s sweeps the thin triangle
    ``tan(theta/2) (s . n)``, n the arc's unit normal at b. So a polygon's area gradient at b is
    ``edge_area_gradient(b, prev) - edge_area_gradient(b, next)``, with no fan apex; it is tangent
    at b. ``b x d`` is taken as ``(b - d) x b``, accurate for short edges.
    """
    return _cross(b - d, b) / (1.0 + _dot(b, d))[..., None]


def triangle_area(a, b, c, radius=1.0):
    """Signed area of the geodesic triangle (a, b, c) on a sphere of the given radius."""
    return radius * radius * solid_angle(a, b, c)


def polygon_area(vertices, radius=1.0):
    """Signed area of one geodesic polygon given by its unit-vector vertices ``(n, 3)``.

    A fan of triangles about the normalised vertex centroid; the result does not depend on the
    apex (as long as no edge passes through the antipode of the apex).
    """
    xp = array_module(vertices)
    apex = normalize(vertices.sum(axis=0))
    nxt = xp.roll(vertices, -1, axis=0)
    return radius * radius * solid_angle(apex[None, :], vertices, nxt).sum()


def regular_polygon(n_sides: int, circumradius_angle: float, radius: float = 1.0):
    """Analytic regular spherical polygon: vertices, side length, perimeter and area.

    The polygon is centred on +z with vertices at polar angle ``circumradius_angle``, listed
    counter-clockwise seen from outside. Returns ``(vertices (n, 3), side, perimeter, area)``
    from spherical trigonometry (Napier's rules), independent of the numerical routes above.
    """
    n = int(n_sides)
    rho = float(circumradius_angle)
    phi = 2.0 * np.pi * np.arange(n) / n
    verts = np.stack([np.sin(rho) * np.cos(phi), np.sin(rho) * np.sin(phi),
                      np.full(n, np.cos(rho))], axis=1)
    # right triangle centre-vertex-edge midpoint: sin(s/2) = sin(rho) sin(pi/n)
    half_side = np.arcsin(np.sin(rho) * np.sin(np.pi / n))
    # tan(alpha/2) = 1 / (cos(rho) tan(pi/n)) gives the interior angle alpha
    alpha = 2.0 * np.arctan2(1.0, np.cos(rho) * np.tan(np.pi / n))
    area = radius * radius * (n * alpha - (n - 2) * np.pi)
    side = 2.0 * half_side * radius
    return radius * verts, side, n * side, area


# ---------------------------------------------------------------------------------------------
# Alternative routes (documented in docs/numerics.md and measured by benchmarks/numerics_table.py).
# The routes above are the ones the constraints and kernels use; the functions below are the
# paper's textbook formulas, kept to show where they lose accuracy, and "difference" forms that
# keep full relative accuracy where the defaults keep only absolute accuracy.
# ---------------------------------------------------------------------------------------------

def geodesic_length_difference(a, b):
    """``atan2(|a x (b - a)|, a.b)``: the paper's atan2 route with the cross product taken of ``b - a``.

    ``a x (b - a) == a x b`` exactly, but ``b - a`` is computed exactly for nearby points
    (Sterbenz), so the cross product does not cancel: a few ulp relative error at every angle.
    Unlike the default half-angle form it does not assume ``|a| == |b| == 1`` (the result is the
    angle between the two directions), so it stays accurate below 1e-9 where the float64 norms of
    the inputs (off 1 by ~1e-16) enter the chord ``|a - b|``.
    """
    xp = array_module(a, b)
    return xp.arctan2(_norm(_cross(a, b - a)), _dot(a, b))


def geodesic_length_gradient_acos(a, b):
    """The naive gradient of ``acos(a.b)`` with respect to ``a``, projected on the tangent plane.

    ``-(b - (a.b) a) / sqrt(1 - (a.b)^2)``: the Cartesian form of the paper's spherical-coordinate
    expressions for ``d_a``. Both the numerator and ``1 - (a.b)^2`` cancel for short arcs (and for
    nearly antipodal points); it returns NaN once ``a.b`` rounds to +-1 (arcs below ~1e-8).
    Kept only as the reference for what the default avoids.
    """
    xp = array_module(a, b)
    c = _dot(a, b)
    t = b - c[..., None] * a
    return -t / xp.sqrt(1.0 - c * c)[..., None]


def geodesic_length_gradient_robust(a, b):
    """Like :func:`geodesic_length_gradient`, also accurate for nearly antipodal points.

    The tangent toward ``b`` is built from ``b - a`` when ``a.b >= 0`` (as the default does) and
    from ``b + a`` otherwise: ``b + a`` is exact near the antipode, where ``b - a ~ -2a`` leaves a
    tangent of size ``pi - theta`` after cancelling against its radial part. Coincident points give
    0 (the minimal-norm subgradient), exactly antipodal points give an arbitrary unit tangent or 0.
    """
    xp = array_module(a, b)
    near = (_dot(a, b) >= 0)[..., None]
    d = xp.where(near, b - a, b + a)
    t = d - _dot(d, a)[..., None] * a
    n = _norm(t)
    return -t / xp.where(n > 0, n, 1.0)[..., None]


def _triple_difference(a, b, c):
    # a.(b x c) == a.((b - a) x (c - a)): no cancellation for small triangles
    return _dot(a, _cross(b - a, c - a))


def triangle_angles(a, b, c):
    """Interior angles at ``a``, ``b``, ``c`` of the geodesic triangle, by the spherical law of cosines.

    ``alpha = acos((cos A - cos B cos C) / (sin B sin C))`` with ``A = |bc|``, ``B = |ca|``,
    ``C = |ab|`` (the paper's formulas; sides from the default length route). Ill conditioned for
    small triangles: the numerator is a difference of numbers near 1 whose result is of order the
    squared side lengths.
    """
    xp = array_module(a, b, c)
    A = geodesic_length(b, c)
    B = geodesic_length(c, a)
    C = geodesic_length(a, b)
    cA, cB, cC = xp.cos(A), xp.cos(B), xp.cos(C)
    sA, sB, sC = xp.sin(A), xp.sin(B), xp.sin(C)

    def angle(num, den):
        return xp.arccos(xp.clip(num / den, -1.0, 1.0))

    return (angle(cA - cB * cC, sB * sC), angle(cB - cC * cA, sC * sA), angle(cC - cA * cB, sA * sB))


def solid_angle_girard(a, b, c):
    """Signed solid angle by Girard's theorem: angle excess ``alpha + beta + gamma - pi``.

    Angles from :func:`triangle_angles`; the sign is that of ``a.(b x c)`` (so it agrees with
    :func:`solid_angle`). Loses all accuracy for small triangles: absolute error ~ eps / (side)^2.
    """
    xp = array_module(a, b, c)
    al, be, ga = triangle_angles(a, b, c)
    return xp.sign(_triple_difference(a, b, c)) * (al + be + ga - np.pi)


def solid_angle_lhuilier(a, b, c):
    """Signed solid angle by L'Huilier's theorem from the three side lengths (default route).

    ``tan(E/4) = sqrt(tan(s/2) tan((s-A)/2) tan((s-B)/2) tan((s-C)/2))``, ``s`` the half perimeter;
    the sign is that of ``a.(b x c)``. Accurate for small well-shaped triangles; ``s - A`` cancels
    for needle-like triangles and for triangles whose vertices lie near one great circle (area near
    2 pi).
    """
    xp = array_module(a, b, c)
    A = geodesic_length(b, c)
    B = geodesic_length(c, a)
    C = geodesic_length(a, b)
    s = 0.5 * (A + B + C)
    t = xp.tan(0.5 * s) * xp.tan(0.5 * (s - A)) * xp.tan(0.5 * (s - B)) * xp.tan(0.5 * (s - C))
    return xp.sign(_triple_difference(a, b, c)) * 4.0 * xp.arctan(xp.sqrt(xp.maximum(t, 0.0)))


def solid_angle_difference(a, b, c):
    """:func:`solid_angle` with the numerator taken as ``a.((b - a) x (c - a))``.

    Same value, but full relative accuracy for tiny triangles, where the default
    ``a.(b x c)`` keeps only absolute accuracy ~eps (relative eps / Omega).
    """
    xp = array_module(a, b, c)
    num = _triple_difference(a, b, c)
    den = 1.0 + _dot(a, b) + _dot(b, c) + _dot(c, a)
    return 2.0 * xp.arctan2(num, den)


def solid_angle_gradient_difference(a, b, c):
    """:func:`solid_angle_gradient` built from differences (full relative accuracy for tiny triangles).

    Uses ``c x a == b x (a - c) + (c - b) x (a - b)`` and the difference numerator; like the default,
    the result is not yet projected on the tangent plane at ``b``.
    """
    num = _triple_difference(a, b, c)
    den = 1.0 + _dot(a, b) + _dot(b, c) + _dot(c, a)
    ca = _cross(b, a - c) + _cross(c - b, a - b)
    g = den[..., None] * ca - num[..., None] * (a + c)
    return 2.0 * g / (num * num + den * den)[..., None]


def tangent_project(x, v):
    """``v - (x.v) x``: the component of ``v`` in the tangent plane at the unit vector ``x``."""
    return v - _dot(x, v)[..., None] * x


def polygon_perimeter(vertices, radius=1.0):
    """Perimeter of one geodesic polygon given by its unit-vertex list ``(n, 3)`` (default route)."""
    xp = array_module(vertices)
    nxt = xp.roll(vertices, -1, axis=0)
    return radius * geodesic_length(vertices, nxt).sum()


def polygon_perimeter_gradient(vertices, radius=1.0):
    """Gradient ``(n, 3)`` of :func:`polygon_perimeter` with respect to each unit vertex.

    In the tangent plane at each vertex. For positions ``x = R u`` divide by ``R``.
    """
    xp = array_module(vertices)
    nxt = xp.roll(vertices, -1, axis=0)
    prv = xp.roll(vertices, 1, axis=0)
    return radius * (geodesic_length_gradient(vertices, nxt) + geodesic_length_gradient(vertices, prv))


def polygon_area_gradient(vertices, radius=1.0):
    """Gradient ``(n, 3)`` of :func:`polygon_area` with respect to each unit vertex.

    The fan apex (the normalised centroid) is held fixed: the area does not depend on the apex, so
    the chain-rule term through the apex vanishes and this is the full gradient. Projected on the
    tangent plane at each vertex; for positions ``x = R u`` divide by ``R``.
    """
    xp = array_module(vertices)
    apex = xp.broadcast_to(normalize(vertices.sum(axis=0)), vertices.shape)
    nxt = xp.roll(vertices, -1, axis=0)
    prv = xp.roll(vertices, 1, axis=0)
    # triangles (apex, v, next) and (apex, prev, v) == (prev, v, apex): v in the middle slot
    g = solid_angle_gradient(apex, vertices, nxt) + solid_angle_gradient(prv, vertices, apex)
    return radius * radius * tangent_project(vertices, g)
