"""Built-in updaters."""
from .division import Division
from .extrusion import Extrusion
from .radius import RadiusSchedule
from .t1 import T1

__all__ = ["Division", "Extrusion", "RadiusSchedule", "T1"]
