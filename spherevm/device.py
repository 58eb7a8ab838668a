"""Where the arrays live: the CPU (NumPy) or an NVIDIA GPU (CuPy).

A :class:`Device` is chosen once per simulation; every array of a State lives on it and every
operation takes its array module from it (``device.xp``). The NumPy path is the reference: it runs
on any machine and defines the numbers that GPU kernels must reproduce.
"""
from __future__ import annotations

import numpy as np

DEVICE_NAMES = ("cpu", "gpu", "auto")


def _cupy_or_none():
    """Return the cupy module if it imports and sees a usable GPU, else None."""
    try:
        import cupy
        if cupy.cuda.runtime.getDeviceCount() < 1:
            return None
        cupy.zeros(1).sum()  # a real launch: fails early on a broken driver
        return cupy
    except Exception:
        return None


def gpu_available() -> bool:
    """Whether CuPy imports and sees a working NVIDIA GPU."""
    return _cupy_or_none() is not None


class Device:
    """An execution device: ``name`` is ``"cpu"`` or ``"gpu"``, ``xp`` its array module."""

    def __init__(self, name: str, xp):
        self.name = name
        self.xp = xp

    @property
    def is_gpu(self) -> bool:
        return self.name == "gpu"

    def __reduce__(self):
        # pickled by name (its array module cannot be): a CPU State travels to worker processes
        return resolve, (self.name,)

    def asarray(self, a, dtype=None):
        """Copy or move ``a`` onto this device."""
        return self.xp.asarray(a, dtype=dtype)

    def to_numpy(self, a):
        """Return ``a`` as a NumPy array (a device-to-host copy on the GPU)."""
        if self.is_gpu and type(a).__module__.startswith("cupy"):
            return a.get()
        return np.asarray(a)

    def fit(self, buffer, data, dtype):
        """``(buffer, view)``: ``data`` (NumPy or on this device) copied into the first rows of
        ``buffer`` when they fit (same dtype and row shape), else into a new buffer; ``view`` is
        those rows, a contiguous array of ``data``'s shape. A new buffer has exactly the rows
        needed the first time (``buffer`` None, or another dtype or row shape) and at least twice the
        old capacity when only the length grew, so an
        array whose length changes now and then (a growing tissue) is reallocated O(log n) times.
        The view aliases the buffer: the next ``fit`` into it overwrites what it shows."""
        dtype = np.dtype(dtype)
        data = data if hasattr(data, "shape") else np.asarray(data)
        shape = tuple(data.shape)
        same_rows = buffer is not None and buffer.dtype == dtype and buffer.shape[1:] == shape[1:]
        if not same_rows or len(buffer) < shape[0]:
            # grow geometrically only a buffer of the same row shape (a new width starts afresh)
            rows = max(shape[0], 2 * len(buffer)) if same_rows else shape[0]
            buffer = self.xp.empty((rows,) + shape[1:], dtype=dtype)
        view = buffer[:shape[0]]
        if self.is_gpu and isinstance(data, np.ndarray):
            view.set(np.ascontiguousarray(data, dtype=dtype))      # host to device, no temporary
        else:
            view[...] = data
        return buffer, view

    def synchronize(self):
        if self.is_gpu:
            self.xp.cuda.get_current_stream().synchronize()

    def __repr__(self):
        return f"Device({self.name!r})"


CPU = Device("cpu", np)


def GPU() -> Device:
    """The current CUDA device through CuPy; raises RuntimeError if none is usable."""
    cp = _cupy_or_none()
    if cp is None:
        raise RuntimeError("device='gpu' needs CuPy and a working NVIDIA GPU; install the 'gpu' extra "
                           "(pip install 'spherevm[gpu]') or use device='cpu'")
    return Device("gpu", cp)


