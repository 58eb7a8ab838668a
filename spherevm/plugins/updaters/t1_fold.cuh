// Whether a T1 flip would fold the network, for t1_detect (t1.cu): the CUDA twin of
// spherevm.folding.t1_fold_level (and of folding.inverted_edges: t1_bow_tie), the same arithmetic in
// the same order on the surface the module is compiled for (geometry/surface.cuh; compiled on the
// CPU for both surfaces and compared with NumPy by tests/test_t1_fold.py). Names as in
// topology.t1_cells:
// C1 = (.., a, u, v, d, ..), C2 = (.., c, v, u, b, ..), C3 = (.., b, u, a, ..), C4 = (.., d, v, c, ..);
// after the flip X = v sits at px on the C1 side with row (Y, d, a), Y = u at py with row (X, b, c).
#pragma once
#include "geometry/surface.cuh"

// An inverted corner at w: its edges to n0, n1, n2 (its row, counter-clockwise in a valid network)
// turn clockwise about the normal, i.e. two of the three turns between consecutive edges are negative.
__device__ __forceinline__ bool t1_inverted(vec3 w, vec3 n0, vec3 n1, vec3 n2, Surface::Size s)
{
    vec3 nrm = Surface::normal(w, s);
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
#define T1_FOLD_PARTS 10   // t1_fold_part: the four cells' areas, then the six corners

// One of t1_fold_level's independent terms (one lane each in the fused steps' warp-wide check,
// t1_pass.cuh): part k < 4 is cell C(k+1)'s signed area now and after the flip (now, after); part
// k >= 4 is whether corner k - 4 (of v, u, a, d, b, c) is inverted now and after it (inverted_now,
// inverted_after).
struct T1FoldPart {
    double now, after;
    bool inverted_now, inverted_after;
};

__device__ __forceinline__ T1FoldPart t1_fold_part(const double* pos, const int* vn, const int* cell_vertices,
                                                   const int* sides, int max_sides, int u, int v, int a, int b,
                                                   int c, int d, int C1, int C2, int C3, int C4, vec3 px, vec3 py,
                                                   Surface::Size s, int k)
{
    T1FoldPart part = {0.0, 0.0, false, false};
    if (k < 4) {
        vec3 pa = load3(pos, a), pb = load3(pos, b), pc = load3(pos, c), pd = load3(pos, d);
        const int cells[4] = {C1, C2, C3, C4};
        const vec3 apex = k == 0 || k == 3 ? px : py;
        vec3 ends[4];
        int m = k < 2 ? 3 : 4;
        if (k == 0) { ends[0] = pa; ends[1] = px; ends[2] = pd; }
        else if (k == 1) { ends[0] = pc; ends[1] = py; ends[2] = pb; }
        else if (k == 2) { ends[0] = pb; ends[1] = py; ends[2] = px; ends[3] = pa; }
        else { ends[0] = pd; ends[1] = px; ends[2] = py; ends[3] = pc; }
        t1_cell_areas(pos, cell_vertices + (long)cells[k] * max_sides, sides[cells[k]], u, v, apex, ends, m, s,
                      &part.now, &part.after);
        return part;
    }
    const int corner[6] = {v, u, a, d, b, c};
    const int w = corner[k - 4];
    part.inverted_now = t1_row_inverted(pos, vn, w, -1, px, s);
    if (k == 4) part.inverted_after = t1_inverted(px, py, load3(pos, d), load3(pos, a), s);
    else if (k == 5) part.inverted_after = t1_inverted(py, px, load3(pos, b), load3(pos, c), s);
    else part.inverted_after = t1_row_inverted(pos, vn, w, k == 6 || k == 8 ? u : v, k < 8 ? px : py, s);
    return part;
}

// t1_fold_level's verdict from its parts: the four cells' areas now (n) and after (a); new: a corner
// is inverted after the flip that was not before; inverted: one is after it.
__device__ __forceinline__ int t1_fold_verdict(const double* n, const double* a, bool new_inverted, bool inverted,
                                               Surface::Size s)
{
    if (!(a[0] > 0.0) || !(a[1] > 0.0) || !(a[2] > 0.0) || !(a[3] > 0.0)) return T1_FOLDS;
    double before = ((n[0] + n[1]) + n[2]) + n[3];
    if (!(fabs(((a[0] + a[1]) + a[2]) + a[3] - before) < Surface::half_area(s))) return T1_FOLDS;
    return new_inverted ? T1_FOLDS : (inverted ? T1_INVERTED : T1_CLEAN);
}

// folding.t1_fold_level of flipping u-v with its vertices at px, py: T1_FOLDS if one of the four
// cells would have area <= 0, or their areas would not add up to what they did, or a corner of u,
// v, a, b, c, d would be inverted that was not; T1_INVERTED if only corners inverted before stay
// so; T1_CLEAN otherwise. Its parts one after another (t1_check's one thread a candidate).
__device__ __forceinline__ int t1_fold_level(const double* pos, const int* vn, const int* cell_vertices,
                                             const int* sides, int max_sides, int u, int v, int a, int b, int c,
                                             int d, int C1, int C2, int C3, int C4, vec3 px, vec3 py,
                                             Surface::Size s)
{
    double n[4], after[4];
    bool new_inverted = false, inverted = false;
#pragma unroll
    for (int k = 0; k < T1_FOLD_PARTS; ++k) {
        T1FoldPart part = t1_fold_part(pos, vn, cell_vertices, sides, max_sides, u, v, a, b, c, d, C1, C2, C3, C4,
                                       px, py, s, k);
        if (k < 4) {
            n[k] = part.now;
            after[k] = part.after;
        } else {
            new_inverted = new_inverted || (part.inverted_after && !part.inverted_now);
            inverted = inverted || part.inverted_after;
        }
    }
    return t1_fold_verdict(n, after, new_inverted, inverted, s);
}

// (x cross y) . z as simplicity.arcs_cross forms it, without fused multiply-adds.
__device__ __forceinline__ double t1_triple(vec3 x, vec3 y, vec3 z)
{
    double p = __dmul_rn(__dsub_rn(__dmul_rn(x.y, y.z), __dmul_rn(x.z, y.y)), z.x);
    double q = __dmul_rn(__dsub_rn(__dmul_rn(x.z, y.x), __dmul_rn(x.x, y.z)), z.y);
    double r = __dmul_rn(__dsub_rn(__dmul_rn(x.x, y.y), __dmul_rn(x.y, y.x)), z.z);
    return __dadd_rn(__dadd_rn(p, q), r);
}

// simplicity.arcs_cross: the arc a b crosses c d properly (Surface::crossing_point coordinates).
__device__ __forceinline__ bool t1_arcs_cross(vec3 a, vec3 b, vec3 c, vec3 d)
{
    double s1 = t1_triple(a, b, c), s2 = t1_triple(a, b, d), s3 = t1_triple(c, d, a), s4 = t1_triple(c, d, b);
    return s1 * s2 < 0.0 && s3 * s4 < 0.0 && s2 * s3 > 0.0;
}

// folding.inverted_edges for the edge u v (neighbours a, b, c, d as t1_cells names them): the
// edges a u and v d cross, or c v and u b (a bow tie; never in a triangle, where they share a vertex).
__device__ __forceinline__ bool t1_bow_tie(const double* pos, vec3 pu, vec3 pv, int a, int b, int c, int d,
                                           Surface::Size s)
{
    vec3 U = Surface::crossing_point(pu, pu, s), V = Surface::crossing_point(pv, pu, s);
    if (a != d && t1_arcs_cross(Surface::crossing_point(load3(pos, a), pu, s), U, V,
                                Surface::crossing_point(load3(pos, d), pu, s)))
        return true;
    return b != c && t1_arcs_cross(Surface::crossing_point(load3(pos, c), pu, s), V, U,
                                   Surface::crossing_point(load3(pos, b), pu, s));
}
