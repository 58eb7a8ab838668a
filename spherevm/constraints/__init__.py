"""Constraint surfaces: they hold the vertices and own the metric (lengths, areas, gradients)."""
from .base import Constraint
from .bump import GaussianBump
from .plane import PeriodicPlane
from .sphere import FlatSphere, Sphere
from .torus import Torus



def surface_for_key(key: str) -> Constraint:
    """The surface a size given by its key alone stands for (``radius=``: a :class:`Sphere`,
    ``box=``: a :class:`PeriodicPlane`), as where a Trajectory is built from a radius or a box."""
    return {"radius": Sphere, "box": PeriodicPlane}[key]()


__all__ = ["Constraint", "FlatSphere", "GaussianBump", "PeriodicPlane", "Sphere", "Torus"]
