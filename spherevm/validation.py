"""Parameter checks shared by the plugins: each error names the parameter and the allowed range."""
from __future__ import annotations

import numpy as np


def positive(name, value) -> float:
    """A positive finite float, else ValueError."""
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a positive finite number, got {value!r}") from None
    if not np.isfinite(v) or v <= 0:
        raise ValueError(f"{name} must be positive and finite, got {value!r}")
    return v


def non_negative(name, value, per_item: str = "a scalar or one value per replica"):
    """A finite array (scalar or 1-D) with every entry >= 0, else ValueError."""
    arr = np.asarray(value, dtype=np.float64)
    if arr.ndim > 1 or not np.all(np.isfinite(arr)) or np.any(arr < 0):
        raise ValueError(f"{name} must be finite and >= 0 ({per_item}), got {value!r}")
    return arr
