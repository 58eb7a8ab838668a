// Bending between neighbouring cells on the sphere: the CUDA path of bending.py.
// E_b = B_r sum over neighbouring cell pairs (i, j) of (1 - n_i.n_j) = B_r |n_i - n_j|^2 / 2.
#include "geometry/sphere.cuh"
#include "device_common.cuh"

// One thread per cell: the area vector a = 1/2 sum_k r_k x r_{k+1}, r_k = x_k - x_0 relative to the
// cell's first vertex (the same terms as bending.py's corners), its unit normal and 1/|a|.
extern "C" __global__ void bending_cell_normals(
    const double* __restrict__ pos, const int* __restrict__ cell_vertices, const int* __restrict__ cell_sides,
    int n_cells, int max_sides, double* __restrict__ normal, double* __restrict__ inv_area)
{
    long c = (long)blockIdx.x * blockDim.x + threadIdx.x;
    if (c >= n_cells) return;
    const int* row = cell_vertices + c * (long)max_sides;
    int n = cell_sides[c];
    vec3 x0 = load3(pos, row[0]);
    vec3 a = v3(0.0, 0.0, 0.0);
    vec3 b = load3(pos, row[1]) - x0;
    for (int i = 1; i + 1 < n; ++i) {
        vec3 d = load3(pos, row[i + 1]) - x0;
        a = a + cross3(b, d);
        b = d;
    }
    double s = rsqrt(dot3(a, a));            // 1 / |2 a|
    store3(normal, c, s * a);
    inv_area[c] = 2.0 * s;
}

// One thread per cell, over its neighbours (CSR start/neighbors, each pair listed from both ends):
// the cell's energy (half of each pair, B/4 |n_i - n_j|^2), the per-replica sum, and
// g_i = dE/da_i = B (s - (s.n_i) n_i) / |a_i| with s = sum_j (n_i - n_j).
extern "C" __global__ void bending_cell_terms(
    const double* __restrict__ normal, const double* __restrict__ inv_area, const int* __restrict__ start,
    const int* __restrict__ neighbors, const int* __restrict__ cell_replica, const double* __restrict__ B,
    int n_cells, double* __restrict__ g, double* __restrict__ cell_energy, double* __restrict__ replica_energy)
{
    long c = (long)blockIdx.x * blockDim.x + threadIdx.x;
    int rep = -1;
    double e = 0.0;
    if (c < n_cells) {
        rep = cell_replica[c];
        double Br = B[rep];
        vec3 ni = load3(normal, c);
        vec3 s = v3(0.0, 0.0, 0.0);
        double sq = 0.0;
        for (int k = start[c]; k < start[c + 1]; ++k) {
            vec3 d = ni - load3(normal, neighbors[k]);
            sq += dot3(d, d);
            s = s + d;
        }
        e = 0.25 * Br * sq;
        cell_energy[c] = e;
        vec3 t = s - dot3(s, ni) * ni;
        store3(g, c, (Br * inv_area[c]) * t);
    }
    segmented_block_add(e, rep, replica_energy);
}

// One thread per vertex, no atomics: corner (v, k) lies in cell vertex_cells[v, k], whose boundary
// runs from the previous vertex vertex_neighbors[v, k + 1] through v to vertex_neighbors[v, k], so
// da_c/dx_v applied to g_c is (x_next - x_prev) x g_c / 2; minus the sum, projected on the tangent
// plane at v.
extern "C" __global__ void bending_vertex_forces(
    const double* __restrict__ pos, const int* __restrict__ vertex_neighbors, const int* __restrict__ vertex_cells,
    int n_vertices, const double* __restrict__ g, double* __restrict__ forces)
{
    long v = (long)blockIdx.x * blockDim.x + threadIdx.x;
    if (v >= n_vertices) return;
    vec3 x = load3(pos, v);
    vec3 r[3];
    for (int k = 0; k < 3; ++k) r[k] = load3(pos, vertex_neighbors[3 * v + k]) - x;
    vec3 grad = v3(0.0, 0.0, 0.0);
    for (int k = 0; k < 3; ++k) {
        vec3 gc = load3(g, vertex_cells[3 * v + k]);
        grad = grad + cross3(r[k] - r[(k + 1) % 3], gc);
    }
    grad = 0.5 * grad;
    grad = grad - (dot3(grad, x) / dot3(x, x)) * x;
    store3(forces, v, -grad);
}