def resolve(device="auto") -> Device:
    """Turn ``"cpu"``, ``"gpu"``, ``"auto"`` or a Device into a Device.

    ``"auto"`` takes the GPU when CuPy sees one and falls back to the CPU otherwise.
    """
    if isinstance(device, Device):
        return device
    if not isinstance(device, str) or device.lower() not in DEVICE_NAMES:
        raise ValueError(f"device must be one of {DEVICE_NAMES} or a spherevm.device.Device, got {device!r}")
    name = device.lower()
    if name == "cpu":
        return CPU
    if name == "gpu":
        return GPU()
    cp = _cupy_or_none()
    return Device("gpu", cp) if cp is not None else CPU


def array_module(*arrays):
    """NumPy or CuPy, whichever owns the given arrays (NumPy if none is a CuPy array)."""
    for a in arrays:
        if type(a).__module__.startswith("cupy"):
            import cupy
            return cupy
    return np


def info() -> dict:
    """Versions and device facts, as printed by ``spherevm info``."""
    import platform
    import scipy
    out = {"python": platform.python_version(), "numpy": np.__version__, "scipy": scipy.__version__}
    try:
        import cupy
        out["cupy"] = cupy.__version__
        try:
            out["cuda_runtime"] = str(cupy.cuda.runtime.runtimeGetVersion())
            n = cupy.cuda.runtime.getDeviceCount()
            out["gpus"] = [cupy.cuda.runtime.getDeviceProperties(i)["name"].decode() for i in range(n)]
        except Exception as exc:  # CuPy present, driver or GPU missing
            out["gpu_error"] = str(exc).splitlines()[0]
    except ImportError:
        out["cupy"] = None
    out["gpu_usable"] = gpu_available()
    out["default_device"] = resolve("auto").name
    return out


def tune_allocator() -> bool:
    """Fixed malloc thresholds for the NumPy path (glibc only); True if they were set.

    glibc maps every allocation above its mmap threshold afresh (128 KiB at start, raised only when
    such a block is freed) and gives freed heap above its trim threshold back to the system, so
    the NumPy path, whose temporaries are 0.1 to 10 MB, can pay a page fault per 4 KiB of every
    temporary in every step, depending on what was allocated before (measured on a 2-core VM:
    the vertex model at 1,000 cells 0.6 or 1.3 ms; a cross product of (3, 3, 16384) vectors 0.3 or
    1.6 ms). Fixed thresholds (32 MiB, the largest glibc takes, and 256 MiB) keep freed memory for
    reuse. Called once when spherevm.device is imported; the environment variable
    ``SPHEREVM_MALLOC=system`` leaves the allocator alone. Numbers do not change, only time.
    """
    import ctypes
    import os
    import sys
    if os.environ.get("SPHEREVM_MALLOC", "") == "system" or not sys.platform.startswith("linux"):
        return False
    try:
        libc = ctypes.CDLL("libc.so.6")
        mallopt = libc.mallopt
    except (OSError, AttributeError):     # not glibc
        return False
    M_TRIM_THRESHOLD, M_MMAP_THRESHOLD = -1, -3
    return bool(mallopt(M_MMAP_THRESHOLD, 32 << 20)) and bool(mallopt(M_TRIM_THRESHOLD, 256 << 20))


ALLOCATOR_TUNED = tune_allocator()
_PACKAGE_DIR = __import__("pathlib").Path(__file__).resolve().parent
_MODULES = {}
BLOCK = 256


class CompiledModule:
    """A compiled cupy.RawModule whose kernels are looked up once: CuPy's ``get_function`` costs a
    few microseconds a call, which small tissues pay at every launch."""

    def __init__(self, module):
        self.module, self._functions = module, {}

    def get_function(self, name):
        function = self._functions.get(name)
        if function is None:
            function = self._functions[name] = self.module.get_function(name)
        return function


def load_module(cu_file, defines=(), prelude="", options=()):
    """Compile (once per process, set of ``defines``, prelude and options) the CUDA source ``cu_file``
    and return it as a :class:`CompiledModule`.

    ``cu_file`` is a path to a ``.cu`` file beside the plugin that owns it; it may include the
    package's headers (``geometry/surface.cuh``, ``device_common.cuh``). ``prelude``: text the
    source starts with (a surface's device code, spherevm.constraints.kernels.surface_kernels);
    ``defines``: macro names passed as ``-D``; ``options``: more compiler options. Kernels use the
    NumPy path's formulas; fused multiply-adds and rsqrt make them agree with it to rounding, not
    bitwise.
    """
    key = (str(cu_file), tuple(defines), prelude, tuple(options))
    if key not in _MODULES:
        code = __import__("pathlib").Path(cu_file).read_text()
        _MODULES[key] = _compile(prelude + code, defines, options)
    return _MODULES[key]


