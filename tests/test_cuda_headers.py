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
from spherevm.constraints import plane as cplane
from spherevm.constraints import sphere as csphere
from spherevm.geometry import sphere as geo
from spherevm.plugins.forces import VertexModel

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

    # ---- the plane, and both surfaces through geometry/surface.cuh (what the kernels call)
    @staticmethod
    def _i32(a):
        return np.ascontiguousarray(a, dtype=np.int32)

    @staticmethod
    def _f64(a):
        return np.ascontiguousarray(a, dtype=np.float64)

    def image_wrap(self, d, x, box):
        """minimum_image(d) and wrap_into_box(x), one box (n, 2) per point."""
        d, x, box = self._vec(d), self._vec(x), self._f64(np.broadcast_to(box, (len(d), 2)))
        image, wrapped = np.empty_like(d), np.empty_like(x)
        self.lib.h_plane_image_wrap(ctypes.c_long(len(d)), self._p(d), self._p(x), self._p(box), self._p(image),
                                    self._p(wrapped))
        return image, wrapped

    @staticmethod
    def _size(state):
        return np.ascontiguousarray(state.constraint.kernel_size(state), dtype=np.float64)

    def cells(self, surface, state):
        """Surface::cell_measures per cell: (area, perimeter, (area_unit, length_unit))."""
        n, cv = state.n_cells, self._i32(state.cell_vertices)
        area, per, units = np.empty(n), np.empty(n), np.empty((n, 2))
        getattr(self.lib, f"h_{surface}_cells")(
            ctypes.c_long(n), self._p(self._vec(state.positions)), self._p(cv), self._p(self._i32(state.cell_sides)),
            self._p(self._i32(state.cell_replica)), self._p(self._size(state)), ctypes.c_int(cv.shape[1]),
            self._p(area), self._p(per), self._p(units))
        return area, per, units

    def forces(self, surface, state, coef):
        """Surface::vertex_force per vertex for per-cell coefficients coef (n_cells, 2)."""
        out = np.empty((state.n_vertices, 3))
        getattr(self.lib, f"h_{surface}_forces")(
            ctypes.c_long(state.n_vertices), self._p(self._vec(state.positions)),
            self._p(self._i32(state.vertex_neighbors)), self._p(self._i32(state.vertex_cells)),
            self._p(self._i32(state.vertex_replica)), self._p(self._size(state)), self._p(self._f64(coef)),
            self._p(out))
        return out

    def edges(self, surface, state, u, v):
        """Surface::chord2 and Surface::edge_length of the pairs (u, v)."""
        u, v = self._i32(u), self._i32(v)
        rep = self._i32(state.vertex_replica[u])
        chord2, length = np.empty(len(u)), np.empty(len(u))
        getattr(self.lib, f"h_{surface}_edges")(
            ctypes.c_long(len(u)), self._p(self._vec(state.positions)), self._p(u), self._p(v), self._p(rep),
            self._p(self._size(state)), self._p(chord2), self._p(length))
        return chord2, length

    def project(self, surface, y, rep, size):
        """Surface::normal(y) and Surface::place(y, normal(y)) (P_N)."""
        y, rep, size = self._vec(y), self._i32(rep), self._f64(size)
        normal, placed = np.empty_like(y), np.empty_like(y)
        getattr(self.lib, f"h_{surface}_project")(ctypes.c_long(len(y)), self._p(y), self._p(rep), self._p(size),
                                                  self._p(normal), self._p(placed))
        return normal, placed

    def t1(self, surface, state, quad, full):
        """Surface::t1_positions of the flips quad (n, 6) = (u, v, a, b, c, d): new X = v and Y = u."""
        quad, full = self._i32(quad), self._f64(full)
        rep = self._i32(state.vertex_replica[quad[:, 0]])
        x, y = np.empty((len(quad), 3)), np.empty((len(quad), 3))
        getattr(self.lib, f"h_{surface}_t1")(ctypes.c_long(len(quad)), self._p(self._vec(state.positions)),
                                             self._p(quad), self._p(rep), self._p(self._size(state)), self._p(full),
                                             self._p(x), self._p(y))
        return x, y

    def cell_normals(self, surface, state):
        cv = self._i32(state.cell_vertices)
        out = np.empty((state.n_cells, 3))
        getattr(self.lib, f"h_{surface}_cell_normals")(ctypes.c_long(state.n_cells), self._p(self._vec(state.positions)),
                                                       self._p(cv), self._p(self._i32(state.cell_sides)),
                                                       self._p(self._i32(state.cell_replica)),
                                                       self._p(self._size(state)), ctypes.c_int(cv.shape[1]),
                                                       self._p(out))
        return out


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


