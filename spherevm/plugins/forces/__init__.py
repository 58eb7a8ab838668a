"""Built-in forces."""
from .vertex_model import VertexModel

__all__ = ["VertexModel"]
