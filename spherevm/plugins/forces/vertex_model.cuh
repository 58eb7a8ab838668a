// The vertex model's two kernel bodies, as templates over what a force fused into them adds: the
// vertex model alone instantiates them with NoExtra (vertex_model.cu, every surface), the bending
// force with its terms (bending.cu, the sphere). An extra gets, after the cell's measures, the cell
// (its vertex row), and adds to the vertex's gradient before the tangent projection
// (Surface::vertex_force); it runs its own loop over the positions just loaded (from L1/L2), so its
// registers are not live across the vertex model's (fewer registers, no spills).
#pragma once
#include "geometry/surface.cuh"
#include "device_common.cuh"

// Cell c of area A and perimeter P: its energy (returned) and the two coefficients the vertex forces need,
// coef = (2 kA (A - A0) area_unit, 2 kP (P - P0) length_unit) (R^2 and R on the sphere, 1 on the plane).
// Shared with the fused small-tissue steps (spherevm/tissue_steps.cu), whose coef is a tissue's copy in
// shared memory, offset so that it is indexed by the global cell index.
__device__ __forceinline__ double vm_cell_terms(double A, double P, long c, Surface::Size s,
                                                const double* kA, const double* kP, const double* A0,
                                                const double* P0, double* coef)
{
    double dA = A - A0[c], dP = P - P0[c];
    coef[2 * c] = 2.0 * kA[c] * dA * Surface::area_unit(s);
    coef[2 * c + 1] = 2.0 * kP[c] * dP * Surface::length_unit(s);
    return kA[c] * dA * dA + kP[c] * dP * dP;
}

// The same for a cell of vector area a on a surface of flat facets (Surface::coef_width 4): its
// coefficients (dE/dA a / A, dE/dP), a / A taken as 0 for a cell of zero area (FlatFacets.shape_gradient).
__device__ __forceinline__ double vm_facet_terms(double A, double P, vec3 a, long c, const double* kA,
                                                 const double* kP, const double* A0, const double* P0, double* coef)
{
    double dA = A - A0[c], dP = P - P0[c];
    double per_area = A != 0.0 ? 2.0 * kA[c] * dA / A : 0.0;
    coef[4 * c] = per_area * a.x;
    coef[4 * c + 1] = per_area * a.y;
    coef[4 * c + 2] = per_area * a.z;
    coef[4 * c + 3] = 2.0 * kP[c] * dP;
    return kA[c] * dA * dA + kP[c] * dP * dP;
}

// Cell c on surface S: its measures, its energy (returned) and its coefficients (vm_cell_terms, or
// vm_facet_terms where S::coef_width is 4: the flat-facet metric of implicit surfaces).
template <class S, class Extra>
__device__ __forceinline__ double vm_cell(const double* pos, const int* row, int n, long c, typename S::Size s,
                                          const double* kA, const double* kP, const double* A0, const double* P0,
                                          double* coef, const Extra& extra)
{
    double A, P;
    if constexpr (S::coef_width == 2) {
        S::cell_measures(pos, row, n, s, &A, &P);
        extra.cell(pos, row, n, c);
        return vm_cell_terms(A, P, c, s, kA, kP, A0, P0, coef);
    } else {
        vec3 a;
        S::facet(pos, row, n, s, &A, &P, &a);
        return vm_facet_terms(A, P, a, c, kA, kP, A0, P0, coef);
    }
}

// One thread per cell: area and perimeter (Surface::cell_measures), the cell's energy, the
// per-replica energy sum (device_common.cuh: `sums` over the cells; left to a later kernel of the
// extra's where Extra::sums_energy), and the two coefficients the vertex kernel needs (vm_cell_terms).
// size: the State's radius (n_replicas,) or box (n_replicas, 2).
template <class Extra>
__device__ __forceinline__ void vm_cell_geometry_body(
    const double* __restrict__ pos, const int* __restrict__ cell_vertices, const int* __restrict__ cell_sides,
    const int* __restrict__ cell_replica, const double* __restrict__ size, int n_cells, int max_sides,
    const double* __restrict__ kA, const double* __restrict__ kP, const double* __restrict__ A0,
    const double* __restrict__ P0, double* __restrict__ coef, double* __restrict__ cell_energy,
    double* __restrict__ replica_energy, SegmentSum sums, Extra extra)
{
    long c = (long)blockIdx.x * blockDim.x + threadIdx.x;
    int rep = -1;
    double e = 0.0;
    if (c < n_cells) {
        rep = cell_replica[c];
        Surface::Size s = Surface::size(size, rep);
        const int* row = cell_vertices + c * max_sides;
        int n = cell_sides[c];
        e = vm_cell<Surface>(pos, row, n, c, s, kA, kP, A0, P0, coef, extra);
        cell_energy[c] = e;
    }
    if (!Extra::sums_energy) segment_sum(e, rep, sums, replica_energy);
}

// One thread per vertex, no atomics: minus the surface gradient of the energy from the vertex's
// three edges and the coefficients of the cells on either side (Surface::vertex_force), with the
// extra's gradient added before the projection.
template <class Extra>
__device__ __forceinline__ void vm_vertex_forces_body(
    const double* __restrict__ pos, const int* __restrict__ vertex_neighbors, const int* __restrict__ vertex_cells,
    const int* __restrict__ vertex_replica, const double* __restrict__ size, int n_vertices,
    const double* __restrict__ coef, double* __restrict__ forces, Extra extra)
{
    long v = (long)blockIdx.x * blockDim.x + threadIdx.x;
    if (v >= n_vertices) return;
    Surface::Size s = Surface::size(size, Surface::vertex_size ? vertex_replica[v] : 0);
    store3(forces, v, Surface::vertex_force(pos, vertex_neighbors, vertex_cells, v, s, coef, extra));
}
