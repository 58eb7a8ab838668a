"""The CUDA headers that hold pure arithmetic, compiled with the host C++ compiler and run on the CPU.

``spherevm/random_philox.cuh`` and ``spherevm/geometry/sphere.cuh`` are included unmodified into
``tests/cuda_host/harness.cpp`` after ``tests/cuda_host/cuda_host.h`` (empty CUDA qualifiers,
uint2/uint4, rsqrt), built once per session into a temporary directory and loaded with ctypes
(docs/testing.md, "CUDA headers on the CPU"). Checked against:

* the Random123 known answers (``kat_vectors``, ``philox4x32 7`` and ``philox4x32 10`` lines) and
  spherevm.random's Philox, bit for bit;
* spherevm.random's ``(seed, stream, timestep, id)`` streams: Philox words and uniforms bit for bit,
  normals to a few ulp (libm log/sin/cos may differ from NumPy's in the last bit, docs/random.md),
  timesteps past 2**32 included so that the counter's two timestep words are pinned;
* spherevm.geometry.sphere and the edge terms of spherevm.constraints.sphere, on random points,
  very short edges, nearly and exactly antipodal points, tiny and degenerate triangles, to
  ``RTOL`` relative (see below).

Without a C++ compiler the host tests skip with the reason; CI has one. The last test runs the same
known answers and streams on the GPU (``gpu`` marker, skipped by conftest without CuPy and a GPU).
"""
import ctypes
import pathlib
import shutil
import subprocess

import numpy as np
import pytest

from conftest import PHILOX_KAT as KAT

import spherevm as svm
from spherevm import random as svr
from spherevm.constraints import sphere as csphere
from spherevm.geometry import sphere as geo

HERE = pathlib.Path(__file__).resolve().parent / "cuda_host"
PACKAGE = pathlib.Path(svm.__file__).resolve().parent
# -ffp-contract=off: no fused multiply-adds, so the host build rounds every operation as NumPy does
# (nvcc does contract by default; the GPU's agreement with NumPy is the business of test_gpu.py).
CXXFLAGS = ["-O2", "-std=c++17", "-shared", "-fPIC", "-ffp-contract=off", "-Wall", "-Wextra"]

# Geometry tolerance, relative to the NumPy value (vectors: relative to its norm). The host build
# evaluates the same expressions in the same order without contraction, so most results are bitwise
# equal; what may differ is rsqrt (1.0 / sqrt on the host, ~1 ulp) against NumPy's x / sqrt, and
# atan2/sqrt-free libm differences of an ulp or two. 1e-14 is ~45-90 ulp: a wide margin over those,
# and far below what any change of formula produces (acos instead of the half-angle form is off by
# ~1e-10 relative at 1e-6 rad; a dropped term or a wrong sign is off by O(1)).
RTOL = 1e-14
# Normals go through log, sqrt, cos and sin: glibc against NumPy's loops, a few ulp (docs/random.md
# measured <= 2 ulp for the header's host path).
NORMAL_ULP = 4


# Timesteps: small, both sides of 2**32 (where the high counter word starts to move), the two words
# swapped into each other, and the extremes. A swap of the counter's timestep words changes every
# draw at every nonzero timestep; a dropped high word changes those from 2**32 on.
TIMESTEPS = [0, 1, 123456, 2**32 - 1, 2**32, 2**32 + 7, (7 << 32) | 3, (3 << 32) | 7, 2**40 + 12345,
             2**63 + 2**32 + 9, 2**64 - 1]
IDS = np.concatenate([np.arange(200), [2**31, 2**32 - 2, 2**32 - 1]]).astype(np.uint32)
COUNT = 7   # odd: the last block contributes one draw
KEYS = [(0, svr.STREAM_BROWNIAN), (2024, svr.STREAM_ACTIVE), (2**32 - 1, svr.STREAM_DIRECTOR_INIT),
        (12345, 2**32 - 1)]


# ------------------------------------------------------------------------------------- the harness
def find_compiler():
    return shutil.which("g++") or shutil.which("c++")


