// Vertex-model energy and forces on the sphere: the CUDA path of vertex_model.py.
#include "geometry/sphere.cuh"
#include "device_common.cuh"

// One thread per cell: area, perimeter and fan apex (normalised vertex centroid), the cell's
// energy, the per-replica energy sum, and the two coefficients the vertex kernel needs:
// coef = (2 kA (A - A0) R^2, 2 kP (P - P0) R), so it gathers 5 doubles per corner.
extern "C" __global__ void vm_cell_geometry(
    const double* __restrict__ pos, const int* __restrict__ cell_vertices, const int* __restrict__ cell_sides,
    const int* __restrict__ cell_replica, const double* __restrict__ radius, int n_cells, int max_sides,
    const double* __restrict__ kA, const double* __restrict__ kP, const double* __restrict__ A0,
    const double* __restrict__ P0, double* __restrict__ coef, double* __restrict__ apex,
    double* __restrict__ cell_energy, double* __restrict__ replica_energy)
{
    long c = (long)blockIdx.x * blockDim.x + threadIdx.x;
    int rep = -1;
    double e = 0.0;
    if (c < n_cells) {
        rep = cell_replica[c];
        const int* row = cell_vertices + c * max_sides;
        int n = cell_sides[c];
        vec3 sum = v3(0.0, 0.0, 0.0);
        for (int i = 0; i < n; ++i) sum = sum + normalize3(load3(pos, row[i]));
        vec3 ap = normalize3(sum);
        vec3 first = normalize3(load3(pos, row[0]));
        vec3 cur = first;
        double P = 0.0, re = 1.0, im = 0.0;   // area = 2 arg(prod (den + i num)), valid below a hemisphere
        for (int i = 0; i < n; ++i) {
            vec3 nxt = i + 1 < n ? normalize3(load3(pos, row[i + 1])) : first;
            P += geodesic_length(cur, nxt);
            double num, den;
            solid_angle_parts(ap, cur, nxt, &num, &den);
            double t = re * den - im * num;
            im = re * num + im * den;
            re = t;
            cur = nxt;
        }
        double A = 2.0 * atan2(im, re);
        double R = radius[rep];
        A *= R * R;
        P *= R;
        double dA = A - A0[c], dP = P - P0[c];
        e = kA[c] * dA * dA + kP[c] * dP * dP;
        coef[2 * c] = 2.0 * kA[c] * dA * (R * R);
        coef[2 * c + 1] = 2.0 * kP[c] * dP * R;
        store3(apex, c, ap);
        cell_energy[c] = e;
    }
    segmented_block_add(e, rep, replica_energy);
}

// One thread per vertex: gather the area and perimeter gradients of its three corners (no
// atomics) and write minus the surface gradient of the energy.
extern "C" __global__ void vm_vertex_forces(
    const double* __restrict__ pos, const int* __restrict__ vertex_neighbors, const int* __restrict__ vertex_cells,
    int n_vertices, const double* __restrict__ coef, const double* __restrict__ apex,
    double* __restrict__ forces)
{
    long v = (long)blockIdx.x * blockDim.x + threadIdx.x;
    if (v >= n_vertices) return;
    vec3 r = load3(pos, v);
    double inv_rn = rsqrt(dot3(r, r));
    vec3 u = inv_rn * r;
    vec3 g = v3(0.0, 0.0, 0.0);
    // neighbour j follows v in cell j (slot j) and precedes it in cell j-1 (slot j+2 mod 3): each
    // neighbour is loaded once and its edge's length gradient is shared by the two cells
    for (int j = 0; j < 3; ++j) {
        int c_next = vertex_cells[3 * v + j], c_prev = vertex_cells[3 * v + (j + 2) % 3];
        vec3 w = normalize3(load3(pos, vertex_neighbors[3 * v + j]));
        vec3 ap_n = load3(apex, c_next), ap_p = load3(apex, c_prev);
        vec3 gA_n = solid_angle_gradient(ap_n, u, w);
        vec3 gA_p = solid_angle_gradient(w, u, ap_p);
        vec3 gA = coef[2 * c_next] * gA_n + coef[2 * c_prev] * gA_p;
        gA = gA - dot3(gA, u) * u;
        g = g + gA + (coef[2 * c_next + 1] + coef[2 * c_prev + 1]) * geodesic_length_gradient(u, w);
    }
    g = inv_rn * g;
    store3(forces, v, -g);
}
