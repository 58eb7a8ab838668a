"""Metric primitives of the constraint surfaces (NumPy; the CUDA headers carry the same formulas)."""
from .sphere import (LENGTH_ROUTES, edge_area_gradient, geodesic_length, geodesic_length_gradient, normalize,
                     polygon_area, regular_polygon, solid_angle, solid_angle_gradient, triangle_area)

__all__ = ["LENGTH_ROUTES", "edge_area_gradient", "geodesic_length", "geodesic_length_gradient", "normalize",
           "polygon_area", "regular_polygon", "solid_angle", "solid_angle_gradient", "triangle_area"]