def build_harness(directory, source=HERE / "harness.cpp", include=PACKAGE):
    """Compile the harness against the headers under ``include``; returns the library's path."""
    cxx = find_compiler()
    lib = pathlib.Path(directory) / "libsvm_cuda_host.so"
    cmd = [cxx, *CXXFLAGS, f"-I{include}", f"-I{HERE}", str(source), "-o", str(lib)]
    done = subprocess.run(cmd, capture_output=True, text=True)
    if done.returncode != 0:
        raise RuntimeError(f"building the CUDA host harness failed:\n{' '.join(cmd)}\n{done.stderr}")
    return lib


class Harness:
    """ctypes front end of harness.cpp: NumPy arrays in, NumPy arrays out."""

    def __init__(self, path):
        self.lib = ctypes.CDLL(str(path))

    @staticmethod
    def _p(a):
        return a.ctypes.data_as(ctypes.c_void_p)

    @staticmethod
    def _vec(a):
        return np.ascontiguousarray(a, dtype=np.float64).reshape(-1, 3)

    def philox(self, ctr, key, rounds=10):
        ctr = np.ascontiguousarray(ctr, dtype=np.uint32).reshape(-1, 4)
        key = np.ascontiguousarray(np.broadcast_to(key, (len(ctr), 2)), dtype=np.uint32)
        out = np.empty_like(ctr)
        self.lib.h_philox4x32(ctypes.c_long(len(ctr)), ctypes.c_uint(rounds), self._p(ctr),
                              self._p(key), self._p(out))
        return out

    def rng_block(self, seed, stream, timestep, ids, nblocks):
        ids = np.ascontiguousarray(ids, dtype=np.uint32)
        out = np.empty((len(ids), nblocks, 4), dtype=np.uint32)
        self.lib.h_rng_block(ctypes.c_uint(seed), ctypes.c_uint(stream), ctypes.c_ulonglong(timestep),
                             ctypes.c_long(len(ids)), self._p(ids), ctypes.c_uint(nblocks), self._p(out))
        return out

    def u01(self, hi, lo):
        hi = np.ascontiguousarray(hi, dtype=np.uint32)
        lo = np.ascontiguousarray(lo, dtype=np.uint32)
        out = np.empty(len(hi))
        self.lib.h_u01(ctypes.c_long(len(hi)), self._p(hi), self._p(lo), self._p(out))
        return out

    def draws(self, kind, seed, stream, timestep, ids, count):
        """kind: "uniform", "normal" (svm_uniform/svm_normal per draw), "uniform2", "normal2"."""
        code = ["uniform", "normal", "uniform2", "normal2"].index(kind)
        ids = np.ascontiguousarray(ids, dtype=np.uint32)
        out = np.empty((len(ids), count))
        self.lib.h_draws(ctypes.c_int(code), ctypes.c_uint(seed), ctypes.c_uint(stream),
                         ctypes.c_ulonglong(timestep), ctypes.c_long(len(ids)), self._p(ids),
                         ctypes.c_uint(count), self._p(out))
        return out

    def _map(self, name, nout_shapes, *vecs):
        vecs = [self._vec(v) for v in vecs]
        n = len(vecs[0])
        outs = [np.empty((n,) + s) for s in nout_shapes]
        getattr(self.lib, name)(ctypes.c_long(n), *[self._p(v) for v in vecs], *[self._p(o) for o in outs])
        return outs if len(outs) > 1 else outs[0]

    def normalize3(self, a):
        return self._map("h_normalize3", [(3,)], a)

    def norm3(self, a):
        return self._map("h_norm3", [()], a)

    def dot_cross(self, a, b):
        return self._map("h_dot_cross", [(), (3,)], a, b)

    def geodesic_length(self, a, b):
        return self._map("h_geodesic_length", [()], a, b)

    def geodesic_length_gradient(self, a, b):
        return self._map("h_geodesic_length_gradient", [(3,)], a, b)

    def solid_angle(self, a, b, c):
        return self._map("h_solid_angle", [()], a, b, c)

    def solid_angle_gradient(self, a, b, c):
        return self._map("h_solid_angle_gradient", [(3,)], a, b, c)

    def edge(self, b, d):
        """make_edge(b, d) -> dict(m, x, m2, q, half, area, length) (area/length: the edge terms)."""
        names = ("m", "x", "m2", "q", "half", "area", "length")
        shapes = [(3,), (3,), (), (), (), (3,), (3,)]
        return dict(zip(names, self._map("h_edge", shapes, b, d)))


