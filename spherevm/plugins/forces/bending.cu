// Bending between neighbouring cells on the sphere: the CUDA path of bending.py.
// E_b = B_r sum over neighbouring cell pairs (i, j) of (1 - n_i.n_j) = B_r |n_i - n_j|^2 / 2.
// Alone: three kernels (normals per cell; energy and dE/da per cell over its neighbours; forces per
// vertex). With the vertex model (Bending.combined): its two kernels with the terms below fused in
// (vertex_model.cuh), and the per-cell kernel between them adding to its energies and summing both.
#include "plugins/forces/bending.cuh"

// What bending adds to the vertex model's kernels (vertex_model.cuh), and what its own kernels run
// (bending.cuh's functions): cell, the cell's unit normal and 1/|2a| (bending_cell_normal);
// add_gradient, the gradient through the area vectors of the vertex's three cells (bending_gradient).
struct BendingTerms {
    static constexpr bool sums_energy = true;   // the bending cell kernel sums both forces' cell energies
    double* normal;
    double* inv_area;          // 1 / |2 a|
    const double* w;
    __device__ __forceinline__ void cell(const double* __restrict__ pos, const int* __restrict__ row, int n,
                                         long c) const {
        vec3 m;
        bending_cell_normal(pos, row, n, &m, inv_area + c);
        store3(normal, c, m);
    }
    __device__ __forceinline__ void add_gradient(vec3& g, const double* __restrict__ pos,
                                                 const int* __restrict__ vertex_neighbors,
                                                 const int* __restrict__ vertex_cells, long v, vec3 x) const {
        bending_gradient(g, pos, vertex_neighbors, vertex_cells, v, x, w);
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

// On a surface of flat facets (Surface::coef_width 4, the implicit surfaces): cell c's unit normal
// and 1/|2a| from its vector area a (Surface::facet: nearest images on a periodic surface), one
// thread a cell; nothing elsewhere (the sphere's normals come with BendingTerms::cell).
template <class S>
__device__ __forceinline__ void bending_facet_normal(const double* pos, const int* row, int n, typename S::Size s,
                                                     double* normal, double* inv_area)
{
    if constexpr (S::coef_width == 4) {
        double A, P;
        vec3 a;
        S::facet(pos, row, n, s, &A, &P, &a);
        vec3 twice = 2.0 * a;
        double k = rsqrt(dot3(twice, twice));
        store3(normal, 0, k * twice);
        *inv_area = k;
    }
}

extern "C" __global__ void bending_facet_normals(
    const double* __restrict__ pos, const int* __restrict__ cell_vertices, const int* __restrict__ cell_sides,
    const int* __restrict__ cell_replica, const double* __restrict__ size, int n_cells, int max_sides,
    double* __restrict__ normal, double* __restrict__ inv_area)
{
    long c = (long)blockIdx.x * blockDim.x + threadIdx.x;
    if (c >= n_cells) return;
    bending_facet_normal<Surface>(pos, cell_vertices + c * (long)max_sides, cell_sides[c],
                                  Surface::size(size, cell_replica[c]), normal + 3 * c, inv_area + c);
}

// One thread per cell, over its neighbours (bending_neighbour_sum): the cell's energy (half of each
// pair, B/4 |n_i - n_j|^2), the per-replica sum, and w_i = (dE/da_i) / 2 (bending_w). ADD (fused):
// the energy is added to what the vertex model's cell kernel wrote and the sum is of both (that
// kernel leaves it here: one sum, not two, saves 30 us at 1e6 cells on an H200), else it is stored.
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
        vec3 ni = load3(normal, c);
        double sq;
        vec3 s = bending_neighbour_sum([&](int j) { return load3(normal, j); }, cell_vertices + c * (long)max_sides,
                                       cell_sides[c], vertex_cells, c, ni, &sq);
        e = 0.25 * Br * sq;
        if (ADD) e += cell_energy[c];
        cell_energy[c] = e;
        store3(w, c, bending_w(s, ni, Br, inv_area[c]));
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
    store3(forces, v, bending_vertex_force(pos, vertex_neighbors, vertex_cells, v, w));
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
