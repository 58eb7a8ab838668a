// Bending between neighbouring cells on the sphere: the CUDA path of bending.py.
// E_b = B_r sum over neighbouring cell pairs (i, j) of (1 - n_i.n_j) = B_r |n_i - n_j|^2 / 2.
// Alone: three kernels (normals per cell; energy and dE/da per cell over its neighbours; forces per
// vertex). With the vertex model (Bending.combined): its two kernels with the terms below fused in
// (vertex_model.cuh), and the per-cell kernel between them adding to its energies and summing both.
#include "plugins/forces/vertex_model.cuh"

// What bending adds to the vertex model's kernels (vertex_model.cuh), and what its own kernels run.
// cell: the doubled area vector A = 2 a = sum over the corners (x_b - x_0) x (x_d - x_b), x_0 the
// cell's first vertex (the same terms as Sphere.cell_geometry's corners; the closing corner adds
// (x_{n-1} - x_0) x (x_0 - x_{n-1}) = 0), its unit normal and 1/|A|.
// add_gradient: the gradient of the energy through the area vectors of the vertex's three cells. a_c
// moves with x_v by (x_next - x_prev) x / 2 per corner; with w_c = (dE/da_c) / 2 and e_j =
// x_{n_j} - x_v the sum over the corners is G = sum_j e_j x (w[slot j] - w[slot j-1]) (as
// Sphere.shape_gradient), added as |x| G to the vertex model's unit-sphere terms (which are
// multiplied by 1/|x| at the end).
struct BendingTerms {
    static constexpr bool sums_energy = true;   // the bending cell kernel sums both forces' cell energies
    double* normal;
    double* inv_area;          // 1 / |2 a|
    const double* w;
    __device__ __forceinline__ void cell(const double* __restrict__ pos, const int* __restrict__ row, int n,
                                         long c) const {
        vec3 x0 = load3(pos, row[0]);
        vec3 xb = x0, A = v3(0.0, 0.0, 0.0);
        for (int i = 1; i < n; ++i) {
            vec3 xd = load3(pos, row[i]);
            A = A + cross3(xb - x0, xd - xb);
            xb = xd;
        }
        double s = rsqrt(dot3(A, A));
        store3(normal, c, s * A);
        inv_area[c] = s;
    }
    __device__ __forceinline__ void add_gradient(vec3& g, const double* __restrict__ pos,
                                                 const int* __restrict__ vertex_neighbors,
                                                 const int* __restrict__ vertex_cells, long v, vec3 x) const {
        // each cell's w loaded once (a loop over j loads each twice: 18 us more at 1e6 cells on an H200)
        const int* vc = vertex_cells + 3 * v;
        const int* vn = vertex_neighbors + 3 * v;
        vec3 w0 = load3(w, vc[0]), w1 = load3(w, vc[1]), w2 = load3(w, vc[2]);
        vec3 G = cross3(load3(pos, vn[0]) - x, w0 - w2);
        G = G + cross3(load3(pos, vn[1]) - x, w1 - w0);
        G = G + cross3(load3(pos, vn[2]) - x, w2 - w1);
        g = g + norm3(x) * G;
    }
};

// One thread per cell: its normal and 1/|2a| (bending alone).
extern "C" __global__ void bending_cell_normals(
    const double* __restrict__ pos, const int* __restrict__ cell_vertices, const int* __restrict__ cell_sides,
    int n_cells, int max_sides, double* __restrict__ normal, double* __restrict__ inv_area)
{
    long c = (long)blockIdx.x * blockDim.x + threadIdx.x;
    if (c >= n_cells) return;
    BendingTerms terms = {normal, inv_area, nullptr};
    terms.cell(pos, cell_vertices + c * (long)max_sides, cell_sides[c], c);
}

// The cell across the edge that leaves vertex v of cell c (counter-clockwise): corner (v, s) with
// vertex_cells[v, s] == c runs along that edge, which borders vertex_cells[v, s - 1] (the three
// loaded at once).
__device__ __forceinline__ int cell_across(const int* __restrict__ vertex_cells, int v, long c)
{
    const int* vc = vertex_cells + 3 * (long)v;
    int c0 = vc[0], c1 = vc[1], c2 = vc[2];
    return c0 == c ? c2 : (c1 == c ? c0 : c1);
}

// Cells with at most this many sides keep their neighbours in registers (the loops unrolled), so
// that a neighbour across two edges is found without walking the edges again; larger cells do.
#define BENDING_REGISTER_SIDES 12