# ------------------------------------------------------------------------------------- the plane
def test_header_minimum_image_and_wrap(harness):
    """minimum_image and wrap_into_box (geometry/plane.cuh) against plane.minimum_image and
    PeriodicPlane.project_normal, bitwise: displacements over many box lengths, exact half and
    one-and-a-half boxes (rint rounds half to even), points on the box edges, just below 0 (they
    round up to L and must come back to 0) and far outside."""
    rng = np.random.default_rng(11)
    n = 3000
    box = rng.uniform(0.5, 40.0, size=(n, 2))
    d = np.zeros((n, 3))
    d[:, :2] = rng.normal(size=(n, 2)) * box * 3
    x = np.zeros((n, 3))
    x[:, :2] = rng.uniform(-5, 5, size=(n, 2)) * box
    x[:, 2] = rng.normal(size=n)                       # P_N drops z
    k = np.arange(12)
    d[k, 0] = box[k, 0] * np.array([0.5, -0.5, 1.5, -1.5, 2.5, 0, -0.0, 1e-300, 0.5, 1, -1, 3])
    x[k, 1] = box[k, 1] * np.array([0, 1, -1e-17, -1e-300, 2, -3, 1 - 1e-16, 0.5, 1e6, -1e6, 1e-17, 7])
    image, wrapped = harness.image_wrap(d, x, box)
    ref_image = cplane.minimum_image(d[:, :2], box)
    ref_wrapped = cplane.PeriodicPlane().project_normal(x, box)
    assert_bitwise(image[:, :2].copy(), ref_image, "minimum_image")
    assert_bitwise(wrapped, ref_wrapped, "wrap_into_box")
    assert np.all(image[:, 2] == 0) and np.all(np.abs(image[:, :2]) <= box / 2)
    assert np.all(wrapped[:, :2] >= 0) and np.all(wrapped[:, :2] < box)
    assert wrapped[2, 1] == 0.0                        # -1e-17 L rounds up to L, taken to 0


def _planar():
    """Two planar replicas with different boxes; cells straddle the boundary."""
    state = svm.State.concatenate([svm.init.random_planar_tiling(200, seed=18),
                                   svm.init.random_planar_tiling(150, seed=3, box=(9.0, 16.0 + 2.0 / 3.0))])
    d = state.positions[state.vertex_neighbors] - state.positions[:, None]
    assert (np.abs(d[..., :2]) > state.box_np()[state.vertex_replica][:, None] / 2).sum() > 20
    return state


SURFACE_STATES = {"plane": _planar, "sphere": lambda: svm.init.random_tiling(300, replicas=2, seed=18)}


def assert_close_global(host, ref, rtol, what=""):
    """``max |host - ref| <= rtol max |ref|`` (forces and positions: a global scale, no cancellation)."""
    host, ref = np.asarray(host), np.asarray(ref)
    assert host.shape == ref.shape, what
    err = np.abs(host - ref).max()
    assert err <= rtol * np.abs(ref).max(), f"{what}: {err:.3g} against {np.abs(ref).max():.3g} (rtol {rtol:g})"


@pytest.mark.parametrize("surface", ["plane", "sphere"])
def test_header_cell_measures_match_numpy(harness, surface):
    """Surface::cell_measures (the force kernel's per-cell loop) against the constraint's
    cell_geometry: on the plane bit for bit (the same edges, running sums and slot-order sums)."""
    state = SURFACE_STATES[surface]()
    geom = state.constraint.cell_geometry(state)
    area, perimeter, units = harness.cells(surface, state)
    if surface == "plane":
        assert_bitwise(area, geom.area, "area")
        assert_bitwise(perimeter, geom.perimeter, "perimeter")
    assert_close(area, geom.area, rtol=RTOL, what="area")
    assert_close(perimeter, geom.perimeter, rtol=RTOL, what="perimeter")
    size = state.constraint.size_np(state)[state.cell_replica]
    expected = np.ones((state.n_cells, 2)) if surface == "plane" else np.stack([size ** 2, size], axis=1)
    assert_bitwise(units, expected, "area_unit, length_unit")
    if surface == "plane":   # the cells tile each box
        np.testing.assert_allclose(np.bincount(state.cell_replica, weights=area), state.box_np().prod(axis=1),
                                   rtol=1e-13)


