"""Gaussian bump on a plane: parameters are validated; nothing else is implemented yet."""
from __future__ import annotations

import numpy as np

from .base import Constraint


class GaussianBump(Constraint):
    """Height field ``z = height * exp(-(x^2 + y^2) / (2 width^2))`` over a square periodic plane.

    ``box`` is the side of the periodic square; the bump must fit inside it (``box > 6 width``) so
    that it is flat at the boundary. Only the normal is implemented; the projection onto the
    surface, the metric and planar periodic tilings are not yet and raise NotImplementedError.
    """

    name = "gaussian_bump"

    def __init__(self, height: float, width: float, box: float):
        h, w, L = float(height), float(width), float(box)
        if not np.isfinite(h):
            raise ValueError(f"height must be finite, got {height}")
        if not np.isfinite(w) or w <= 0:
            raise ValueError(f"width must be positive and finite, got {width}")
        if not np.isfinite(L) or L <= 6 * w:
            raise ValueError(f"box must be finite and larger than 6 * width = {6 * w}, got {box}")
        self.height, self.width, self.box = h, w, L

    def normal(self, x):
        from ..device import array_module
        xp = array_module(x)
        g = self.height * xp.exp(-(x[..., 0] ** 2 + x[..., 1] ** 2) / (2 * self.width ** 2))
        n = xp.stack([g * x[..., 0] / self.width ** 2, g * x[..., 1] / self.width ** 2, xp.ones_like(g)], axis=-1)
        return n / xp.sqrt((n * n).sum(axis=-1))[..., None]

    def __repr__(self):
        return f"GaussianBump(height={self.height}, width={self.width}, box={self.box})"
