"""A surface plugin as a user writes one: z = A sin(2 pi x / Lx) over a periodic box (docs/surfaces.md).

Registered under the entry-point group ``spherevm.surfaces`` (``spherevm_sinusoid-0.1.dist-info``
here, what ``pip install`` of a package declaring it would leave)::

    [project.entry-points."spherevm.surfaces"]
    sinusoid = "spherevm_sinusoid:Sinusoid"
"""
import numpy as np
from scipy.special import ellipe

from spherevm.constraints import ImplicitSurface
from spherevm.device import array_module


class Sinusoid(ImplicitSurface):
    """``F = z - A sin(2 pi x / Lx)``: one period across a periodic box (Lx, Ly)."""

    name = "sinusoid"
    size_names = ("Lx", "Ly", "amplitude")   # per replica, all lengths
    periodic = True                          # the first two are the periodic box
    euler_characteristic = 0
    # F and grad F in CUDA (p: device_parameters, the box, the amplitude and the wavenumber 2 pi / Lx,
    # worked out once rather than divided in every evaluation): the same formulas on the GPU
    device_parameter_names = ("Lx", "Ly", "amplitude", "wavenumber")
    cuda_code = r"""
__device__ inline double F(vec3 x, const double* p) { return x.z - p[2] * sin(p[3] * x.x); }
__device__ inline vec3 grad_F(vec3 x, const double* p) { return v3(-p[2] * p[3] * cos(p[3] * x.x), 0.0, 1.0); }
"""

    def __init__(self, amplitude=1.0, box=10.0):
        lx, ly = np.broadcast_to(np.asarray(box, dtype=float).reshape(-1), (2,))
        self.amplitude, self.box = float(amplitude), (float(lx), float(ly))
        self.shape = tuple(self.check_size([lx, ly, amplitude])[0])

    def device_parameters(self, size):
        """``(Lx, Ly, amplitude, 2 pi / Lx)`` per replica: what the CUDA code reads as ``p``."""
        return np.column_stack([size, 2 * np.pi / size[:, 0]])

    def F(self, x, size):
        Lx, _, A = self.parameters(size)
        return x[..., 2] - A * array_module(x).sin(2 * np.pi * x[..., 0] / Lx)

    def grad_F(self, x, size):
        xp = array_module(x)
        Lx, _, A = self.parameters(size)
        slope = -A * (2 * np.pi / Lx) * xp.cos(2 * np.pi * x[..., 0] / Lx)
        return xp.stack([slope, xp.zeros_like(slope), xp.ones_like(slope)], axis=-1)

    def total_area_np(self, size):
        """``Lx Ly (2/pi) sqrt(1 + s^2) E(s^2 / (1 + s^2))``, ``s = 2 pi A / Lx`` (E: complete elliptic)."""
        Lx, Ly, A = np.moveaxis(np.asarray(size, dtype=float), -1, 0)
        s2 = (2 * np.pi * A / Lx) ** 2
        return Lx * Ly * (2 / np.pi) * np.sqrt(1 + s2) * ellipe(s2 / (1 + s2))

    def area_density_bound(self, size):
        """The largest area per unit of box area, ``sqrt(1 + s^2)`` (random tilings draw by it)."""
        return float(np.sqrt(1 + (2 * np.pi * size[2] / size[0]) ** 2))
