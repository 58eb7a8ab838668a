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


def real(name, value, strict: bool = False, maximum: float | None = None) -> float:
    """A finite float >= 0, or > 0 with ``strict``; at most ``maximum`` when given."""
    try:
        v = float(value)
    except (TypeError, ValueError):
        v = float("nan")
    if not np.isfinite(v) or v < 0 or (strict and v == 0) or (maximum is not None and v > maximum):
        if maximum is not None:
            allowed = f"a number in {'(' if strict else '['}0, {maximum:g}]"
        else:
            allowed = "positive and finite" if strict else "a finite number >= 0"
        raise ParameterError(name, value, allowed)
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


def stored(where: str, value, dtype, shape=None, low=None, high=None, above=None, finite=True):
    """A stored array (a file's chunk, a checkpoint field) as a reader expects it, else ValueError
    ``"<where>: expected <what>, got <what it is>"``.

    Parameters
    ----------
    where : what the array is and where it was read from (file, frame, chunk).
    dtype : the exact dtype. shape : the exact shape; ``None`` entries take any length.
    low, high : inclusive bounds of every entry; above : an exclusive lower bound.
    finite : floats must be finite (default); with False, NaN and infinities pass.

    Returns
    -------
    The array (NumPy).
    """
    arr = np.asarray(value)
    dtype = np.dtype(dtype)
    if arr.dtype != dtype:
        raise ValueError(f"{where}: expected {dtype}, got {arr.dtype}")
    if shape is not None and (arr.ndim != len(shape) or any(n is not None and n != m for n, m in zip(shape, arr.shape))):
        want = "(" + ", ".join("any" if n is None else str(n) for n in shape) + ("," if len(shape) == 1 else "") + ")"
        raise ValueError(f"{where}: expected shape {want}, got {arr.shape}")
    checks = [(~np.isfinite(arr) if dtype.kind == "f" and finite else None, "finite values")]
    if low is not None:
        checks.append((arr < low, f"values >= {low}"))
    if high is not None:
        checks.append((arr > high, f"values <= {high}"))
    if above is not None:
        checks.append((arr <= above, f"values > {above}"))
    for bad, what in checks:
        if bad is not None and bad.any():
            at = tuple(int(i) for i in np.unravel_index(int(np.flatnonzero(bad)[0]), arr.shape))
            raise ValueError(f"{where}: expected {what}, got {arr[at].item()!r} at index {at[0] if arr.ndim == 1 else at}")
    return arr


def stored_size(where: str, size, cells, total_area):
    """Refuse a stored surface size (per replica, ``(n_replicas, *size_shape)``) whose ``cells``
    (per replica) would be of a size sqrt(<A>) outside [1e-50, 1e50], the range the tilings accept
    (areas ~R^2 and energies ~R^4 stay in float64), with ``total_area`` the surface's area of a
    size (``Constraint.total_area_np``; a surface without one is not checked); ValueError naming ``where``."""
    with np.errstate(over="ignore", divide="ignore", invalid="ignore"):
        try:
            area = total_area(size)
        except NotImplementedError:
            return
        unit = np.sqrt(area / np.maximum(cells, 1))
    bad = ~((unit >= 1e-50) & (unit <= 1e50))
    if bad.any():
        r = int(np.flatnonzero(bad)[0])
        raise ValueError(f"{where}: expected a size that gives cells of sqrt(<A>) in [1e-50, 1e50], got "
                         f"{size[r].tolist()} for replica {r} of {int(cells[r])} cells (sqrt(<A>) = {unit[r]:.3g})")


#: the largest target shape index p0 = P0/sqrt(<A>) the sweeps and the command line take: every
#: regular polygon has p0 < 4.6 (a triangle: 4.56) and tissues are fluid from p0 ~ 3.81 on, while
#: energies grow as p0^2 (p0 = 1e300 overflows float64)
SHAPE_INDEX_MAX = 100.0
#: the cell sizes sqrt(<A>) the initialisers take: areas (~size^2) and energies (~size^4) then stay
#: inside the range of float64 with room to spare
CELL_SIZE_RANGE = (1e-50, 1e50)


def check_cell_size(name: str, value, size: float, default: str):
    """Refuse ``name`` = ``value`` when it makes cells of size sqrt(<A>) = ``size`` outside
    :data:`CELL_SIZE_RANGE` (ValueError; ``default`` says which value gives <A> = 1)."""
    if not CELL_SIZE_RANGE[0] <= size <= CELL_SIZE_RANGE[1]:
        raise ValueError(f"{name} {value!r} gives cells of size sqrt(<A>) = {size:.3g}: areas and energies would "
                         f"leave the range of float64; choose units in which cells are of order 1 ({default})")


class InsufficientMemory(MemoryError, ValueError):
    """A request that would not fit in memory, refused before allocating (a MemoryError and a ValueError)."""


def did_you_mean(name: str, choices) -> str:
    """``" (did you mean 'x'?)"`` with the choice nearest ``name`` (difflib, ignoring case), or ``""``
    when none is near: the tail of an error about an unknown name."""
    import difflib
    lowered = {str(c).lower(): c for c in choices}
    close = difflib.get_close_matches(str(name).lower(), list(lowered), n=1, cutoff=0.6)
    return f" (did you mean {lowered[close[0]]!r}?)" if close else ""