@pytest.fixture(scope="session")
def harness(tmp_path_factory):
    if find_compiler() is None:
        pytest.skip("no C++ compiler (g++ or c++) on PATH: the CUDA headers cannot be built for the CPU")
    return Harness(build_harness(tmp_path_factory.mktemp("cuda_host")))


# ------------------------------------------------------------------------------------- comparisons
def assert_close(host, ref, rtol=RTOL, what=""):
    """``|host - ref| <= rtol |ref|`` per item; for vectors (last axis 3) in the Euclidean norm."""
    host, ref = np.asarray(host), np.asarray(ref)
    assert host.shape == ref.shape, what
    assert np.array_equal(np.isfinite(host), np.isfinite(ref)), what
    if ref.ndim == 2 and ref.shape[1] == 3:
        # norms of rows pre-scaled by their largest |component| (edge terms reach 1e287 at q = 0)
        big = np.max(np.abs(ref), axis=1, keepdims=True)
        big = np.where(big > 0, big, 1.0)
        err, scale = np.linalg.norm((host - ref) / big, axis=1), np.linalg.norm(ref / big, axis=1)
    else:
        err, scale = np.abs(host - ref), np.abs(ref)
    bad = ~(err <= rtol * scale)
    assert not bad.any(), (f"{what}: {bad.sum()} of {bad.size} differ by more than {rtol:g} relative; "
                           f"worst relative error {np.max(err / np.where(scale > 0, scale, 1)):.3g}")


def assert_bitwise(host, ref, what=""):
    host, ref = np.asarray(host), np.asarray(ref)
    assert host.shape == ref.shape and host.dtype == ref.dtype, what
    view = np.uint64 if host.dtype == np.float64 else host.dtype
    diff = host.view(view) != ref.view(view)
    assert not diff.any(), f"{what}: {diff.sum()} of {diff.size} differ, first at {np.argwhere(diff)[0]}"


# ------------------------------------------------------------------------------------- Philox
@pytest.mark.parametrize("rounds,ctr,key,expected", KAT)
def test_header_philox_known_answers(harness, rounds, ctr, key, expected):
    """Random123's known answers, from the header (svm_philox4x32_10 / _R) and from spherevm.random."""
    assert harness.philox(ctr, key, rounds)[0].tolist() == expected
    assert svr.philox4x32(ctr, key, rounds).tolist() == expected


def test_header_philox_matches_numpy_on_random_counters(harness):
    rng = np.random.default_rng(18)
    ctr = rng.integers(0, 2**32, size=(4000, 4), dtype=np.uint32)
    key = rng.integers(0, 2**32, size=(4000, 2), dtype=np.uint32)
    for rounds in (10, 7, 1, 0):
        assert_bitwise(harness.philox(ctr, key, rounds), svr.philox4x32(ctr, key, rounds), f"rounds={rounds}")


def test_header_u01_is_exact(harness):
    rng = np.random.default_rng(3)
    hi = np.concatenate([[0, 0xFFFFFFFF, 0x80000000, 0], rng.integers(0, 2**32, 4000)]).astype(np.uint32)
    lo = np.concatenate([[0, 0xFFFFFFFF, 0, 0xFFF], rng.integers(0, 2**32, 4000)]).astype(np.uint32)
    u = harness.u01(hi, lo)
    assert_bitwise(u, svr.uniform_from_words(hi, lo), "svm_u01")
    assert u[:4].tolist() == [2.0**-53, 1.0 - 2.0**-53, 0.5 + 2.0**-53, 2.0**-53]


