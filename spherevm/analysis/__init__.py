"""Analysis of states and trajectories."""
from .shapes import cell_shapes, mean_shape_index, pentagon_perimeter, regular_polygon_perimeter, shape_index

__all__ = ["cell_shapes", "mean_shape_index", "pentagon_perimeter", "regular_polygon_perimeter", "shape_index"]
