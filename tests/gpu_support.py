"""Shared skip logic for GPU tests: they run only where CuPy sees a working NVIDIA GPU."""
import pytest

from spherevm.device import _cupy_or_none

HAS_GPU = _cupy_or_none() is not None
requires_gpu = pytest.mark.skipif(not HAS_GPU, reason="needs CuPy and a working NVIDIA GPU")
