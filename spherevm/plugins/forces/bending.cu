// Bending between neighbouring cells on the sphere: the CUDA path of bending.py.
// E_b = B_r sum over neighbouring cell pairs (i, j) of (1 - n_i.n_j) = B_r |n_i - n_j|^2 / 2.
// Alone: three kernels (normals per cell; energy and dE/da per cell over its neighbours; forces per
// vertex). With the vertex model (Bending.combined): its two kernels with the terms below fused in
// (vertex_model.cuh), and the per-cell kernel between them adding to its energies.
#include "plugins/forces/vertex_model.cuh"

// Per cell: the doubled area vector A = 2 a = sum over the corners (x_b - x_0) x (x_d - x_b), x_0
// the cell's first vertex (the same terms as Sphere.cell_geometry's corners), its unit normal and
// 1/|A|.
struct BendingCell {
    double* normal;
    double* inv_area;          // 1 / |2 a|
    vec3 x0, A;
    __device__ BendingCell(double* normal_, double* inv_area_) : normal(normal_), inv_area(inv_area_) {}
    __device__ __forceinline__ void cell_start(vec3 x) { x0 = x; A = v3(0.0, 0.0, 0.0); }
    __device__ __forceinline__ void cell_corner(vec3 xb, vec3 xd) { A = A + cross3(xb - x0, xd - xb); }
    __device__ __forceinline__ void cell_end(long c) {
        double s = rsqrt(dot3(A, A));
        store3(normal, c, s * A);
        inv_area[c] = s;
    }
};

// Per vertex: the gradient of the energy through the area vectors of its three cells. a_c moves
// with x_v by (x_next - x_prev) x / 2 per corner; with w_c = (dE/da_c) / 2 and e_j = x_{n_j} - x_v
// the sum over the corners is sum_j e_j x (w[slot j] - w[slot j-1]) (as Sphere.shape_gradient).
// add_gradient scales it to the vertex model's unit-sphere terms (multiplied by 1/|x| at the end).
struct BendingVertex {
    const double* w;
    vec3 wc[3], G;
    __device__ explicit BendingVertex(const double* w_) : w(w_) {}
    __device__ __forceinline__ void vertex_start(const int* cells) {
        for (int k = 0; k < 3; ++k) wc[k] = load3(w, cells[k]);
        G = v3(0.0, 0.0, 0.0);
    }
    __device__ __forceinline__ void vertex_edge(int j, vec3 e) { G = G + cross3(e, wc[j] - wc[(j + 2) % 3]); }
    __device__ __forceinline__ void add_gradient(vec3& g, vec3 x) const { g = g + norm3(x) * G; }
};

// One thread per cell: its normal and 1/|2a| (bending alone).
extern "C" __global__ void bending_cell_normals(
    const double* __restrict__ pos, const int* __restrict__ cell_vertices, const int* __restrict__ cell_sides,
    int n_cells, int max_sides, double* __restrict__ normal, double* __restrict__ inv_area)
{
    long c = (long)blockIdx.x * blockDim.x + threadIdx.x;
    if (c >= n_cells) return;
    const int* row = cell_vertices + c * (long)max_sides;
    int n = cell_sides[c];
    BendingCell cell(normal, inv_area);
    vec3 xb = load3(pos, row[0]);
    cell.cell_start(xb);
    for (int i = 1; i < n; ++i) {          // the closing corner (x_{n-1}, x_0) adds (x_{n-1} - x_0) x (x_0 - x_{n-1}) = 0
        vec3 xd = load3(pos, row[i]);
        cell.cell_corner(xb, xd);
        xb = xd;
    }
    cell.cell_end(c);
}

// The cell across the edge that leaves vertex v of cell c (counter-clockwise): corner (v, s) with
// vertex_cells[v, s] == c runs along that edge, which borders vertex_cells[v, s - 1].
__device__ __forceinline__ int cell_across(const int* __restrict__ vertex_cells, int v, long c)
{
    const int* vc = vertex_cells + 3 * (long)v;
    int s = vc[0] == c ? 0 : (vc[1] == c ? 1 : 2);
    return vc[(s + 2) % 3];
}

