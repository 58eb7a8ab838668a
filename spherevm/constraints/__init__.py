"""Constraint surfaces: they hold the vertices and own the metric (lengths, areas, gradients)."""
from .base import Constraint
from .bump import GaussianBump
from .ellipsoid import Ellipsoid
from .implicit import ImplicitSurface
from .plane import PeriodicPlane
from .sphere import FlatSphere, Sphere
from .torus import Torus

__all__ = ["Constraint", "Ellipsoid", "FlatSphere", "GaussianBump", "ImplicitSurface", "PeriodicPlane", "Sphere",
           "Torus"]
