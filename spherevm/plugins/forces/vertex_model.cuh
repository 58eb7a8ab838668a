// The vertex model's two kernel bodies, as templates over what a force fused into them adds: the
// vertex model alone instantiates them with NoExtra (vertex_model.cu), the bending force with its
// terms (bending.cu). An extra gets, after the vertex model's own loop, the cell (its vertex row)
// or the vertex (its position), and adds to the vertex's gradient before the tangent projection.
// It runs its own loop over the positions the vertex model has just loaded (from L1/L2), so its
// registers are not live across the vertex model's (fewer registers, no spills).
#pragma once
#include "geometry/sphere.cuh"
#include "device_common.cuh"

struct NoExtra {
    __device__ __forceinline__ void cell(const double*, const int*, int, long) const {}
    __device__ __forceinline__ void add_gradient(vec3&, const double*, const int*, const int*, long, vec3) const {}
};

// One thread per cell: area (fan about the cell's first vertex a, each triangle (a, b, d) as
// den + i num with num = (a - b).(b x d), den = 1 + b.d + a.(b + d), the area 2 arg of their
// product: one atan2 per cell, valid below a hemisphere), perimeter, the cell's energy, the
// per-replica energy sum, and the two coefficients the vertex kernel needs:
// coef = (2 kA (A - A0) R^2, 2 kP (P - P0) R).
template <class Extra>
__device__ __forceinline__ void vm_cell_geometry_body(
    const double* __restrict__ pos, const int* __restrict__ cell_vertices, const int* __restrict__ cell_sides,
    const int* __restrict__ cell_replica, const double* __restrict__ radius, int n_cells, int max_sides,
    const double* __restrict__ kA, const double* __restrict__ kP, const double* __restrict__ A0,
    const double* __restrict__ P0, double* __restrict__ coef, double* __restrict__ cell_energy,
    double* __restrict__ replica_energy, Extra extra)
{
    long c = (long)blockIdx.x * blockDim.x + threadIdx.x;
    int rep = -1;
    double e = 0.0;
    if (c < n_cells) {
        rep = cell_replica[c];
        const int* row = cell_vertices + c * max_sides;
        int n = cell_sides[c];
        vec3 a = normalize3(load3(pos, row[0]));
        vec3 b = a;
        double P = 0.0, re = 1.0, im = 0.0;
        for (int i = 0; i < n; ++i) {
            vec3 d = i + 1 < n ? normalize3(load3(pos, row[i + 1])) : a;
            edge_terms t = make_edge(b, d);
            P += half_angle(t);
            double num = dot3(a - b, t.x);
            double den = 0.5 * t.q + dot3(a, b + d);
            double r = re * den - im * num;
            im = re * num + im * den;
            re = r;
            b = d;
        }
        extra.cell(pos, row, n, c);
        double R = radius[rep];
        double A = 2.0 * atan2(im, re) * (R * R);
        P *= 2.0 * R;
        double dA = A - A0[c], dP = P - P0[c];
        e = kA[c] * dA * dA + kP[c] * dP * dP;
        coef[2 * c] = 2.0 * kA[c] * dA * (R * R);
        coef[2 * c + 1] = 2.0 * kP[c] * dP * R;
        cell_energy[c] = e;
    }
    segmented_block_add(e, rep, replica_energy);
}

// One thread per vertex, no atomics: each of its three edges v -> n_j lies in cell j (slot j) and,
// as n_j -> v, in cell j-1 (slot j+2 mod 3); minus the surface gradient of the energy,
// sum_j (coefA[j-1] - coefA[j]) w(v, n_j) + (coefP[j] + coefP[j-1]) d theta_j / dv, as in
// Sphere.shape_gradient. The extra adds its gradient (in units of these unit-sphere terms) before
// the tangent projection.
template <class Extra>
__device__ __forceinline__ void vm_vertex_forces_body(
    const double* __restrict__ pos, const int* __restrict__ vertex_neighbors, const int* __restrict__ vertex_cells,
    int n_vertices, const double* __restrict__ coef, double* __restrict__ forces, Extra extra)
{
    long v = (long)blockIdx.x * blockDim.x + threadIdx.x;
    if (v >= n_vertices) return;
    vec3 r = load3(pos, v);
    double inv_rn = rsqrt(dot3(r, r));
    vec3 u = inv_rn * r;
    vec3 g = v3(0.0, 0.0, 0.0);
    for (int j = 0; j < 3; ++j) {
        int c_next = vertex_cells[3 * v + j], c_prev = vertex_cells[3 * v + (j + 2) % 3];
        edge_terms t = make_edge(u, normalize3(load3(pos, vertex_neighbors[3 * v + j])));
        g = g + (coef[2 * c_prev] - coef[2 * c_next]) * edge_area_term(t)
              + (coef[2 * c_next + 1] + coef[2 * c_prev + 1]) * edge_length_term(t);
    }
    extra.add_gradient(g, pos, vertex_neighbors, vertex_cells, v, r);
    g = g - dot3(g, u) * u;
    store3(forces, v, -(inv_rn * g));
}