// One thread per cell, over its neighbours, found by walking its edges (from the State's arrays, so
// nothing to rebuild after T1 flips; a neighbour across two edges counts once, as in bending.py's
// pair list): the cell's energy (half of each pair, B/4 |n_i - n_j|^2), the per-replica sum, and
// w_i = (dE/da_i) / 2 = B (s - (s.n_i) n_i) / |2 a_i| with s = sum_j (n_i - n_j). ADD: the energies
// are added to what the vertex model's cell kernel wrote (fused), else they are stored.
template <bool ADD>
__device__ __forceinline__ void bending_cell_terms_body(
    const double* __restrict__ normal, const double* __restrict__ inv_area, const int* __restrict__ cell_vertices,
    const int* __restrict__ cell_sides, const int* __restrict__ vertex_cells, int n_cells, int max_sides,
    const int* __restrict__ cell_replica, const double* __restrict__ B, double* __restrict__ w,
    double* __restrict__ cell_energy, double* __restrict__ replica_energy)
{
    long c = (long)blockIdx.x * blockDim.x + threadIdx.x;
    int rep = -1;
    double e = 0.0;
    if (c < n_cells) {
        rep = cell_replica[c];
        double Br = B[rep];
        const int* row = cell_vertices + c * (long)max_sides;
        int n = cell_sides[c];
        vec3 ni = load3(normal, c);
        vec3 s = v3(0.0, 0.0, 0.0);
        double sq = 0.0;
        for (int k = 0; k < n; ++k) {
            int j = cell_across(vertex_cells, row[k], c);
            bool counted = j == c;
            for (int i = 0; i < k && !counted; ++i) counted = cell_across(vertex_cells, row[i], c) == j;
            if (counted) continue;
            vec3 d = ni - load3(normal, j);
            sq += dot3(d, d);
            s = s + d;
        }
        e = 0.25 * Br * sq;
        cell_energy[c] = ADD ? cell_energy[c] + e : e;
        vec3 t = s - dot3(s, ni) * ni;
        store3(w, c, (Br * inv_area[c]) * t);
    }
    segmented_block_add(e, rep, replica_energy);
}

extern "C" __global__ void bending_cell_terms(
    const double* __restrict__ normal, const double* __restrict__ inv_area, const int* __restrict__ cell_vertices,
    const int* __restrict__ cell_sides, const int* __restrict__ vertex_cells, int n_cells, int max_sides,
    const int* __restrict__ cell_replica, const double* __restrict__ B, double* __restrict__ w,
    double* __restrict__ cell_energy, double* __restrict__ replica_energy)
{
    bending_cell_terms_body<false>(normal, inv_area, cell_vertices, cell_sides, vertex_cells, n_cells, max_sides,
                                   cell_replica, B, w, cell_energy, replica_energy);
}

extern "C" __global__ void bending_cell_terms_add(
    const double* __restrict__ normal, const double* __restrict__ inv_area, const int* __restrict__ cell_vertices,
    const int* __restrict__ cell_sides, const int* __restrict__ vertex_cells, int n_cells, int max_sides,
    const int* __restrict__ cell_replica, const double* __restrict__ B, double* __restrict__ w,
    double* __restrict__ cell_energy, double* __restrict__ replica_energy)
{
    bending_cell_terms_body<true>(normal, inv_area, cell_vertices, cell_sides, vertex_cells, n_cells, max_sides,
                                  cell_replica, B, w, cell_energy, replica_energy);
}

// One thread per vertex, no atomics: minus the gradient through its three cells, projected on the
// tangent plane at v (bending alone).
extern "C" __global__ void bending_vertex_forces(
    const double* __restrict__ pos, const int* __restrict__ vertex_neighbors, const int* __restrict__ vertex_cells,
    int n_vertices, const double* __restrict__ w, double* __restrict__ forces)
{
    long v = (long)blockIdx.x * blockDim.x + threadIdx.x;
    if (v >= n_vertices) return;
    vec3 x = load3(pos, v);
    BendingVertex vertex(w);
    vertex.vertex_start(vertex_cells + 3 * v);
    for (int j = 0; j < 3; ++j) vertex.vertex_edge(j, load3(pos, vertex_neighbors[3 * v + j]) - x);
    vec3 g = vertex.G;
    g = g - (dot3(g, x) / dot3(x, x)) * x;
    store3(forces, v, -g);
}

// The vertex model's kernels with the bending terms fused in (Bending.combined).
extern "C" __global__ void vm_bending_cell_geometry(
    const double* __restrict__ pos, const int* __restrict__ cell_vertices, const int* __restrict__ cell_sides,
    const int* __restrict__ cell_replica, const double* __restrict__ radius, int n_cells, int max_sides,
    const double* __restrict__ kA, const double* __restrict__ kP, const double* __restrict__ A0,
    const double* __restrict__ P0, double* __restrict__ coef, double* __restrict__ cell_energy,
    double* __restrict__ replica_energy, double* __restrict__ normal, double* __restrict__ inv_area)
{
    BendingCell cell(normal, inv_area);
    vm_cell_geometry_body(pos, cell_vertices, cell_sides, cell_replica, radius, n_cells, max_sides, kA, kP, A0, P0,
                          coef, cell_energy, replica_energy, cell);
}

extern "C" __global__ void vm_bending_vertex_forces(
    const double* __restrict__ pos, const int* __restrict__ vertex_neighbors, const int* __restrict__ vertex_cells,
    int n_vertices, const double* __restrict__ coef, const double* __restrict__ w, double* __restrict__ forces)
{
    BendingVertex vertex(w);
    vm_vertex_forces_body(pos, vertex_neighbors, vertex_cells, n_vertices, coef, forces, vertex);
}
