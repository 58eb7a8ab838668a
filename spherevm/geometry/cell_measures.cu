// Every cell's area and perimeter, one thread a cell (spherevm.constraints.kernels.cell_measures):
// the vertex model's Surface::cell_measures, so the shapes the GPU reports are the ones its energy sees.
#include "geometry/surface.cuh"

extern "C" __global__ void cell_measures(const double* __restrict__ pos, const int* __restrict__ cell_vertices,
                                         const int* __restrict__ cell_sides, const int* __restrict__ cell_replica,
                                         const double* __restrict__ size, int n_cells, int max_sides,
                                         double* __restrict__ area, double* __restrict__ perimeter)
{
    long c = (long)blockIdx.x * blockDim.x + threadIdx.x;
    if (c >= n_cells) return;
    Surface::cell_measures(pos, cell_vertices + c * max_sides, cell_sides[c], Surface::size(size, cell_replica[c]),
                           area + c, perimeter + c);
}
