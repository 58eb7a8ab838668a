// Vertex-model energy and forces: the CUDA path of vertex_model.py, compiled once per surface
// (geometry/surface.cuh: the sphere, or the periodic plane with -DSVM_SURFACE_PLANE).
#include "geometry/surface.cuh"
#include "device_common.cuh"

// One thread per cell: area and perimeter (Surface::cell_measures), the cell's energy, the
// per-replica energy sum, and the two coefficients the vertex kernel needs:
// coef = (2 kA (A - A0) area_unit, 2 kP (P - P0) length_unit) (R^2 and R on the sphere, 1 on the plane).
// size: the State's radius (n_replicas,) or box (n_replicas, 2).
extern "C" __global__ void vm_cell_geometry(
    const double* __restrict__ pos, const int* __restrict__ cell_vertices, const int* __restrict__ cell_sides,
    const int* __restrict__ cell_replica, const double* __restrict__ size, int n_cells, int max_sides,
    const double* __restrict__ kA, const double* __restrict__ kP, const double* __restrict__ A0,
    const double* __restrict__ P0, double* __restrict__ coef, double* __restrict__ cell_energy,
    double* __restrict__ replica_energy)
{
    long c = (long)blockIdx.x * blockDim.x + threadIdx.x;
    int rep = -1;
    double e = 0.0;
    if (c < n_cells) {
        rep = cell_replica[c];
        Surface::Size s = Surface::size(size, rep);
        double A, P;
        Surface::cell_measures(pos, cell_vertices + c * max_sides, cell_sides[c], s, &A, &P);
        double dA = A - A0[c], dP = P - P0[c];
        e = kA[c] * dA * dA + kP[c] * dP * dP;
        coef[2 * c] = 2.0 * kA[c] * dA * Surface::area_unit(s);
        coef[2 * c + 1] = 2.0 * kP[c] * dP * Surface::length_unit(s);
        cell_energy[c] = e;
    }
    segmented_block_add(e, rep, replica_energy);
}

// One thread per vertex, no atomics: minus the surface gradient of the energy from the vertex's
// three edges and the coefficients of the cells on either side (Surface::vertex_force).
extern "C" __global__ void vm_vertex_forces(
    const double* __restrict__ pos, const int* __restrict__ vertex_neighbors, const int* __restrict__ vertex_cells,
    const int* __restrict__ vertex_replica, const double* __restrict__ size, int n_vertices,
    const double* __restrict__ coef, double* __restrict__ forces)
{
    long v = (long)blockIdx.x * blockDim.x + threadIdx.x;
    if (v >= n_vertices) return;
    Surface::Size s = Surface::size(size, Surface::vertex_size ? vertex_replica[v] : 0);
    store3(forces, v, Surface::vertex_force(pos, vertex_neighbors, vertex_cells, v, s, coef));
}
