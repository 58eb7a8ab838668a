"""An implicit surface on the GPU: the CUDA code of its F and grad F (a class's ``cuda_code`` or
``cuda_file``) wrapped into a shape struct for ``Implicit<Shape>`` of constraints/implicit.cuh (the
flat-facet metric, the closest-point projection and T1's geometry, written once for every implicit
surface), and the size table the kernels take.

The code defines, in a namespace of its own, ``__device__ double F(vec3 x, const double* p)`` and
``__device__ vec3 grad_F(vec3 x, const double* p)`` (``p``: the replica's parameters in the order of
``size_names``, or the values ``device_parameters`` derives from them, named by
``device_parameter_names``; ``vec3``, ``v3``, ``dot3``, ``cross3`` and CUDA's math functions are
available) and, where the class sets ``cuda_projection = True``, ``__device__ vec3 project(vec3 x,
const double* p)``, a closed-form closest point (else Newton iterations as
ImplicitSurface.project_normal).
"""
from __future__ import annotations

import inspect
from pathlib import Path

import numpy as np

from .base import DeviceSurface

_BUILT = {}
#: no contracted multiply-adds: every operation rounded as written, so a function gives the same bits
#: wherever it is inlined (the general kernels and the fused small-tissue steps), whoever wrote it
FMAD = ("--fmad=false",)


def shape_code(cls):
    """The CUDA code of ``cls``'s F and grad F: ``cuda_code``, else the text of ``cuda_file`` (a path,
    relative to the folder of the module defining the class), else None."""
    if cls.cuda_code is not None:
        return cls.cuda_code
    if cls.cuda_file is not None:
        path = Path(cls.cuda_file)
        return (path if path.is_absolute() else Path(inspect.getfile(cls)).parent / path).read_text()
    return None


def device_surface(surface) -> DeviceSurface:
    """``surface``'s :class:`DeviceSurface` (built once per class): its code in namespace ``svm_<Name>``,
    the struct ``<Name>Shape`` forwarding to it, compiled as ``Implicit<<Name>Shape>``. ValueError,
    saying what to add, if the class gives no CUDA code."""
    cls = type(surface)
    if cls not in _BUILT:
        code, name = shape_code(cls), cls.__name__
        if code is None:
            raise ValueError(f"{name} has no CUDA code to run on the GPU: give the class cuda_code (a string) or "
                             f"cuda_file (a .cuh path) defining __device__ double F(vec3 x, const double* p) and "
                             f"__device__ vec3 grad_F(vec3 x, const double* p) (docs/surfaces.md, 'On the GPU'), "
                             f"or use device='cpu'")
        project = (f"\n    __device__ static vec3 project(vec3 x, const double* p) {{ return svm_{name}::project(x, p); }}"
                   if cls.cuda_projection else "")
        source = (f'#include "constraints/implicit.cuh"\nnamespace svm_{name} {{\n{code}\n}}\n'
                  f"struct {name}Shape {{\n"
                  f"    static constexpr int k = {len(cls.device_parameter_names or cls.size_names)};\n"
                  f"    static constexpr bool periodic = {'true' if cls.periodic else 'false'};\n"
                  f"    static constexpr bool projects = {'true' if cls.cuda_projection else 'false'};\n"
                  f"    __device__ static double F(vec3 x, const double* p) {{ return svm_{name}::F(x, p); }}\n"
                  f"    __device__ static vec3 grad_F(vec3 x, const double* p) {{ return svm_{name}::grad_F(x, p); }}"
                  f"{project}\n}};")
        _BUILT[cls] = DeviceSurface(source, f"Implicit<{name}Shape>", coef_width=4, options=FMAD)
    return _BUILT[cls]


def kernel_size(surface, state):
    """The size table of ``Implicit<Shape>::size``, on the State's device, kept until ``state.size`` is
    assigned again: per replica the device parameters (``surface.device_parameters``: by default the
    parameters), the length scale and half the area (``k + 2`` columns)."""
    entry = state.cached((surface, "kernel size"), lambda: [None, None])
    if entry[0] is not state.size:
        size = np.asarray(state.size_np(), dtype=np.float64).reshape(state.n_replicas, -1)
        device = np.asarray(surface.device_parameters(size), dtype=np.float64).reshape(state.n_replicas, -1)
        names = type(surface).device_parameter_names or surface.size_names
        if device.shape[1] != len(names):     # the CUDA code would read the wrong columns
            raise ValueError(f"{type(surface).__name__}.device_parameters gives {device.shape[1]} values a replica, "
                             f"its CUDA code reads {len(names)} ({', '.join(names)}): name them in "
                             "device_parameter_names")
        table = np.concatenate([device, np.asarray(surface.length_scale(size)).reshape(-1, 1),
                                0.5 * np.asarray(surface.total_area_np(size)).reshape(-1, 1)], axis=1)
        entry[:] = [state.size, state.device.asarray(np.ascontiguousarray(table))]
    return entry[1]
