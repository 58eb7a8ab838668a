// Vertex-model energy and forces: the CUDA path of vertex_model.py, compiled once per surface
// (geometry/surface.cuh: the surface whose device code the module starts with). The kernel
// bodies are in vertex_model.cuh (bending.cu fuses its terms into the same bodies on the sphere).
#include "plugins/forces/vertex_model.cuh"

// Both kernels at most 64 registers (4 blocks of spherevm.device.BLOCK = 256 threads an SM; 70 and 68
// unbounded, 3 blocks): on an H200 at 4,096 x 64 cells 48.7 and 24.9 us against 51.2 and 27.9 (ncu),
// a Brownian + T1 step at 1e6 cells 0.41 ms against 0.44; the same bits (register allocation only).
extern "C" __global__ void __launch_bounds__(256, 4) vm_cell_geometry(
    const double* __restrict__ pos, const int* __restrict__ cell_vertices, const int* __restrict__ cell_sides,
    const int* __restrict__ cell_replica, const double* __restrict__ size, int n_cells, int max_sides,
    const double* __restrict__ kA, const double* __restrict__ kP, const double* __restrict__ A0,
    const double* __restrict__ P0, double* __restrict__ coef, double* __restrict__ cell_energy,
    double* __restrict__ replica_energy, const int* __restrict__ cell_start, int n_replicas,
    double* __restrict__ scratch, unsigned int* __restrict__ count)
{
    vm_cell_geometry_body(pos, cell_vertices, cell_sides, cell_replica, size, n_cells, max_sides, kA, kP, A0, P0,
                          coef, cell_energy, replica_energy, SegmentSum{cell_start, n_replicas, scratch, count},
                          NoExtra());
}

extern "C" __global__ void __launch_bounds__(256, 4) vm_vertex_forces(
    const double* __restrict__ pos, const int* __restrict__ vertex_neighbors, const int* __restrict__ vertex_cells,
    const int* __restrict__ vertex_replica, const double* __restrict__ size, int n_vertices,
    const double* __restrict__ coef, double* __restrict__ forces)
{
    vm_vertex_forces_body(pos, vertex_neighbors, vertex_cells, vertex_replica, size, n_vertices, coef, forces,
                          NoExtra());
}