// One thread per cell, over its neighbours, found by walking its edges (from the State's arrays, so
// nothing to rebuild after T1 flips; a neighbour across two edges counts once, as in bending.py's
// pair list): the cell's energy (half of each pair, B/4 |n_i - n_j|^2), the per-replica sum, and
// w_i = (dE/da_i) / 2 = B (s - (s.n_i) n_i) / |2 a_i| with s = sum_j (n_i - n_j). ADD (fused): the
// energy is added to what the vertex model's cell kernel wrote and the sum is of both (that kernel
// leaves it here: one sum, not two, saves 30 us at 1e6 cells on an H200), else it is stored.
template <bool ADD>
__device__ __forceinline__ void bending_cell_terms_body(
    const double* __restrict__ normal, const double* __restrict__ inv_area, const int* __restrict__ cell_vertices,
    const int* __restrict__ cell_sides, const int* __restrict__ vertex_cells, int n_cells, int max_sides,
    const int* __restrict__ cell_replica, const double* __restrict__ B, double* __restrict__ w,
    double* __restrict__ cell_energy, double* __restrict__ replica_energy, SegmentSum sums)
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
        auto add = [&](int j) { vec3 d = ni - load3(normal, j); sq += dot3(d, d); s = s + d; };
        if (n <= BENDING_REGISTER_SIDES) {
            int js[BENDING_REGISTER_SIDES];
#pragma unroll
            for (int k = 0; k < BENDING_REGISTER_SIDES; ++k) {
                if (k < n) {
                    int j = js[k] = cell_across(vertex_cells, row[k], c);
                    bool counted = j == c;
#pragma unroll
                    for (int i = 0; i < k; ++i) counted = counted || js[i] == j;
                    if (!counted) add(j);
                }
            }
        } else {
            for (int k = 0; k < n; ++k) {
                int j = cell_across(vertex_cells, row[k], c);
                bool counted = j == c;
                for (int i = 0; i < k && !counted; ++i) counted = cell_across(vertex_cells, row[i], c) == j;
                if (!counted) add(j);
            }
        }
        e = 0.25 * Br * sq;
        if (ADD) e += cell_energy[c];
        cell_energy[c] = e;
        vec3 t = s - dot3(s, ni) * ni;
        store3(w, c, (Br * inv_area[c]) * t);
    }
    segment_sum(e, rep, sums, replica_energy);
}

// The cell kernel, storing (bending alone) or adding to the vertex model's energies and summing both (fused).
#define BENDING_CELL_TERMS_KERNEL(NAME, ADD)                                                                  \
    extern "C" __global__ void NAME(                                                                          \
        const double* __restrict__ normal, const double* __restrict__ inv_area,                               \
        const int* __restrict__ cell_vertices, const int* __restrict__ cell_sides,                            \
        const int* __restrict__ vertex_cells, int n_cells, int max_sides, const int* __restrict__ cell_replica, \
        const double* __restrict__ B, double* __restrict__ w, double* __restrict__ cell_energy,               \
        double* __restrict__ replica_energy, const int* __restrict__ cell_start, int n_replicas,              \
        double* __restrict__ scratch, unsigned int* __restrict__ count)                                       \
    {                                                                                                         \
        bending_cell_terms_body<ADD>(normal, inv_area, cell_vertices, cell_sides, vertex_cells, n_cells,      \
                                     max_sides, cell_replica, B, w, cell_energy, replica_energy,              \
                                     SegmentSum{cell_start, n_replicas, scratch, count});                     \
    }
BENDING_CELL_TERMS_KERNEL(bending_cell_terms, false)
BENDING_CELL_TERMS_KERNEL(bending_cell_terms_add, true)

// One thread per vertex, no atomics: minus the gradient through its three cells, projected on the
// tangent plane at v (bending alone).
extern "C" __global__ void bending_vertex_forces(
    const double* __restrict__ pos, const int* __restrict__ vertex_neighbors, const int* __restrict__ vertex_cells,
    int n_vertices, const double* __restrict__ w, double* __restrict__ forces)
{
    long v = (long)blockIdx.x * blockDim.x + threadIdx.x;
    if (v >= n_vertices) return;
    vec3 x = load3(pos, v);
    double inv_rn = rsqrt(dot3(x, x));
    vec3 u = inv_rn * x;
    vec3 g = v3(0.0, 0.0, 0.0);
    BendingTerms terms = {nullptr, nullptr, w};
    terms.add_gradient(g, pos, vertex_neighbors, vertex_cells, v, x);
    g = g - dot3(g, u) * u;
    store3(forces, v, -(inv_rn * g));
}

// The vertex model's kernels with the bending terms fused in (Bending.combined).
extern "C" __global__ void vm_bending_cell_geometry(
    const double* __restrict__ pos, const int* __restrict__ cell_vertices, const int* __restrict__ cell_sides,
    const int* __restrict__ cell_replica, const double* __restrict__ radius, int n_cells, int max_sides,
    const double* __restrict__ kA, const double* __restrict__ kP, const double* __restrict__ A0,
    const double* __restrict__ P0, double* __restrict__ coef, double* __restrict__ cell_energy,
    double* __restrict__ normal, double* __restrict__ inv_area)
{
    BendingTerms terms = {normal, inv_area, nullptr};   // no sum of energies here (sums_energy)
    vm_cell_geometry_body(pos, cell_vertices, cell_sides, cell_replica, radius, n_cells, max_sides, kA, kP, A0, P0,
                          coef, cell_energy, nullptr, SegmentSum{nullptr, 0, nullptr, nullptr}, terms);
}

// At most 80 registers (3 blocks of spherevm.device.BLOCK = 256 threads an SM; 92 unbounded, 2 blocks):
// 7% faster at 4,096 x 64 cells on an H200 despite a 56-byte spill.
extern "C" __global__ void __launch_bounds__(256, 3) vm_bending_vertex_forces(
    const double* __restrict__ pos, const int* __restrict__ vertex_neighbors, const int* __restrict__ vertex_cells,
    const int* __restrict__ vertex_replica, const double* __restrict__ radius, int n_vertices,
    const double* __restrict__ coef, const double* __restrict__ w, double* __restrict__ forces)
{
    BendingTerms terms = {nullptr, nullptr, w};
    vm_vertex_forces_body(pos, vertex_neighbors, vertex_cells, vertex_replica, radius, n_vertices, coef, forces,
                          terms);
}