@pytest.mark.parametrize("surface", ["plane", "sphere"])
def test_header_vertex_forces_match_numpy(harness, surface):
    """Surface::vertex_force against the constraint's shape_gradient, for random per-cell
    coefficients (areas and perimeters weighted independently) and for the vertex model's own, whose
    coefficients the cell loop makes (2 kA (A - A0) area_unit, 2 kP (P - P0) length_unit)."""
    state = SURFACE_STATES[surface]()
    con = state.constraint
    geom = con.cell_geometry(state)
    _, _, units = harness.cells(surface, state)
    rng = np.random.default_rng(7)
    for d_area, d_perimeter in ((rng.normal(size=state.n_cells), rng.normal(size=state.n_cells)),
                                (np.eye(state.n_cells)[5], np.zeros(state.n_cells)),
                                (np.zeros(state.n_cells), np.eye(state.n_cells)[9])):
        coef = np.stack([d_area * units[:, 0], d_perimeter * units[:, 1]], axis=1)
        host, ref = harness.forces(surface, state, coef), -con.shape_gradient(state, geom, d_area, d_perimeter)
        if surface == "plane":
            assert_bitwise(host, ref, "vertex_force")
        assert_close_global(host, ref, rtol=RTOL, what="vertex_force")
    model = VertexModel.dimensionless(kr=1.0, p0=3.7)
    kA, kP, A0, P0 = model.parameters(state)
    area, perimeter, units = harness.cells(surface, state)
    coef = np.stack([2.0 * kA * (area - A0) * units[:, 0], 2.0 * kP * (perimeter - P0) * units[:, 1]], axis=1)
    ref = model.compute(state).forces
    assert_close_global(harness.forces(surface, state, coef), ref, rtol=1e-13, what="vertex-model forces")
    if surface == "plane":
        assert np.all(ref[:, 2] == 0)


@pytest.mark.parametrize("surface", ["plane", "sphere"])
def test_header_t1_edges_projection_and_normals(harness, surface):
    """Surface::chord2 and edge_length (T1's short-edge test) against T1.short_edges' chords and the
    constraint's edge_lengths; normal and place (P_N) against the constraint; cell_normal against
    cell_normals (the plane's are (0, 0, 1), bitwise)."""
    state = SURFACE_STATES[surface]()
    con = state.constraint
    u = np.repeat(np.arange(state.n_vertices), 3)
    v = state.vertex_neighbors.reshape(-1)
    chord2, length = harness.edges(surface, state, u, v)
    if surface == "plane":
        dd = con.displacement(state, u, v)
        assert_bitwise(chord2, (dd * dd).sum(axis=1), "chord2")
    else:
        dd = state.positions[u] - state.positions[v]
        assert_close(chord2, np.einsum("ij,ij->i", dd, dd), rtol=RTOL, what="chord2")
    assert_close(length, con.edge_lengths(state, u, v), rtol=RTOL, what="edge_length")

    rng = np.random.default_rng(3)
    rep = rng.integers(0, state.n_replicas, 500)
    size = con.size_np(state)
    y = state.positions[rng.integers(0, state.n_vertices, 500)] + rng.normal(scale=0.3, size=(500, 3))
    if surface == "plane":
        y[:50, :2] -= size[rep[:50]] * 1.5            # far outside the box
    normal, placed = harness.project(surface, y, rep, size)
    ref = con.project_normal(y, size[rep])
    assert_close(placed, ref, rtol=RTOL, what="place")
    assert_close(normal, con.normal(ref), rtol=RTOL, what="normal")
    normals = harness.cell_normals(surface, state)
    if surface == "plane":
        assert_bitwise(normals, con.cell_normals(state), "cell_normal")
    else:
        assert_close(normals, con.cell_normals(state), rtol=RTOL, what="cell_normal")


@pytest.mark.parametrize("surface", ["plane", "sphere"])
def test_header_t1_positions_match_t1_flip(harness, surface):
    """Surface::t1_positions (t1_apply's geometry) against topology.t1_flip, one flip at a time: edges
    across the periodic boundary, ordinary ones, and a zero-length edge (its direction comes from
    the neighbouring cells)."""
    state = SURFACE_STATES[surface]()
    con = state.constraint
    vn = state.vertex_neighbors
    d = con.displacement(state, np.arange(state.n_vertices).repeat(3), vn.reshape(-1)) if surface == "plane" else None
    corners = np.flatnonzero(np.arange(state.n_vertices).repeat(3) < vn.reshape(-1))
    if surface == "plane":
        raw = (state.positions[vn.reshape(-1), :2] - state.positions[np.arange(state.n_vertices).repeat(3), :2])
        across = corners[np.abs(raw[corners] - d[corners]).max(axis=1) > 0][:10]
        assert len(across) == 10
        corners = np.concatenate([across, corners[::37][:10]])
    else:
        corners = corners[::29][:20]
    zero = corners[-1]
    state.positions[vn.reshape(-1)[zero]] = state.positions[zero // 3]    # a zero-length edge
    scale = np.sqrt(state.mean_cell_area)
    for corner in corners:
        u, slot = np.array([corner // 3]), np.array([corner % 3])
        v, a, b, c, dd, *_ = svm.topology.t1_cells(vn, state.vertex_cells, u, slot)
        full = 0.37 * scale[state.vertex_replica[u]]
        x, y = harness.t1(surface, state, np.stack([u, v, a, b, c, dd], axis=1), full)
        flipped = state.copy()
        svm.topology.t1_flip(flipped, u, slot, full)
        ref = flipped.positions[np.concatenate([v, u])]
        got = np.concatenate([x, y])
        if surface == "plane":
            assert_bitwise(got, ref, f"t1_positions of corner {corner}")
        else:
            assert_close_global(got, ref, rtol=RTOL, what=f"t1_positions of corner {corner}")


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
