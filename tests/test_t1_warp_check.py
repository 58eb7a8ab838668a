"""The fused steps check a T1 candidate with a whole warp (t1_check_candidate_warp: the usual and the
turned placement's fold parts on their own lanes); t1_check checks it in one thread
(t1_check_candidate). Both must decide the same for every candidate: kept or refused, turned or not,
and the same claims. Every edge of a jittered tiling is made a candidate (t1_detect_vertex with no
length limit) and checked both ways at new lengths from short to long enough that many placements
fold, so every branch is taken: kept usual, kept turned, refused.
"""
from pathlib import Path

import numpy as np
import pytest

import spherevm as svm

PACKAGE = Path(svm.__file__).parent

SOURCE = r"""
#include "plugins/updaters/t1_pass.cuh"

// Every edge u < v of replica 0 as a candidate: t1_detect_vertex with no length limit.
extern "C" __global__ void list_edges(const double* pos, const int* vn, const int* vc, const double* size, int nv,
                                      int* count, int* cand, double* len, int capacity)
{
    int u = blockIdx.x * blockDim.x + threadIdx.x;
    if (u < nv) t1_detect_vertex(pos, vn, vc, Surface::size(size, 0), 1e300, false, 0, u, count, cand, len, capacity);
}

// Each candidate's check at the new length `full`: verdict[i] = 0 refused, 1 kept usual, 2 kept turned.
// by_warp: a warp a candidate (t1_check_candidate_warp), else a thread a candidate (t1_check_candidate).
extern "C" __global__ void check_all(const double* pos, const int* vn, const int* sides, const int* cell_vertices,
                                     int max_sides, const double* size, double full, int* claim, int* cand, int n,
                                     int by_warp, int untangle, int* verdict)
{
    long t = (long)blockIdx.x * blockDim.x + threadIdx.x;
    long i = by_warp ? t >> 5 : t;
    if (i >= n) return;   // a whole warp leaves together when by_warp
    int* e = cand + i * CAND_INTS;
    Surface::Size s = Surface::size(size, 0);
    bool kept = by_warp ? t1_check_candidate_warp(pos, vn, sides, cell_vertices, max_sides, s, full, untangle, claim, e)
                        : t1_check_candidate(pos, vn, sides, cell_vertices, max_sides, s, full, untangle, claim, e);
    if (!by_warp || (threadIdx.x & 31) == 0) verdict[i] = kept ? 1 + e[12] : 0;
}
"""


def jittered(surface, n_cells, seed):
    """A tiling whose vertices are moved by a good part of an edge, so corners invert and cells fold."""
    tiling = svm.init.random_planar_tiling if surface == "plane" else svm.init.random_tiling
    state = tiling(n_cells, seed=seed)
    rng = np.random.default_rng(seed)
    pos = np.asarray(state.positions, dtype=float).copy()
    edge = np.sqrt(float(np.mean(state.mean_cell_area)))
    pos += 0.25 * edge * rng.standard_normal(pos.shape)
    if surface == "plane":
        pos[:, 2] = 0.0
    else:
        pos *= (np.asarray(state.radius)[0] / np.linalg.norm(pos, axis=1))[:, None]
    return state, pos, edge


@pytest.mark.gpu
@pytest.mark.parametrize("surface", ["sphere", "plane"])
@pytest.mark.parametrize("untangle", [0, 1])
def test_a_warp_decides_every_candidate_as_one_thread_does(surface, untangle):
    import cupy as cp
    state, pos, edge = jittered(surface, 300, seed=5)
    module = cp.RawModule(code=state.constraint.device_surface().prelude + SOURCE, options=("-std=c++17", f"-I{PACKAGE}"))
    size = cp.asarray(np.asarray(state.box if surface == "plane" else state.radius, dtype=float))
    pos = cp.asarray(pos)
    vn, vc = cp.asarray(state.vertex_neighbors, dtype=cp.int32), cp.asarray(state.vertex_cells, dtype=cp.int32)
    table = cp.asarray(state.cell_vertices, dtype=cp.int32)
    sides = cp.asarray(state.cell_sides, dtype=cp.int32)
    nv = state.n_vertices
    capacity = 3 * nv // 2
    count = cp.zeros(1, dtype=cp.int32)
    cand = cp.zeros(capacity * 13, dtype=cp.int32)
    length = cp.zeros(capacity)
    module.get_function("list_edges")(((nv + 127) // 128,), (128,),
                                      (pos, vn, vc, size, np.int32(nv), count, cand, length, np.int32(capacity)))
    n = int(count.get()[0])
    assert n == capacity, "every edge listed once"
    totals = np.zeros(3, dtype=int)
    for factor in (0.05, 0.5, 1.0, 2.0, 4.0):
        out = []
        for by_warp in (0, 1):
            claim = cp.full(state.n_cells, 2**31 - 1, dtype=cp.int32)
            verdict = cp.full(n, -1, dtype=cp.int32)
            threads = 32 * n if by_warp else n
            module.get_function("check_all")(((threads + 127) // 128,), (128,),
                                             (pos, vn, sides, table, np.int32(state.max_sides), size,
                                              np.float64(factor * edge), claim, cand.copy(), np.int32(n),
                                              np.int32(by_warp), np.int32(untangle), verdict))
            out.append((verdict.get(), claim.get()))
        (one, claim_one), (warp, claim_warp) = out
        assert (one >= 0).all(), "every candidate decided"
        assert np.array_equal(one, warp), f"new length {factor} edges: the warp and the thread decide alike"
        assert np.array_equal(claim_one, claim_warp), f"new length {factor} edges: the same claims"
        totals += np.bincount(one, minlength=3)
    assert (totals > 20).all(), f"refused, kept usual and kept turned all reached: {totals}"
