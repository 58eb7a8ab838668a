"""Counter-based random numbers: Philox4x32-10 keyed by (seed, stream), counted by (id, timestep).

Every draw is a pure function of ``(seed, stream, timestep, id, index)``: there is no generator
state, so the numbers do not depend on the order in which ids are visited, on how they are split
into batches, or on a GPU launch configuration. ``spherevm/random_philox.cuh`` implements the same
construction for CUDA kernels; integers and uniforms agree bit for bit, normals to a few ulp.
The construction is documented in ``docs/random.md``; in short:

* **key** ``= (seed, stream)``, two uint32 words.
* **counter** ``= (id, timestep & 0xffffffff, timestep >> 32, block)``, four uint32 words;
  ``block = 0, 1, 2, ...`` numbers the Philox calls one id needs in one step.
* Philox call ``block`` gives words ``w0, w1, w2, w3``; draw ``j`` (0-based) of an id comes from
  block ``j // 2``: the pair ``(w0, w1)`` when ``j`` is even, ``(w2, w3)`` when ``j`` is odd.
* **uniform** from a pair ``(hi, lo)``: ``n = (hi << 20) | (lo >> 12)`` (52 bits), then
  ``u = (2 n + 1) * 2**-53``, the midpoint of the n-th of 2**52 equal bins of [0, 1). Every step is
  exact, so ``u`` lies in ``[2**-53, 1 - 2**-53]`` (never 0 or 1) and is bitwise reproducible.
* **normal** (Box-Muller) from block ``b``: ``u1, u2`` the uniforms of draws ``2b`` and ``2b+1``,
  ``r = sqrt(-2 log u1)``, ``t = TWO_PI * u2``; draw ``2b`` is ``r cos t`` and draw ``2b+1`` is
  ``r sin t``.

Use one stream per purpose (``STREAM_*`` below); ``uniform`` and ``normal`` with the same
arguments read the same Philox words, so a purpose that needs both must use two streams.
"""
from __future__ import annotations

import operator

import numpy as np

__all__ = ["philox4x32", "uniform", "normal", "uniform_from_words",
           "STREAM_BROWNIAN", "STREAM_ACTIVE", "STREAM_DIRECTOR_INIT", "STREAM_DIVISION",
           "STREAM_VERTEX_BIRTH",
           "PHILOX_M0", "PHILOX_M1", "PHILOX_W0", "PHILOX_W1", "TWO_PI"]

# Streams: one per purpose. Draws indexed by vertex ids and by cell ids must not share a stream.
STREAM_BROWNIAN = 0   #: translational noise of the integrator, indexed by vertex id
STREAM_ACTIVE = 1     #: rotational noise of the cell polarity (director), indexed by cell id
STREAM_DIRECTOR_INIT = 2   #: initial director angles (drawn at timestep 0), indexed by cell id
STREAM_DIVISION = 3   #: cell division (draw 0: whether, 1: the cut's angle, 2: the daughter's director), by cell id
STREAM_VERTEX_BIRTH = 4   #: director of a vertex a division creates (vertex directors), indexed by vertex id

# Philox4x32 constants (Salmon et al., SC'11; Random123 philox.h).
PHILOX_M0 = 0xD2511F53   # multiplier applied to counter word 0
PHILOX_M1 = 0xCD9E8D57   # multiplier applied to counter word 2
PHILOX_W0 = 0x9E3779B9   # Weyl increment of key word 0 (golden ratio)
PHILOX_W1 = 0xBB67AE85   # Weyl increment of key word 1 (sqrt(3) - 1)

TWO_PI = 6.283185307179586   # the double nearest 2 pi (== 2 * math.pi); the CUDA header uses it too
_TWO_M53 = 2.0 ** -53        # 1.1102230246251565e-16, exact

_U32 = 0xFFFFFFFF
_MASK = np.uint64(_U32)
_SHIFT32 = np.uint64(32)


