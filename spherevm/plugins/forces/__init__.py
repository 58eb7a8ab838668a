"""Built-in forces."""
from .bending import Bending, cell_normals
from .vertex_model import VertexModel

__all__ = ["Bending", "VertexModel", "cell_normals"]
