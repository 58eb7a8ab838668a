"""The ellipsoid x^2/a^2 + y^2/b^2 + z^2/c^2 = 1: Newton projections, area by quadrature."""
from __future__ import annotations

from functools import lru_cache

import numpy as np

from ..device import array_module
from .implicit import ImplicitSurface, rejection

#: Gauss-Legendre nodes in cos(theta) and equal steps in phi of the area quadrature (the integrand is
#: smooth, and periodic in phi: both converge spectrally; 1e-15 relative at axis ratios up to 10)
QUADRATURE_NODES = (256, 512)


def area_element(u, phi, a, b, c):
    """The ellipsoid's area per ``du dphi`` at ``(a sqrt(1-u^2) cos phi, b sqrt(1-u^2) sin phi, c u)``:
    ``sqrt(a^2 b^2 u^2 + c^2 (1 - u^2) (b^2 cos^2 phi + a^2 sin^2 phi))``."""
    return np.sqrt((a * b * u) ** 2 + c * c * (1 - u * u) * ((b * np.cos(phi)) ** 2 + (a * np.sin(phi)) ** 2))


@lru_cache(maxsize=256)
def ellipsoid_area(a: float, b: float, c: float) -> float:
    """The area of the ellipsoid of semi-axes a, b, c by quadrature (Gauss-Legendre in ``u = cos
    theta``, the trapezoid rule in phi)."""
    nu, nphi = QUADRATURE_NODES
    u, w = np.polynomial.legendre.leggauss(nu)
    phi = np.arange(nphi) * (2 * np.pi / nphi)
    return float((w[:, None] * area_element(u[:, None], phi[None], a, b, c)).sum() * (2 * np.pi / nphi))


class Ellipsoid(ImplicitSurface):
    """The ellipsoid of semi-axes a, b, c along x, y, z: ``F = x^2/a^2 + y^2/b^2 + z^2/c^2 - 1``.
    Closest points by Newton iterations (:class:`ImplicitSurface`), the area by quadrature
    (:func:`ellipsoid_area`), Euler characteristic 2. (a, b, c) are per replica (``size``); the
    instance's values are the shape a tiling starts from.

    Parameters
    ----------
    a, b, c : float
        Positive semi-axes."""

    name = "ellipsoid"
    size_names = ("a", "b", "c")
    euler_characteristic = 2
    cuda_file = "ellipsoid.cuh"
    device_parameter_names = ("inv_a2", "inv_b2", "inv_c2")

    def __init__(self, a: float = 1.0, b: float = 1.0, c: float = 1.0):
        self.shape = tuple(self.check_size([a, b, c])[0])
        self.a, self.b, self.c = self.shape

    def device_parameters(self, size):
        """``(1/a^2, 1/b^2, 1/c^2)`` per replica: F and grad F in the CUDA code without a division."""
        return 1.0 / np.asarray(size, dtype=np.float64) ** 2

    @property
    def rigid_motions(self):
        """Those of its shape: every rotation when a = b = c, those about z when a = b, else none
        (a tissue of a general ellipsoid has no rigid motion)."""
        a, b, c = self.shape
        return ("rotations",) if a == b == c else ("z-rotations",) if a == b else ()

    def F(self, x, size):
        a, b, c = self.parameters(size)
        return (x[..., 0] / a) ** 2 + (x[..., 1] / b) ** 2 + (x[..., 2] / c) ** 2 - 1.0

    def grad_F(self, x, size):
        return 2.0 * x / size ** 2

    def tiling_points(self, rng, n, size):
        """``(u, phi)`` = (cos theta, phi) uniform, kept with probability :func:`area_element` over its
        largest value ``max(a b, c max(a, b))``: uniform by area. No plane (the hull of the points'
        directions is triangulated)."""
        a, b, c = size
        bound = max(a * b, c * max(a, b))
        u, phi = rejection(rng, n, lambda m: np.stack([2 * rng.random(m) - 1, 2 * np.pi * rng.random(m)], axis=1),
                           lambda s: area_element(s[:, 0], s[:, 1], a, b, c) / bound).T
        s = np.sqrt(1 - u * u)
        return np.stack([a * s * np.cos(phi), b * s * np.sin(phi), c * u], axis=1), None, None

    def hessian_F(self, x, size):
        """``diag(2/a^2, 2/b^2, 2/c^2)``."""
        return array_module(x).broadcast_to(2.0 / size[..., None, :] ** 2 * array_module(x).eye(3),
                                            x.shape + (3,))

    def total_area_np(self, size):
        """The area per row of ``size`` (:func:`ellipsoid_area`)."""
        s = np.asarray(size, dtype=np.float64)
        flat = s.reshape(-1, 3)
        return np.array([ellipsoid_area(*map(float, row)) for row in flat]).reshape(s.shape[:-1])
