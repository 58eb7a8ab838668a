"""Analysis of states and trajectories: cell shapes, dynamics (MSD, Q_s, F_s, tau_alpha), rigidity, quantities against
the local Gaussian curvature.

The cell shape and centroid functions live in :mod:`spherevm.shapes`, the Recorder in
:mod:`spherevm.plugins.writers.recorder`; they are re-exported here for analysis scripts.
"""
from . import rigidity
from ..plugins.writers.recorder import Recorder, Recording, log_spaced_times
from ..shapes import (cell_centroids, cell_shapes, mean_shape_index, pentagon_perimeter,
                      pentagon_perimeter_at_curvature, polygon_perimeter_at_curvature, regular_polygon_perimeter,
                      shape_index)
from .curvature import Binned, binned_mean, cell_curvature, gaussian_curvature, torus_curvature_range
from ..trigger import OnTimesteps
from .dynamics import (ArrheniusFit, NoRelaxationWarning, TimeCorrelation, arrhenius_fit, msd,
                       self_intermediate_scattering, self_overlap, tau_alpha)
from .rigidity import classify, critical_perimeter, p0_star, smoothing_width, transition_density, zero_fraction
from .trajectory import Trajectory, remove_rigid_rotation

__all__ = ["ArrheniusFit", "Binned", "NoRelaxationWarning", "OnTimesteps", "Recorder", "Recording", "TimeCorrelation",
           "Trajectory", "arrhenius_fit", "binned_mean", "cell_centroids", "cell_shapes", "classify",
           "critical_perimeter", "p0_star", "rigidity", "smoothing_width", "transition_density", "zero_fraction",
           "log_spaced_times", "mean_shape_index", "msd", "cell_curvature", "gaussian_curvature", "pentagon_perimeter",
           "pentagon_perimeter_at_curvature", "polygon_perimeter_at_curvature", "regular_polygon_perimeter",
           "remove_rigid_rotation", "self_intermediate_scattering", "self_overlap", "shape_index", "tau_alpha",
           "torus_curvature_range"]
