"""spherevm: vertex models of confluent tissue on curved surfaces, on the CPU or an NVIDIA GPU."""
from . import analysis, constraints, device, geometry, gsdio, init, plugins, shapes, topology, trigger
from .simulation import Simulation
from .plugins.writers import write_gsd
from .state import State

__version__ = "0.1.0"

__all__ = ["Simulation", "State", "analysis", "constraints", "device", "geometry", "gsdio", "init", "plugins",
           "shapes", "topology", "trigger", "__version__"]