# ------------------------------------------------------------------------------------- streams
@pytest.mark.parametrize("seed,stream", KEYS)
def test_header_streams_match_numpy(harness, seed, stream):
    """svm_rng_block/svm_uniform(2)/svm_normal(2) against spherevm.random over (seed, stream, timestep,
    id): 11 timesteps x 203 ids x 7 draws = 15,631 draws of each kind per key."""
    nblocks = (COUNT + 1) // 2
    for t in TIMESTEPS:
        what = f"seed={seed} stream={stream} timestep={t:#x}"
        words = harness.rng_block(seed, stream, t, IDS, nblocks)
        ctr = np.stack(np.broadcast_arrays(IDS[:, None], np.uint32(t & 0xFFFFFFFF), np.uint32(t >> 32),
                                           np.arange(nblocks, dtype=np.uint32)[None, :]), axis=-1)
        assert_bitwise(words, svr.philox4x32(ctr, [seed, stream]), "svm_rng_block " + what)

        u = svr.uniform(seed, stream, t, IDS, COUNT)
        assert_bitwise(harness.draws("uniform", seed, stream, t, IDS, COUNT), u, "svm_uniform " + what)
        assert_bitwise(harness.draws("uniform2", seed, stream, t, IDS, COUNT), u, "svm_uniform2 " + what)

        z = svr.normal(seed, stream, t, IDS, COUNT)
        z1 = harness.draws("normal", seed, stream, t, IDS, COUNT)
        z2 = harness.draws("normal2", seed, stream, t, IDS, COUNT)
        assert_bitwise(z1, z2, "svm_normal against svm_normal2 " + what)   # the same host code
        ulps = np.abs(z1 - z) / np.spacing(np.abs(z))
        assert ulps.max() <= NORMAL_ULP, f"svm_normal {what}: {ulps.max():.1f} ulp from NumPy"


def test_timestep_words_are_distinguished(harness):
    """Timesteps that differ only in which 32-bit word holds which value draw different numbers, and
    a timestep past 2**32 draws what spherevm.random draws (a swapped or dropped high word fails)."""
    a = harness.draws("uniform2", 7, 0, (1 << 32) | 2, IDS, 4)
    b = harness.draws("uniform2", 7, 0, (2 << 32) | 1, IDS, 4)
    c = harness.draws("uniform2", 7, 0, 2, IDS, 4)
    assert not np.any(a == b) and not np.any(a == c)
    assert_bitwise(a, svr.uniform(7, 0, (1 << 32) | 2, IDS, 4), "timestep 2**32 + 2")


# ------------------------------------------------------------------------------------- geometry
def _unit(x):
    return x / np.linalg.norm(x, axis=-1, keepdims=True)


def _tangent(rng, a):
    """A random unit tangent at each unit vector of ``a``."""
    return _unit(geo.tangent_project(a, rng.normal(size=a.shape)))


def _pairs(seed=0, n=600):
    """Unit-vector pairs (a, b): random; very short arcs 1e-13 .. 1e-1 rad; nearly antipodal (pi minus
    1e-13 .. 1e-1); exactly coincident and exactly antipodal; along the axes."""
    rng = np.random.default_rng(seed)
    a = _unit(rng.normal(size=(n, 3)))
    b = _unit(rng.normal(size=(n, 3)))
    eps = np.logspace(-13, -1, n)[:, None]
    t = _tangent(rng, a)
    short = _unit(a + eps * t)
    anti = _unit(-a + eps * t)
    axes = np.eye(3)
    A = np.concatenate([a, a, a, a, a, axes, axes])
    B = np.concatenate([b, short, anti, a.copy(), -a, np.roll(axes, 1, axis=0), -axes])
    return A, B


def _triangles(seed=1, n=600):
    """Unit-vector triangles (a, b, c): random; tiny (sides 1e-10 .. 1e-1) in both orientations;
    nearly degenerate (c close to the great circle through a and b); with a repeated vertex."""
    rng = np.random.default_rng(seed)
    a, b, c = (_unit(rng.normal(size=(n, 3))) for _ in range(3))
    s = np.logspace(-10, -1, n)[:, None]
    t1, t2 = _tangent(rng, a), _tangent(rng, a)
    tb, tc = _unit(a + s * t1), _unit(a + s * t2)
    flat = _unit(a + b + 1e-9 * rng.normal(size=(n, 3)))
    A = np.concatenate([a, a, a, a, a])
    B = np.concatenate([b, tb, tc, b, a])
    C = np.concatenate([c, tc, tb, flat, c])
    return A, B, C


def test_header_vector_helpers(harness):
    rng = np.random.default_rng(5)
    x = rng.normal(size=(2000, 3)) * np.logspace(-3, 3, 2000)[:, None]   # positions of any size
    assert_close(harness.normalize3(x), geo.normalize(x), what="normalize3")
    assert_close(harness.norm3(x), np.linalg.norm(x, axis=1), what="norm3")
    y = rng.normal(size=(2000, 3))
    dot, cross = harness.dot_cross(x, y)
    assert_bitwise(dot, geo._dot(x, y), "dot3")
    assert_bitwise(cross, geo._cross(x, y), "cross3")


