"""GSD writer and reader (placeholder until the GSD module lands)."""
from ..base import Writer


class GSD(Writer):
    pass


def read_state(path, frame=-1, device=None):
    raise NotImplementedError
