"""Built-in updaters."""

__all__ = []