def test_header_geodesic_length_and_gradient(harness):
    a, b = _pairs()
    assert_close(harness.geodesic_length(a, b), geo.geodesic_length(a, b), what="geodesic_length")
    g = harness.geodesic_length_gradient(a, b)
    assert_close(g, geo.geodesic_length_gradient(a, b), what="geodesic_length_gradient")
    coincident = np.all(a == b, axis=1)
    assert coincident.sum() >= 600 and np.all(g[coincident] == 0.0)   # the minimal-norm subgradient


def test_header_solid_angle_and_gradient(harness):
    a, b, c = _triangles()
    assert_close(harness.solid_angle(a, b, c), geo.solid_angle(a, b, c), what="solid_angle")
    assert_close(harness.solid_angle_gradient(a, b, c), geo.solid_angle_gradient(a, b, c),
                 what="solid_angle_gradient")


def _edge_reference(b, d):
    """The edge terms exactly as Sphere.cell_geometry and Sphere._edge_factors compute them
    (spherevm/constraints/sphere.py), for (n, 3) arrays; checked against that code by
    test_header_edge_terms_match_the_sphere_constraint."""
    m = b - d
    m2 = geo._dot(m, m)
    q = np.maximum(4.0 - m2, 0.0)
    sm, sp = np.sqrt(m2), np.sqrt(q)
    x = geo._cross(m, b)
    area_f, length_f = csphere.Sphere._edge_factors(dict(q=q, two_sin=sm * sp))
    return dict(m=m, x=x, m2=m2, q=q, half=np.arctan2(sm, sp), area=area_f[:, None] * x,
                length=length_f[:, None] * m)


def test_header_edge_terms(harness):
    """make_edge, half_angle, edge_area_term and edge_length_term on short, antipodal and coincident
    edges, against the constraint's formulas; half_angle also against geodesic_length / 2."""
    b, d = _pairs(seed=2)
    host, ref = harness.edge(b, d), _edge_reference(b, d)
    for name in ("m", "x", "m2", "q", "half", "area", "length"):
        assert_close(host[name], ref[name], what=name)
    # away from the antipode: there q = 4 - |m|^2 keeps only absolute accuracy (~4e-16), which moves
    # the angle by ~1e-16 / sqrt(q) against the |b + d| of geodesic_length
    ok = ref["q"] > 1e-4
    assert_close(2.0 * host["half"][ok], geo.geodesic_length(b[ok], d[ok]), rtol=1e-13,
                 what="half_angle against geodesic_length")


def test_header_edge_terms_match_the_sphere_constraint(harness):
    """On a random tiling, the header's edge terms for every corner equal those Sphere.cell_geometry
    keeps (m, x, q and the factors of _edge_factors), and half_angle sums to the perimeters."""
    state = svm.init.random_tiling(300, seed=18)
    sphere = state.constraint
    geom = sphere.cell_geometry(state)
    u = geom.corners["u"]                      # (3, V) unit vectors
    for index, part in zip(geom.corners["index"], geom.corners["parts"]):
        lo, hi = index["lo"], index["hi"]
        b = np.tile(u[:, lo:hi], (1, 3)).T     # slot-major corners: b repeated for the 3 slots
        d = u[:, index["next"]].T
        host = harness.edge(b, d)
        assert_close(host["m"], part["m"].T, what="m")
        assert_close(host["x"], part["x"].T, what="x")
        assert_close(host["q"], part["q"], what="q")
        area_f, length_f = sphere._edge_factors(part)
        assert_close(host["area"], (area_f * part["x"]).T, what="edge_area_term")
        assert_close(host["length"], (length_f * part["m"]).T, what="edge_length_term")
        ref = _edge_reference(b, d)   # the mirror used for the extreme edges is the constraint's code
        assert_bitwise(np.ascontiguousarray(ref["x"]), np.ascontiguousarray(part["x"].T), "reference x")
        assert_bitwise(ref["q"], np.ascontiguousarray(part["q"]), "reference q")
        assert_close(host["half"], ref["half"], what="half_angle")
    # the perimeter from the header's half angles, summed per cell as the force kernel does
    b = np.repeat(u.T, 3, axis=0)
    d = u.T[state.vertex_neighbors.reshape(-1)]
    half = harness.edge(b, d)["half"]
    per = 2.0 * np.bincount(state.vertex_cells.reshape(-1), weights=half, minlength=state.n_cells)
    assert_close(per * state.radius[state.cell_replica], geom.perimeter, rtol=1e-13, what="perimeter")


