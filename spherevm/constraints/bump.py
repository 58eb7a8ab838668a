"""A Gaussian bump on the periodic plane: a height field measured with the flat-facet metric."""
from __future__ import annotations

from functools import lru_cache

import numpy as np

from ..device import array_module
from .implicit import ImplicitSurface

#: the box's sides must be at least this many widths (the bump is flat to e^-4.5 = 1% of its height
#: at the box's edges)
MIN_BOX_WIDTHS = 6.0
#: quadrature of the area: grid steps per width, and the half-window (in widths) outside which the
#: surface is flat to rounding (e^-(12^2/2) = 5e-32)
STEPS_PER_WIDTH, WINDOW_WIDTHS = 4, 12.0


def _images(d, L, w, second=False):
    """``sum_m exp(-(d - m L)^2 / 2 w^2)`` over m = -1, 0, 1 and its first (and with ``second`` its
    second) derivative in ``d`` (``d`` the minimum image of the offset from the box's centre)."""
    xp = array_module(d)
    g, dg, d2g = 0.0, 0.0, 0.0
    for m in (-1, 0, 1):
        s = d - m * L
        e = xp.exp(-s * s / (2 * w * w))
        g, dg = g + e, dg - s / (w * w) * e
        if second:
            d2g = d2g + (s * s / w ** 4 - 1 / (w * w)) * e
    return (g, dg, d2g) if second else (g, dg)


def _offsets(x, y, Lx, Ly):
    """The minimum images of the offsets of (x, y) from the box's centre."""
    xp = array_module(x)
    dx, dy = x - 0.5 * Lx, y - 0.5 * Ly
    return dx - Lx * xp.rint(dx / Lx), dy - Ly * xp.rint(dy / Ly)


def _height(x, y, Lx, Ly, h, w):
    """The height and its two derivatives at (x, y)."""
    dx, dy = _offsets(x, y, Lx, Ly)
    gx, dgx = _images(dx, Lx, w)
    gy, dgy = _images(dy, Ly, w)
    return h * gx * gy, h * dgx * gy, h * gx * dgy


@lru_cache(maxsize=256)
def bump_area(Lx: float, Ly: float, h: float, w: float) -> float:
    """The area of the bump over its box: ``Lx Ly`` plus the integral of ``sqrt(1 + |grad z|^2) - 1``
    by the trapezoid rule over the window where it is not zero (the whole box if smaller), whose
    error falls as ``exp(-2 pi^2 STEPS_PER_WIDTH^2)``."""
    axes = []
    for L in (Lx, Ly):
        half = min(0.5 * L, WINDOW_WIDTHS * w)
        n = int(np.ceil(2 * half * STEPS_PER_WIDTH / w))
        axes.append((0.5 * L - half + np.arange(n) * (2 * half / n), 2 * half / n))
    (x, sx), (y, sy) = axes
    _, zx, zy = _height(x[:, None], y[None, :], Lx, Ly, h, w)
    excess = zx * zx + zy * zy
    return float(Lx * Ly + (excess / (1 + np.sqrt(1 + excess))).sum() * sx * sy)


class GaussianBump(ImplicitSurface):
    """The height field ``z = height exp(-|(x, y) - centre|^2 / (2 width^2))`` over a periodic box
    (Lx, Ly), the bump in the box's middle, summed over the nearest periodic images (smooth across
    the box's edges; it differs from the single Gaussian by less than ``height e^-4.5`` when the
    box is ``6 width`` wide, the smallest allowed). ``F = z - height(x, y)``; closest points by Newton
    iterations, the area by quadrature (:func:`bump_area`), Euler characteristic 0. Positions are
    stored with x, y wrapped into the box; edges are minimum images. The parameters ``(Lx, Ly,
    height, width)`` are per replica (``size``); the instance's are the shape a tiling starts from.

    Parameters
    ----------
    height : float
        Positive (a dimple is the bump seen from below).
    width : float
        Positive.
    box : float or (Lx, Ly), optional
        The periodic box, at least ``6 width`` in each direction (default ``10 width``)."""

    name = "gaussian_bump"
    size_names = ("Lx", "Ly", "height", "width")
    periodic = True
    euler_characteristic = 0
    cuda_file = "bump.cuh"

    def __init__(self, height: float = 1.0, width: float = 1.0, box=None):
        b = np.broadcast_to(np.asarray(10.0 * float(width) if box is None else box, dtype=np.float64).reshape(-1), (2,))
        self.height, self.width, self.box = float(height), float(width), (float(b[0]), float(b[1]))
        self.shape = tuple(self.check_size([b[0], b[1], height, width])[0])

    def check_parameters(self, Lx, Ly, h, w):
        for name, L in (("Lx", Lx), ("Ly", Ly)):
            bad = ~(np.asarray(L) >= MIN_BOX_WIDTHS * np.asarray(w))
            if bad.any():
                raise ValueError(f"the box's {name} must be at least {MIN_BOX_WIDTHS:g} width = "
                                 f"{MIN_BOX_WIDTHS * np.asarray(w)[bad][0]:g} for the bump to be flat at its edges, "
                                 f"got {name}={np.asarray(L)[bad][0]:g}")

    def F(self, x, size):
        return x[..., 2] - _height(x[..., 0], x[..., 1], *self.parameters(size))[0]

    def grad_F(self, x, size):
        xp = array_module(x)
        _, zx, zy = _height(x[..., 0], x[..., 1], *self.parameters(size))
        return xp.stack([-zx, -zy, xp.ones_like(zx)], axis=-1)

    def hessian_F(self, x, size):
        """``-`` the height's second derivatives, in x and y (closed form)."""
        Lx, Ly, h, w = self.parameters(size)
        dx, dy = _offsets(x[..., 0], x[..., 1], Lx, Ly)
        gx, dgx, d2gx = _images(dx, Lx, w, second=True)
        gy, dgy, d2gy = _images(dy, Ly, w, second=True)
        out = array_module(x).zeros(x.shape + (3,))
        out[..., 0, 0], out[..., 1, 1] = -h * d2gx * gy, -h * gx * d2gy
        out[..., 0, 1] = out[..., 1, 0] = -h * dgx * dgy
        return out

    def area_density_bound(self, size):
        """An upper bound of the area per unit of box area, ``sqrt(1 + |grad z|^2)``: the steepest
        slope of the Gaussian, ``height e^-1/2 / width``, with 1% for the images."""
        return float(np.sqrt(1 + (1.01 * size[2] * np.exp(-0.5) / size[3]) ** 2))

    def length_scale(self, size):
        """``sqrt(Lx Ly)``, as on the periodic plane."""
        return array_module(size).sqrt(size[..., 0] * size[..., 1])

    def total_area_np(self, size):
        """The area per row of ``size`` (:func:`bump_area`)."""
        s = np.asarray(size, dtype=np.float64)
        return np.array([bump_area(*map(float, row)) for row in s.reshape(-1, 4)]).reshape(s.shape[:-1])