def keyword_hints(cls):
    """Wrap ``cls.__init__`` (when the class defines one) so that a call with a keyword it does not
    take raises TypeError naming the class, the keyword and the nearest parameter, instead of
    Python's bare message. Returns ``cls``."""
    import functools
    import inspect
    init = cls.__dict__.get("__init__")
    if init is None or getattr(init, "keyword_hints", False):
        return cls

    @functools.wraps(init)
    def __init__(self, *args, **kwargs):
        try:
            init(self, *args, **kwargs)
        except TypeError:
            params = inspect.signature(init).parameters
            if any(p.kind is p.VAR_KEYWORD for p in params.values()):
                raise
            names = [n for n, p in list(params.items())[1:] if p.kind not in (p.VAR_POSITIONAL, p.POSITIONAL_ONLY)]
            unknown = [k for k in kwargs if k not in names]
            if not unknown:
                raise
            who = type(self) if type(self).__init__ is __init__ else cls   # a subclass inherits it, or calls it
            raise TypeError(f"{who.__name__}() got an unexpected keyword argument {unknown[0]!r}"
                            f"{did_you_mean(unknown[0], names)}; its parameters: {', '.join(names)}") from None
    __init__.keyword_hints = True
    cls.__init__ = __init__
    return cls


class KeywordHints:
    """A base class (of ``spherevm.plugins.Operation``): the constructor of every subclass, a
    user's included, answers a keyword it does not take with the nearest parameter
    (:func:`keyword_hints`)."""

    def __init_subclass__(cls, **kwargs):
        super().__init_subclass__(**kwargs)
        keyword_hints(cls)


def available_host_memory():
    """Bytes of host memory available now (``MemAvailable`` of /proc/meminfo, else sysconf), or None."""
    try:
        with open("/proc/meminfo") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    try:
        import os
        return int(os.sysconf("SC_AVPHYS_PAGES")) * int(os.sysconf("SC_PAGE_SIZE"))
    except (ValueError, OSError, AttributeError):
        return None


def available_device_memory():
    """Bytes free on the current GPU now (CuPy's ``memGetInfo``), or None without one."""
    try:
        import cupy
        return int(cupy.cuda.runtime.memGetInfo()[0])
    except Exception:
        return None


# The memory model behind the guards, in bytes per cell (measured with tracemalloc, random_tiling(100000)
# and 20 FIRE + T1 steps, 2-core VM): building one random tiling peaks near 1.5 kB per cell of it
# (qhull, the dual, the Morton sort); a finished State holds ~160 B per cell (a second copy when a
# Simulation takes it); a CPU run (State, forces, FIRE memory, geometry scratch) peaks near 1.9 kB
# per cell; a GPU run keeps ~400 B per cell on the device and little beyond the State on the host.
# Rounded up: a guard that refuses a run that would fit is worse than one that lets a tight one try.
BUILD_BYTES_PER_CELL = 2500
STATE_BYTES_PER_CELL = 500
CPU_RUN_BYTES_PER_CELL = 2500
GPU_RUN_BYTES_PER_CELL = 400


def _gib(n):
    return f"{n / 2 ** 40:.3g} TiB" if n >= 2 ** 40 else f"{n / 2 ** 30:.3g} GiB"


def check_memory(what: str, host_bytes: float, device_bytes: float = 0.0, gpu: bool = False,
                 advice: str = "ask for fewer cells or replicas"):
    """Refuse (InsufficientMemory) a request whose estimated host or GPU memory exceeds what is
    available now, with both numbers in the message."""
    host = available_host_memory()
    if host is not None and host_bytes > host:
        raise InsufficientMemory(f"{what} needs about {_gib(host_bytes)} of host memory, but only {_gib(host)} "
                                 f"is available; {advice}")
    free = available_device_memory() if gpu and device_bytes else None
    if free is not None and device_bytes > free:
        raise InsufficientMemory(f"{what} needs about {_gib(device_bytes)} of GPU memory, but only {_gib(free)} "
                                 f"is free; {advice}")


def check_tiling_memory(what: str, n_cells: float, replicas: int, gpu: bool):
    """Refuse before allocating tilings that cannot fit: the States and the largest tiling being
    built on the host, the States on a GPU (``gpu``: the tilings are made on one)."""
    total = float(n_cells) * replicas
    check_memory(what, host_bytes=total * STATE_BYTES_PER_CELL + float(n_cells) * BUILD_BYTES_PER_CELL,
                 device_bytes=total * GPU_RUN_BYTES_PER_CELL, gpu=gpu)


def check_run_memory(what: str, cells: float, largest: float, gpu: bool, copies: int = 1,
                     advice: str = "ask for fewer cells or replicas"):
    """Refuse (InsufficientMemory) before anything is built a run of ``cells`` cells in all, in
    tilings of at most ``largest`` cells each, on the GPU or the CPU, ``copies`` times at once (a
    sweep's worker processes): the host must hold the tiling being built and the run (its State on
    a GPU run, everything on a CPU run), the GPU the device arrays of a GPU run."""
    per_cell = STATE_BYTES_PER_CELL if gpu else CPU_RUN_BYTES_PER_CELL
    host = copies * (float(cells) * per_cell + float(largest) * BUILD_BYTES_PER_CELL)
    check_memory(what, host_bytes=host, device_bytes=float(cells) * GPU_RUN_BYTES_PER_CELL, gpu=gpu, advice=advice)
