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
    xp = array_module(a, b, c)
    num = _dot(a, _cross(b, c))
    den = 1.0 + _dot(a, b) + _dot(b, c) + _dot(c, a)
    g = den[..., None] * _cross(c, a) - num[..., None] * (a + c)
    return 2.0 * g / (num * num + den * den)[..., None]


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
