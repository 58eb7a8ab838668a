"""Analysis of states and trajectories: cell shapes, dynamics (MSD, Q_s, F_s, tau_alpha)."""
from .dynamics import (NoRelaxationWarning, TimeCorrelation, Trajectory, cell_centroids, log_spaced_times, msd,
                       remove_rigid_rotation, self_intermediate_scattering, self_overlap, tau_alpha)
from . import rigidity
from .recorder import OnTimesteps, Recorder
from .rigidity import classify, critical_perimeter, p0_star, smoothing_width, transition_density, zero_fraction
from .shapes import cell_shapes, mean_shape_index, pentagon_perimeter, regular_polygon_perimeter, shape_index

__all__ = ["NoRelaxationWarning", "OnTimesteps", "Recorder", "TimeCorrelation", "Trajectory", "cell_centroids",
           "cell_shapes", "classify", "critical_perimeter", "p0_star", "rigidity", "smoothing_width",
           "transition_density", "zero_fraction", "log_spaced_times", "mean_shape_index", "msd", "pentagon_perimeter",
           "regular_polygon_perimeter", "remove_rigid_rotation", "self_intermediate_scattering", "self_overlap",
           "shape_index", "tau_alpha"]
