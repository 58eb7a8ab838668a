"""Kernel arguments as C structs, defined once in Python.

A :class:`KernelStruct` lists a struct's fields with their C types. It writes the CUDA declaration
(:attr:`KernelStruct.cuda`, compiled into the kernels that take it) and packs values into a NumPy
record of the same layout (:meth:`KernelStruct.pack`), which CuPy passes to a kernel by value. So
a kernel's arguments are named, not placed by position, and the two sides cannot drift apart.
"""
from __future__ import annotations

import numpy as np

#: C types a field may have, and their NumPy types (every pointer is a 64-bit address)
C_TYPES = {"double": np.float64, "int": np.int32, "unsigned int": np.uint32, "long long": np.int64,
           "unsigned long long": np.uint64}


def _numpy_type(ctype: str):
    if ctype.endswith("*"):
        return np.uint64
    try:
        return C_TYPES[ctype]
    except KeyError:
        raise ValueError(f"a kernel struct field is a pointer or one of {sorted(C_TYPES)}, got {ctype!r}") from None


def address(value) -> int:
    """The device address of a CuPy array (0 for None)."""
    return 0 if value is None else int(value.data.ptr)


class KernelStruct:
    """A C struct of kernel arguments.

    Parameters
    ----------
    name : str
        The struct's C name.
    fields : sequence of (str, str)
        ``(field name, C type)`` in order; a C type is a pointer (``"const double*"``) or one of
        :data:`C_TYPES`.
    """

    def __init__(self, name: str, fields):
        self.name = name
        self.fields = tuple(fields)
        self.dtype = np.dtype([(f, _numpy_type(t)) for f, t in self.fields], align=True)

    @property
    def cuda(self) -> str:
        """The C declaration of the struct."""
        body = "".join(f"    {ctype} {field};\n" for field, ctype in self.fields)
        return f"struct {self.name} {{\n{body}}};\n"

    def pack(self, **values) -> np.void:
        """A record of the struct's layout holding ``values`` (CuPy arrays for pointers, or None).

        Parameters
        ----------
        **values
            One value per field, by name.

        Returns
        -------
        numpy.void
            The record, which CuPy passes to a kernel by value.

        Raises
        ------
        ValueError
            If a field is missing or unknown.
        """
        if len(values) != len(self.fields) or any(f not in values for f, _ in self.fields):
            names = {f for f, _ in self.fields}
            raise ValueError(f"{self.name}: missing fields {sorted(names - set(values))}, unknown fields "
                             f"{sorted(set(values) - names)}")
        row = tuple(address(values[f]) if t.endswith("*") else values[f] for f, t in self.fields)
        return np.array(row, dtype=self.dtype)[()]
