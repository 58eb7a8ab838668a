"""Parameter checks shared by the library and the command line: each error names the parameter
and the allowed range. The ``spherevm`` command wraps these same functions as argparse types."""
from __future__ import annotations

import numpy as np


class ParameterError(ValueError):
    """A value outside its allowed range; ``allowed`` says what is (the CLI reports it per flag)."""

    def __init__(self, name, value, allowed: str):
        super().__init__(f"{name} must be {allowed}, got {value!r}")
        self.name, self.value, self.allowed = name, value, allowed


def integer(name, value, minimum: int = 0, maximum: int | None = None) -> int:
    """An integer in ``[minimum, maximum]`` (an integral float or NumPy integer is fine, a bool is not)."""
    try:
        ok = (int(value) == value and not isinstance(value, (bool, np.bool_)) and int(value) >= minimum
              and (maximum is None or int(value) <= maximum))
    except (TypeError, ValueError, OverflowError):
        ok = False
    if not ok:
        if maximum is not None:
            allowed = f"an integer in [{minimum}, {maximum}]"
        else:
            allowed = "a non-negative integer" if minimum == 0 else f"an integer >= {minimum}"
        raise ParameterError(name, value, allowed)
    return int(value)


def real(name, value, strict: bool = False) -> float:
    """A finite float >= 0, or > 0 with ``strict``."""
    try:
        v = float(value)
    except (TypeError, ValueError):
        v = float("nan")
    if not np.isfinite(v) or v < 0 or (strict and v == 0):
        raise ParameterError(name, value, "positive and finite" if strict else "a finite number >= 0")
    return v


def positive(name, value) -> float:
    """A finite float > 0."""
    return real(name, value, strict=True)


def non_negative(name, value, per_item: str = "a scalar or one value per replica"):
    """A finite array (scalar or 1-D) with every entry >= 0, else ValueError."""
    arr = np.asarray(value, dtype=np.float64)
    if arr.ndim > 1 or not np.all(np.isfinite(arr)) or np.any(arr < 0):
        raise ValueError(f"{name} must be finite and >= 0 ({per_item}), got {value!r}")
    return arr
