"""The parameter checks shared by the library and the command line."""
import math

import numpy as np
import pytest

from spherevm import validation


@pytest.mark.parametrize("value, minimum, expected", [(0, 0, 0), (4, 4, 4), (7.0, 1, 7), (np.int64(3), 1, 3)])
def test_integer_accepts(value, minimum, expected):
    got = validation.integer("n", value, minimum)
    assert got == expected and type(got) is int


@pytest.mark.parametrize("value, minimum, message", [
    (-1, 0, "n must be a non-negative integer, got -1"),
    (3, 4, "n must be an integer >= 4, got 3"),
    (1.5, 1, "n must be an integer >= 1, got 1.5"),
    (True, 0, "n must be a non-negative integer, got True"),
    ("5", 0, "n must be a non-negative integer, got '5'"),
    (None, 0, "n must be a non-negative integer, got None"),
    (math.inf, 0, "n must be a non-negative integer, got inf"),
    (math.nan, 0, "n must be a non-negative integer, got nan"),
])
def test_integer_rejects_naming_the_range(value, minimum, message):
    with pytest.raises(validation.ParameterError) as info:
        validation.integer("n", value, minimum)
    assert str(info.value) == message and isinstance(info.value, ValueError)


def test_real_and_positive():
    assert validation.real("kr", 0) == 0.0 and validation.real("kr", "2.5") == 2.5
    assert validation.positive("dt", 0.1) == 0.1
    for bad in (-1e-300, math.nan, math.inf, "x", None):
        with pytest.raises(ValueError, match=r"kr must be a finite number >= 0, got"):
            validation.real("kr", bad)
    for bad in (0, -1, math.nan, "x"):
        with pytest.raises(ValueError, match=r"dt must be positive and finite, got"):
            validation.positive("dt", bad)
    with pytest.raises(validation.ParameterError) as info:
        validation.real("dt", 0.0, strict=True)
    assert info.value.allowed == "positive and finite" and info.value.name == "dt"


def test_non_negative_arrays():
    assert np.array_equal(validation.non_negative("T", [0.0, 1.0]), [0.0, 1.0])
    with pytest.raises(ValueError, match=r"T must be finite and >= 0"):
        validation.non_negative("T", [[1.0]])
