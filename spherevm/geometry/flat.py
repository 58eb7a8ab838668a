"""The flat-facet metric: straight chords and vector areas of polygons whose vertices lie on any
surface, and their gradients.

A cell is the closed polygon of its vertices ``x_0 .. x_{n-1}`` (points in space, not yet on any
particular surface). Its edges are straight chords, of length ``|x_{j+1} - x_j|``; its area is the
magnitude of its vector area

    a = 1/2 sum_j x_j x x_{j+1} = 1/2 sum_j (x_j - x_0) x (x_{j+1} - x_0),

signed by the side of the surface it faces: ``A = sign(a . n) |a|`` with ``n`` a reference normal
(the sum of the surface normals at the vertices). Why the vector area (and not a fan of triangles
about the cell's centre projected onto the surface):

* it is defined by the polygon alone, for any non-planar polygon (no centre to choose, no projection
  onto the surface), translation invariant, and smooth wherever ``a != 0``;
* its gradient needs no derivative of a projection: ``d(w . a)/dx_i = (x_{i+1} - x_{i-1}) x w / 2``,
  so on a surface given only by F and grad F the forces are exact (a projected centre's derivative
  would need the surface's second derivatives);
* for a planar polygon it is the polygon's area; for a cell of size h on a surface of curvature 1/R
  it is the area of the cell's projection onto its best plane, which differs from the curved
  patch's area by a relative O((h/R)^2), the order of the chords' own error (a fan about a centre
  on the surface is also O((h/R)^2), its constant about half as large: 1.9 times smaller on random
  tilings of the sphere, 1.8 for regular polygons).

The second form of ``a`` (differences about ``x_0``) is the one computed: small cells keep full
relative accuracy far from the origin. All functions broadcast over leading axes (last axis of
length 3) and work on NumPy and CuPy arrays alike.
"""
from __future__ import annotations

from ..device import array_module
from .sphere import _cross, _dot, _norm


def cross_rows(a, b):
    """``a x b`` of vectors stored component-first, ``(3, ...)`` (contiguous rows: faster than a last
    axis of length 3)."""
    return array_module(a, b).stack([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]])


def dot_rows(a, b):
    """``a . b`` of vectors stored component-first, ``(3, ...)`` -> ``(...)``."""
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


def vector_area(vertices):
    """Vector area ``(..., 3)`` of the closed polygons ``vertices`` ``(..., n, 3)``:
    ``1/2 sum_j (x_j - x_0) x (x_{j+1} - x_0)``."""
    r = vertices[..., 1:, :] - vertices[..., :1, :]
    return 0.5 * _cross(r[..., :-1, :], r[..., 1:, :]).sum(axis=-2)


def signed_area(vector, reference):
    """``|a|`` with the sign of ``a . reference`` (0 where they are perpendicular): the flat area of a
    polygon of vector area ``a``, positive when it runs counter-clockwise seen from the side
    ``reference`` points to."""
    return array_module(vector).sign(_dot(vector, reference)) * _norm(vector)


def perimeter(vertices):
    """Sum of the chords ``|x_{j+1} - x_j|`` of the closed polygons ``vertices`` ``(..., n, 3)``."""
    xp = array_module(vertices)
    return _norm(xp.roll(vertices, -1, axis=-2) - vertices).sum(axis=-1)


def vector_area_gradient(previous, following, w):
    """Gradient of ``w . a`` with respect to a polygon's vertex ``x_i``, given its neighbours along
    the polygon ``previous = x_{i-1}`` and ``following = x_{i+1}``: ``(x_{i+1} - x_{i-1}) x w / 2``
    (with ``w = a / A`` it is the gradient of the signed area ``A``)."""
    return 0.5 * _cross(following - previous, w)


def chord_gradient(edge):
    """Gradient of the chord length ``|x_n - x_v|`` with respect to ``x_v``, given ``edge = x_n -
    x_v``: ``-edge / |edge|`` (0 for a zero-length edge, the minimal-norm subgradient)."""
    xp = array_module(edge)
    length = _norm(edge)
    return -edge / xp.where(length > 0, length, 1.0)[..., None]