def _as_u32_array(a, name, last):
    """``a`` as a uint32 array whose last axis has length ``last``; values must fit in 32 bits."""
    arr = np.asarray(a)
    if arr.ndim == 0 or arr.shape[-1] != last:
        raise ValueError(f"{name} must have shape (..., {last}), got {arr.shape}")
    if arr.dtype == np.uint32:
        return arr
    if arr.dtype.kind not in "iu":
        raise ValueError(f"{name} must hold integers in [0, 2**32), got dtype {arr.dtype}")
    if arr.size and (arr.min() < 0 or arr.max() > _U32):
        raise ValueError(f"{name} must hold integers in [0, 2**32)")
    return arr.astype(np.uint32)


def philox4x32(counter, key, rounds=10):
    """The Philox4x32-R block function of Random123, vectorised over leading axes.

    ``counter``: uint32 array (..., 4); ``key``: uint32 array (..., 2); leading axes broadcast.
    Returns a uint32 array (..., 4). ``rounds=10`` is Philox4x32-10 (the Random123 default and the
    one :func:`uniform` and :func:`normal` use); ``rounds=7`` is also covered by the known-answer
    tests. One round, with ``mulhilo(a, b)`` the high and low 32-bit halves of the 64-bit product::

        hi0, lo0 = mulhilo(M0, c0);  hi1, lo1 = mulhilo(M1, c2)
        (c0, c1, c2, c3) = (hi1 ^ c1 ^ k0, lo1, hi0 ^ c3 ^ k1, lo0)

    and before every round but the first the key is bumped: ``k0 += W0; k1 += W1`` (mod 2**32).
    """
    rounds = operator.index(rounds)
    if rounds < 0:
        raise ValueError(f"rounds must be a non-negative integer, got {rounds}")
    ctr = _as_u32_array(counter, "counter", 4).astype(np.uint64)
    k = _as_u32_array(key, "key", 2).astype(np.uint64)
    shape = np.broadcast_shapes(ctr.shape[:-1], k.shape[:-1])
    c0, c1, c2, c3 = (np.broadcast_to(ctr[..., i], shape) for i in range(4))
    k0, k1 = k[..., 0], k[..., 1]
    m0, m1 = np.uint64(PHILOX_M0), np.uint64(PHILOX_M1)
    w0, w1 = np.uint64(PHILOX_W0), np.uint64(PHILOX_W1)
    for r in range(rounds):
        if r > 0:
            k0 = (k0 + w0) & _MASK
            k1 = (k1 + w1) & _MASK
        p0 = m0 * c0   # < 2**64: exact in uint64
        p1 = m1 * c2
        c0, c1, c2, c3 = ((p1 >> _SHIFT32) ^ c1 ^ k0, p1 & _MASK,
                          (p0 >> _SHIFT32) ^ c3 ^ k1, p0 & _MASK)
    out = np.empty(shape + (4,), dtype=np.uint32)
    for i, c in enumerate((c0, c1, c2, c3)):
        out[..., i] = c
    return out


def uniform_from_words(hi, lo):
    """Map pairs of uint32 words to doubles in (0, 1): ``(2 ((hi << 20) | (lo >> 12)) + 1) * 2**-53``.

    The 52-bit integer ``n`` keeps all 32 bits of ``hi`` and the top 20 of ``lo``; ``2n + 1 < 2**53``
    converts to double exactly and the power-of-two scale is exact, so the result is the same bit
    pattern on every IEEE machine. Range: ``[2**-53, 1 - 2**-53]``, symmetric about 1/2.
    """
    hi = np.asarray(hi, dtype=np.uint32).astype(np.uint64)
    lo = np.asarray(lo, dtype=np.uint32).astype(np.uint64)
    n = (hi << np.uint64(20)) | (lo >> np.uint64(12))
    return ((n << np.uint64(1)) | np.uint64(1)).astype(np.float64) * _TWO_M53