def load_source(code: str, defines=(), options=()):
    """Compile (once per process, source text, set of ``defines`` and options) generated CUDA source
    that may include the package's headers and ``.cu`` files, and return it as a :class:`CompiledModule`."""
    key = ("source", code, tuple(defines), tuple(options))
    if key not in _MODULES:
        _MODULES[key] = _compile(code, defines, options)
    return _MODULES[key]


def _compile(code, defines, options):
    import cupy
    options = ("-std=c++17", f"-I{_PACKAGE_DIR}") + tuple(f"-D{name}" for name in defines) + tuple(options)
    return CompiledModule(cupy.RawModule(code=code, options=options))


def launch(kernel, n, args, block=BLOCK):
    """Launch ``kernel`` with one thread per item over ``n`` items."""
    if n > 0:
        kernel(((n + block - 1) // block,), (block,), args)


def segment_sums(state, over: str, n_sums: int = 1):
    """The arguments (start, n_segments, scratch, count) of a kernel's per-replica sums over the
    State's ``over`` ("cells" or "vertices"), launched with :func:`launch` one thread per item
    (``device_common.cuh``: no floating-point atomics, so the sums have the same bits on every
    run). Kept with the State (a resize, which changes the offsets, clears it): the scratch is
    reused by every launch (they run one after another on the stream), and each launch leaves the
    ticket counters at zero."""
    def build():
        xp = state.device.xp
        start = state.cell_start if over == "cells" else state.vertex_start
        n_segments = len(start) - 1
        n_tiles = (int(start[-1]) + BLOCK - 1) // BLOCK
        return (xp.asarray(start.astype(np.int32)), np.int32(n_segments), xp.empty(n_sums * (n_tiles + n_segments)),
                xp.zeros(n_segments, dtype=np.uint32))
    return state.cached((segment_sums, over, n_sums), build)


_ORDERED_BINCOUNT = r"""
extern "C" __global__ void ordered_bincount(const long long* order, const long long* start, const double* w,
                                            long long n_bins, double* out)
{
    long long b = (long long)blockIdx.x * blockDim.x + threadIdx.x;
    if (b >= n_bins) return;
    double s = 0.0;
    for (long long j = start[b]; j < start[b + 1]; ++j) s += w[order[j]];
    out[b] = s;
}
"""


def weighted_bincount(index, weights, minlength):
    """``numpy.bincount(index, weights, minlength)`` on either device (``minlength``: the number of
    bins, above every index). On the GPU each bin adds its weights one by one in the order NumPy
    does (a stable sort of the indices), not with CuPy's atomics, whose order varies from run to
    run: the same bits on every run, and the NumPy path's bits for the same weights."""
    if isinstance(index, np.ndarray):
        return np.bincount(index, weights=weights, minlength=minlength)
    import cupy
    if "ordered_bincount" not in _MODULES:
        _MODULES["ordered_bincount"] = cupy.RawKernel(_ORDERED_BINCOUNT, "ordered_bincount")
    index = index.reshape(-1)
    w = cupy.ascontiguousarray(weights, dtype=cupy.float64).reshape(-1)
    order = cupy.argsort(index)                          # CuPy's sort is stable
    start = cupy.searchsorted(index[order], cupy.arange(minlength + 1, dtype=index.dtype)).astype(cupy.int64)
    out = cupy.empty(minlength)
    launch(_MODULES["ordered_bincount"], minlength, (order.astype(cupy.int64), start, w, np.int64(minlength), out))
    return out


_REPLICA_SUMMARY = r"""
// out (n_replicas + n_replicas + 2 words, zeroed before): per replica the largest |F_v| (its bits:
// non-negative doubles order as their bits, and a NaN norm, above +inf, wins as in a max that
// propagates NaN), the energy's bits, then n_vertices - v for the first vertex v whose position is
// not finite (0: none), then a word the caller's own check may set (not written here). |F|^2 summed as NumPy sums a row, without fused multiply-adds.
extern "C" __global__ void replica_summary(const double* forces, const double* pos, const int* vertex_replica,
                                           const double* energy, int n_vertices, int n_replicas,
                                           unsigned long long* out)
{
    int v = blockIdx.x * blockDim.x + threadIdx.x;
    if (energy != nullptr && v < n_replicas) out[n_replicas + v] = (unsigned long long)__double_as_longlong(energy[v]);
    if (v >= n_vertices) return;
    if (forces != nullptr) {
        double fx = forces[3 * v], fy = forces[3 * v + 1], fz = forces[3 * v + 2];
        double m = sqrt(__dadd_rn(__dadd_rn(__dmul_rn(fx, fx), __dmul_rn(fy, fy)), __dmul_rn(fz, fz)));
        atomicMax(out + vertex_replica[v], (unsigned long long)__double_as_longlong(m));
    }
    if (!(isfinite(pos[3 * v]) && isfinite(pos[3 * v + 1]) && isfinite(pos[3 * v + 2])))
        atomicMax(out + 2 * n_replicas, (unsigned long long)(n_vertices - v));
}
"""


def replica_summary(positions, vertex_replica, n_replicas, forces=None, energy=None):
    """What a convergence check reads, in one array on the positions' device (one read-back on
    the GPU instead of one per quantity): per replica the largest vertex force norm ``max |F_v|``
    (0 for a replica without vertices) and the ``energy``, then the first vertex whose position is
    not finite, then one word (0) for a check of the caller's to set on the device before the read
    (``summary[-1:]``; Simulation's closed-cell flag). ``forces`` and ``energy`` may be None (only the positions are looked at).
    :func:`read_replica_summary` unpacks it; ``summary[:n_replicas].view(float64)`` is the
    maximum force on the device. Maximum and finiteness are exact, so both paths give the same
    bits for the same forces (the norm is summed in NumPy's order, without fused multiply-adds)."""
    nv, nr = len(positions), n_replicas
    if isinstance(positions, np.ndarray):
        out = np.zeros(2 * nr + 2, dtype=np.uint64)
        if forces is not None:
            fmax = np.zeros(nr)
            with np.errstate(invalid="ignore"):   # a NaN force is what a check is there to report
                np.maximum.at(fmax, vertex_replica, np.sqrt((forces * forces).sum(axis=1)))
            out[:nr] = fmax.view(np.uint64)
        if energy is not None:
            out[nr:2 * nr] = np.asarray(energy, dtype=np.float64).view(np.uint64)
        bad = np.flatnonzero(~np.isfinite(positions).all(axis=1))
        out[2 * nr] = nv - bad[0] if len(bad) else 0
        return out
    import cupy
    if "replica_summary" not in _MODULES:
        _MODULES["replica_summary"] = cupy.RawKernel(_REPLICA_SUMMARY, "replica_summary")
    out = cupy.zeros(2 * nr + 2, dtype=cupy.uint64)
    null = np.uintp(0)
    launch(_MODULES["replica_summary"], max(nv, nr),
           (null if forces is None else forces, positions, vertex_replica, null if energy is None else energy,
            np.int32(nv), np.int32(nr), out))
    return out


def read_replica_summary(summary, n_vertices, n_replicas):
    """``(max_force, energy, first_bad_vertex, flag)`` in NumPy from :func:`replica_summary`'s array
    (one device-to-host copy); ``first_bad_vertex`` is -1 when every position is finite, ``flag``
    the caller's word."""
    host = summary.get() if not isinstance(summary, np.ndarray) else summary
    nr = n_replicas
    last = int(host[2 * nr])
    return (host[:nr].view(np.float64).copy(), host[nr:2 * nr].view(np.float64).copy(),
            n_vertices - last if last else -1, int(host[2 * nr + 1]))
