// The bending force's device functions (bending.py: E_b = B_r sum over neighbouring cell pairs of
// |n_i - n_j|^2 / 2), shared by its general kernels (bending.cu) and its stage of the fused
// small-tissue steps (bending_stage.cuh), so the two give the same bits: every product and sum is
// rounded as written (vec3.cuh's *_rn), as the compiler would otherwise fuse multiply-adds by the
// code each is inlined into.
#pragma once
#include "plugins/forces/vertex_model.cuh"

// Cell c's unit normal and 1 / |A| from its doubled area vector A = 2 a = sum over the corners
// (x_b - x_0) x (x_d - x_b), x_0 the cell's first vertex (the same terms as Sphere.cell_geometry's
// corners; the closing corner adds (x_{n-1} - x_0) x (x_0 - x_{n-1}) = 0).
__device__ __forceinline__ void bending_cell_normal(const double* pos, const int* row, int n, vec3* normal,
                                                    double* inv_area)
{
    vec3 x0 = load3(pos, row[0]);
    vec3 xb = x0, A = v3(0.0, 0.0, 0.0);
    for (int i = 1; i < n; ++i) {
        vec3 xd = load3(pos, row[i]);
        A = add3_rn(A, cross3_rn(xb - x0, xd - xb));
        xb = xd;
    }
    double s = rsqrt(dot3_rn(A, A));
    *normal = mul3_rn(s, A);
    *inv_area = s;
}

// The cell across the edge that leaves vertex v of cell c (counter-clockwise): corner (v, s) with
// vertex_cells[v, s] == c runs along that edge, which borders vertex_cells[v, s - 1] (the three
// loaded at once).
__device__ __forceinline__ int cell_across(const int* vertex_cells, int v, long c)
{
    const int* vc = vertex_cells + 3 * (long)v;
    int c0 = vc[0], c1 = vc[1], c2 = vc[2];
    return c0 == c ? c2 : (c1 == c ? c0 : c1);
}

// Cells with at most this many sides keep their neighbours in registers (the loops unrolled), so
// that a neighbour across two edges is found without walking the edges again; larger cells do.
#define BENDING_REGISTER_SIDES 12

// Over the neighbours of cell c (row: its vertices, n of them), found by walking its edges (from
// the State's arrays, so nothing to rebuild after T1 flips; a neighbour across two edges counts
// once, as in bending.py's pair list), in the order of its edges: s = sum_j (n_i - n_j) (returned)
// and *sq = sum_j |n_i - n_j|^2. normal(j): cell j's unit normal; ni: cell c's.
template <class Normal>
__device__ __forceinline__ vec3 bending_neighbour_sum(const Normal& normal, const int* row, int n,
                                                      const int* vertex_cells, long c, vec3 ni, double* sq_out)
{
    vec3 s = v3(0.0, 0.0, 0.0);
    double sq = 0.0;
    auto add = [&](int j) { vec3 d = ni - normal(j); sq = __dadd_rn(sq, dot3_rn(d, d)); s = add3_rn(s, d); };
    if (n <= BENDING_REGISTER_SIDES) {
        int js[BENDING_REGISTER_SIDES];
#pragma unroll
        for (int k = 0; k < BENDING_REGISTER_SIDES; ++k)   // every neighbour first: loads that wait on none
            js[k] = k < n ? cell_across(vertex_cells, row[k], c) : (int)c;   // (c: never counted)
#pragma unroll
        for (int k = 0; k < BENDING_REGISTER_SIDES; ++k) {
            bool counted = js[k] == c;
#pragma unroll
            for (int i = 0; i < k; ++i) counted = counted || js[i] == js[k];
            if (!counted) add(js[k]);
        }
    } else {
        for (int k = 0; k < n; ++k) {
            int j = cell_across(vertex_cells, row[k], c);
            bool counted = j == c;
            for (int i = 0; i < k && !counted; ++i) counted = cell_across(vertex_cells, row[i], c) == j;
            if (!counted) add(j);
        }
    }
    *sq_out = sq;
    return s;
}

// w_i = (dE/da_i) / 2 = B (s - (s.n_i) n_i) / |2 a_i| (inv_area = 1 / |2 a_i|), from the neighbour sum s.
__device__ __forceinline__ vec3 bending_w(vec3 s, vec3 ni, double B, double inv_area)
{
    vec3 t = fma3_rn(-dot3_rn(s, ni), ni, s);
    return mul3_rn(__dmul_rn(B, inv_area), t);
}

// The energy's gradient at vertex v (position x) through the area vectors of its three cells, added
// to g in the units of the vertex model's unit-sphere terms (which are multiplied by 1/|x| at the
// end: |x| G). a_c moves with x_v by (x_next - x_prev) x / 2 per corner; with w_c = (dE/da_c) / 2
// and e_j = x_{n_j} - x_v the sum over the corners is G = sum_j e_j x (w[slot j] - w[slot j-1]) (as
// Sphere.shape_gradient). Each cell's w is loaded once (a loop over j loads each twice: 18 us more
// at 1e6 cells on an H200).
__device__ __forceinline__ void bending_gradient(vec3& g, const double* pos, const int* vertex_neighbors,
                                                 const int* vertex_cells, long v, vec3 x, const double* w)
{
    const int* vc = vertex_cells + 3 * v;
    const int* vn = vertex_neighbors + 3 * v;
    vec3 w0 = load3(w, vc[0]), w1 = load3(w, vc[1]), w2 = load3(w, vc[2]);
    vec3 G = cross3_rn(load3(pos, vn[0]) - x, w0 - w2);
    G = add3_rn(G, cross3_rn(load3(pos, vn[1]) - x, w1 - w0));
    G = add3_rn(G, cross3_rn(load3(pos, vn[2]) - x, w2 - w1));
    g = fma3_rn(sqrt(dot3_rn(x, x)), G, g);
}

// Bending alone: minus the gradient at vertex v through its three cells, projected on the tangent
// plane at v.
__device__ __forceinline__ vec3 bending_vertex_force(const double* pos, const int* vertex_neighbors,
                                                     const int* vertex_cells, long v, const double* w)
{
    vec3 x = load3(pos, v);
    double inv_rn = rsqrt(dot3_rn(x, x));
    vec3 u = mul3_rn(inv_rn, x);
    vec3 g = v3(0.0, 0.0, 0.0);
    bending_gradient(g, pos, vertex_neighbors, vertex_cells, v, x, w);
    g = fma3_rn(-dot3_rn(g, u), u, g);
    return -mul3_rn(inv_rn, g);
}