def _check_int(value, name, lo, hi):
    try:
        v = operator.index(value)
    except TypeError:
        raise ValueError(f"{name} must be an integer in [{lo}, {hi}), got {value!r}") from None
    if not lo <= v < hi:
        raise ValueError(f"{name} must be an integer in [{lo}, {hi}), got {v}")
    return v


def _check_ids(ids):
    arr = np.asarray(ids)
    if arr.ndim == 0:
        arr = arr.reshape(1)
    if arr.ndim != 1:
        raise ValueError(f"ids must be a 1-D array of integers in [0, 2**32), got shape {arr.shape}")
    if arr.size == 0:
        return np.zeros(0, dtype=np.uint32)
    if arr.dtype.kind not in "iu":
        raise ValueError(f"ids must be integers in [0, 2**32), got dtype {arr.dtype}")
    if arr.min() < 0 or arr.max() > _U32:
        raise ValueError(f"ids must be integers in [0, 2**32), got values in "
                         f"[{arr.min()}, {arr.max()}]")
    return arr.astype(np.uint32)


def _blocks(seed, stream, timestep, ids, count):
    """Philox output for every id and block: uint32 (len(ids), ceil(count / 2), 4)."""
    seed = _check_int(seed, "seed", 0, 2**32)
    stream = _check_int(stream, "stream", 0, 2**32)
    timestep = _check_int(timestep, "timestep", 0, 2**64)
    count = _check_int(count, "count", 1, 2**32 + 1)
    ids = _check_ids(ids)
    nblocks = (count + 1) // 2
    ctr = np.empty((ids.size, nblocks, 4), dtype=np.uint32)
    ctr[..., 0] = ids[:, None]
    ctr[..., 1] = timestep & _U32
    ctr[..., 2] = timestep >> 32
    ctr[..., 3] = np.arange(nblocks, dtype=np.uint32)[None, :]
    key = np.array([seed, stream], dtype=np.uint32)
    return philox4x32(ctr, key), count


def uniform(seed, stream, timestep, ids, count=1):
    """Uniform doubles in the open interval (0, 1), shape ``(len(ids), count)``.

    ``seed`` in [0, 2**32); ``stream`` in [0, 2**32), one per purpose (``STREAM_*``); ``timestep``
    in [0, 2**64); ``ids`` vertex or cell ids in [0, 2**32); ``count`` >= 1 draws per id. Row ``i``
    depends only on ``(seed, stream, timestep, ids[i])``, and column ``j`` does not depend on
    ``count`` (asking for more draws appends columns).
    """
    words, count = _blocks(seed, stream, timestep, ids, count)
    u = uniform_from_words(words[..., 0::2], words[..., 1::2])   # (N, nblocks, 2)
    return u.reshape(u.shape[0], 2 * u.shape[1])[:, :count]


def normal(seed, stream, timestep, ids, count=1):
    """Standard normal doubles, shape ``(len(ids), count)``, by Box-Muller.

    Same arguments and guarantees as :func:`uniform`, from the same Philox words: with
    ``u = uniform(seed, stream, timestep, ids, 2 * b + 2)``, columns ``2b`` and ``2b + 1`` are
    ``sqrt(-2 log u[:, 2b]) * (cos, sin)(TWO_PI * u[:, 2b + 1])``. ``|z| <= sqrt(106 log 2) ~ 8.57``.
    """
    words, count = _blocks(seed, stream, timestep, ids, count)
    u = uniform_from_words(words[..., 0::2], words[..., 1::2])   # (N, nblocks, 2): u1, u2
    r = np.sqrt(-2.0 * np.log(u[..., 0]))
    t = TWO_PI * u[..., 1]
    z = np.stack((r * np.cos(t), r * np.sin(t)), axis=-1)   # (N, nblocks, 2)
    return z.reshape(z.shape[0], 2 * z.shape[1])[:, :count]
