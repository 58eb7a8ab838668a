// Whether a T1 flip would fold the network, for t1_detect (t1.cu): the CUDA twin of
// spherevm.folding.t1_fold_level, the same arithmetic in the same order on the surface the module is
// compiled for (geometry/surface.cuh; compiled on the CPU for both surfaces and compared with
// NumPy by tests/test_t1_fold.py). Names as in topology.t1_cells:
// C1 = (.., a, u, v, d, ..), C2 = (.., c, v, u, b, ..), C3 = (.., b, u, a, ..), C4 = (.., d, v, c, ..);
// after the flip X = v sits at px on the C1 side with row (Y, d, a), Y = u at py with row (X, b, c).
#pragma once
#include "geometry/surface.cuh"

// An inverted corner at w: its edges to n0, n1, n2 (its row, counter-clockwise in a valid network)
// turn clockwise about the normal, i.e. two of the three turns between consecutive edges are negative.
__device__ __forceinline__ bool t1_inverted(vec3 w, vec3 n0, vec3 n1, vec3 n2, Surface::Size s)
{
    vec3 nrm = Surface::normal(w);
    vec3 e0 = Surface::delta(w, n0, s), e1 = Surface::delta(w, n1, s), e2 = Surface::delta(w, n2, s);
    int negative = (dot3(nrm, cross3(e0, e1)) < 0.0 ? 1 : 0) + (dot3(nrm, cross3(e1, e2)) < 0.0 ? 1 : 0)
                 + (dot3(nrm, cross3(e2, e0)) < 0.0 ? 1 : 0);
    return negative >= 2;
}

// w's row now (moved < 0), or with its neighbour `moved` at `at`: is the corner inverted?
__device__ __forceinline__ bool t1_row_inverted(const double* pos, const int* vn, int w, int moved, vec3 at,
                                                Surface::Size s)
{
    vec3 n[3];
    for (int k = 0; k < 3; ++k) n[k] = vn[3 * w + k] == moved ? at : load3(pos, vn[3 * w + k]);
    return t1_inverted(load3(pos, w), n[0], n[1], n[2], s);
}

// A cell's signed areas now and after the flip, in one walk of its row (each position loaded once:
// the check is one thread's chain of dependent loads). Now: the fan about its first vertex over its
// edges, in row order. After, as the force will measure it: the fan about its first vertex after
// the flip (`moved` if the row starts with u or v) over its edges that do not touch u or v, in row
// order, then its new edges along the chain ends[0..m).
__device__ __forceinline__ void t1_cell_areas(const double* pos, const int* row, int n, int u, int v, vec3 moved,
                                              const vec3* ends, int m, Surface::Size s, double* now, double* after)
{
    int p = row[0];
    vec3 first = load3(pos, p), xp = first;
    vec3 apex = p == u || p == v ? moved : first;
    double a_now = 0.0, a_after = 0.0;
    for (int j = 0; j < n; ++j) {
        int q = row[j + 1 < n ? j + 1 : 0];
        vec3 xq = j + 1 < n ? load3(pos, q) : first;
        a_now += Surface::triangle_area(first, xp, xq, s);
        if (!(p == u || p == v || q == u || q == v)) a_after += Surface::triangle_area(apex, xp, xq, s);
        p = q;
        xp = xq;
    }
    for (int k = 0; k + 1 < m; ++k) a_after += Surface::triangle_area(apex, ends[k], ends[k + 1], s);
    *now = a_now;
    *after = a_after;
}

#define T1_CLEAN 0      // folding.CLEAN, INVERTED, FOLDS
#define T1_INVERTED 1
#define T1_FOLDS 2

// folding.t1_fold_level of flipping u-v with its vertices at px, py: T1_FOLDS if one of the four
// cells would have area <= 0, or their areas would not add up to what they did, or a corner of u,
// v, a, b, c, d would be inverted that was not; T1_INVERTED if only corners inverted before stay
// so; T1_CLEAN otherwise.
__device__ __forceinline__ int t1_fold_level(const double* pos, const int* vn, const int* cell_vertices,
                                             const int* sides, int max_sides, int u, int v, int a, int b, int c,
                                             int d, int C1, int C2, int C3, int C4, vec3 px, vec3 py,
                                             Surface::Size s)
{
    vec3 pa = load3(pos, a), pb = load3(pos, b), pc = load3(pos, c), pd = load3(pos, d);
    vec3 e1[3] = {pa, px, pd}, e2[3] = {pc, py, pb}, e3[4] = {pb, py, px, pa}, e4[4] = {pd, px, py, pc};
    const int* row1 = cell_vertices + (long)C1 * max_sides;
    const int* row2 = cell_vertices + (long)C2 * max_sides;
    const int* row3 = cell_vertices + (long)C3 * max_sides;
    const int* row4 = cell_vertices + (long)C4 * max_sides;
    double n1, n2, n3, n4, a1, a2, a3, a4;
    t1_cell_areas(pos, row1, sides[C1], u, v, px, e1, 3, s, &n1, &a1);
    t1_cell_areas(pos, row2, sides[C2], u, v, py, e2, 3, s, &n2, &a2);
    t1_cell_areas(pos, row3, sides[C3], u, v, py, e3, 4, s, &n3, &a3);
    t1_cell_areas(pos, row4, sides[C4], u, v, px, e4, 4, s, &n4, &a4);
    if (!(a1 > 0.0) || !(a2 > 0.0) || !(a3 > 0.0) || !(a4 > 0.0)) return T1_FOLDS;
    double before = ((n1 + n2) + n3) + n4;
    if (!(fabs(((a1 + a2) + a3) + a4 - before) < Surface::half_area(s))) return T1_FOLDS;
    bool now[6] = {t1_row_inverted(pos, vn, v, -1, px, s), t1_row_inverted(pos, vn, u, -1, py, s),
                   t1_row_inverted(pos, vn, a, -1, px, s), t1_row_inverted(pos, vn, d, -1, px, s),
                   t1_row_inverted(pos, vn, b, -1, py, s), t1_row_inverted(pos, vn, c, -1, py, s)};
    bool after[6] = {t1_inverted(px, py, pd, pa, s), t1_inverted(py, px, pb, pc, s),
                     t1_row_inverted(pos, vn, a, u, px, s), t1_row_inverted(pos, vn, d, v, px, s),
                     t1_row_inverted(pos, vn, b, u, py, s), t1_row_inverted(pos, vn, c, v, py, s)};
    int level = T1_CLEAN;
    for (int i = 0; i < 6; ++i) {
        if (after[i] && !now[i]) return T1_FOLDS;
        if (after[i]) level = T1_INVERTED;
    }
    return level;
}