# ------------------------------------------------------------------------------------- on the GPU
GPU_SOURCE = r"""
#include "random_philox.cuh"
extern "C" __global__ void kat_philox(const unsigned int* ctr, const unsigned int* key,
                                      const unsigned int* rounds, unsigned int* out, int n)
{
    int i = blockIdx.x * blockDim.x + threadIdx.x;
    if (i >= n) return;
    uint4 c = make_uint4(ctr[4 * i], ctr[4 * i + 1], ctr[4 * i + 2], ctr[4 * i + 3]);
    uint2 k = make_uint2(key[2 * i], key[2 * i + 1]);
    uint4 w = rounds[i] == 10u ? svm_philox4x32_10(c, k) : svm_philox4x32_R(rounds[i], c, k);
    out[4 * i] = w.x; out[4 * i + 1] = w.y; out[4 * i + 2] = w.z; out[4 * i + 3] = w.w;
}
extern "C" __global__ void kat_draws(unsigned int seed, unsigned int stream, unsigned long long timestep,
                                     const unsigned int* ids, int n, unsigned int count,
                                     double* uniform, double* normal, double* uniform2, double* normal2)
{
    int i = blockIdx.x * blockDim.x + threadIdx.x;
    if (i >= n) return;
    for (unsigned int j = 0; j < count; ++j) {
        uniform[i * count + j] = svm_uniform(seed, stream, timestep, ids[i], j);
        normal[i * count + j] = svm_normal(seed, stream, timestep, ids[i], j);
    }
    for (unsigned int b = 0; 2 * b < count; ++b) {
        double u0, u1, z0, z1;
        svm_uniform2(seed, stream, timestep, ids[i], b, &u0, &u1);
        svm_normal2(seed, stream, timestep, ids[i], b, &z0, &z1);
        uniform2[i * count + 2 * b] = u0;
        normal2[i * count + 2 * b] = z0;
        if (2 * b + 1 < count) { uniform2[i * count + 2 * b + 1] = u1; normal2[i * count + 2 * b + 1] = z1; }
    }
}
"""


@pytest.mark.gpu
def test_gpu_philox_known_answers_and_streams():
    """The same known answers and streams from the header compiled by NVRTC for the device, where
    the high product word is __umulhi: words and uniforms bitwise, normals within a few ulp
    (docs/random.md measured <= 3 ulp on an H200)."""
    import cupy as cp
    mod = cp.RawModule(code=GPU_SOURCE, options=("-std=c++17", f"-I{PACKAGE}"))
    ctr = cp.asarray([k[1] for k in KAT], dtype=cp.uint32)
    key = cp.asarray([k[2] for k in KAT], dtype=cp.uint32)
    rounds = cp.asarray([k[0] for k in KAT], dtype=cp.uint32)
    out = cp.zeros((len(KAT), 4), dtype=cp.uint32)
    mod.get_function("kat_philox")((1,), (32,), (ctr, key, rounds, out, np.int32(len(KAT))))
    assert out.get().tolist() == [k[3] for k in KAT]

    ids = cp.asarray(IDS)
    for seed, stream in KEYS:
        for t in TIMESTEPS:
            what = f"seed={seed} stream={stream} timestep={t:#x}"
            bufs = [cp.zeros((len(IDS), COUNT)) for _ in range(4)]
            mod.get_function("kat_draws")(((len(IDS) + 127) // 128,), (128,),
                                          (np.uint32(seed), np.uint32(stream), np.uint64(t), ids,
                                           np.int32(len(IDS)), np.uint32(COUNT), *bufs))
            uni, nor, uni2, nor2 = (b.get() for b in bufs)
            u = svr.uniform(seed, stream, t, IDS, COUNT)
            assert_bitwise(uni, u, "svm_uniform on the GPU " + what)
            assert_bitwise(uni2, u, "svm_uniform2 on the GPU " + what)
            z = svr.normal(seed, stream, t, IDS, COUNT)
            for got, name in ((nor, "svm_normal"), (nor2, "svm_normal2")):
                ulps = np.abs(got - z) / np.spacing(np.abs(z))
                assert ulps.max() <= NORMAL_ULP, f"{name} on the GPU {what}: {ulps.max():.1f} ulp"
